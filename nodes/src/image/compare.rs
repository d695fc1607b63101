//! `image.compare`: the error of an image against a reference of the same size — RMSE, PSNR
//! (against the reference's peak), mean and max absolute error, the fraction of pixels off by more
//! than 1% of the peak, and a false-colour-free difference image (|a − b| per channel). Against
//! a ground truth also the relative RMSE and the bias (over the object's pixels where masks say
//! which they are) and, with both images' masks, the intersection over union of what each
//! covers: whether the silhouettes agree.

use crate::btf::pca::psnr;
use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {}

pub struct Compare;

impl Node for Compare {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.compare",
            version: 2,
            doc: "Error of an image against a reference: RMSE, PSNR, mean/max absolute error, fraction of pixels off by > 1% of the peak, difference image; relative RMSE and bias (over the masks' union), silhouette IoU (with both masks).",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("reference", Image::TYPE, "the reference image"),
                Port::input("image", Image::TYPE, "the image to measure"),
                Port::optional("reference_mask", Image::TYPE, "where the reference shows the object (first channel > 0.5), e.g. render.reference's coverage"),
                Port::optional("mask", Image::TYPE, "where the image shows the object, e.g. render.mesh's mask"),
            ],
            outputs: vec![
                Port::output("rmse", "Scalar", "root-mean-square error over all samples"),
                Port::output("psnr", "Scalar", "20·log10(reference peak / rmse) dB, capped at 300"),
                Port::output("mean_abs", "Scalar", "mean absolute error"),
                Port::output("max_abs", "Scalar", "largest absolute error"),
                Port::output("differing", "Scalar", "fraction of pixels with a channel off by > 1% of the peak"),
                Port::output("difference", Image::TYPE, "|image − reference| per channel"),
                Port::optional_output("relative_rmse", "Scalar", "RMSE over the RMS of the reference, over the masks' union (all pixels without masks); absent for a black reference"),
                Port::optional_output("bias", "Scalar", "sum of the image over sum of the reference, minus 1, over the same pixels; absent for a black reference"),
                Port::optional_output("iou", "Scalar", "pixels both masks cover over pixels either covers (with both masks; 1 when neither covers any)"),
            ],
            disk_cache: false,
        }
    }

    fn run(&self, ctx: &NodeContext, _p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let (r, a) = (
            inputs.get::<Image>("reference")?,
            inputs.get::<Image>("image")?,
        );
        // RGBA against RGB (a Mitsuba render of an exported scene is RGBA): compared on RGB.
        let (r, a) = (
            rgb_beside(ctx, "reference", r, a),
            rgb_beside(ctx, "image", a, r),
        );
        let (r, a) = (r.as_ref(), a.as_ref());
        same_size(r, a)?;
        let masks = [
            ("reference_mask", inputs.opt::<Image>("reference_mask")?),
            ("mask", inputs.opt::<Image>("mask")?),
        ];
        for (port, m) in masks {
            if let Some(m) = m {
                if (m.width, m.height) != (r.width, r.height) || m.channels == 0 {
                    return Err(NodeError::input(
                        port,
                        format!(
                            "{}×{} does not match the reference's {}×{}",
                            m.width, m.height, r.width, r.height
                        ),
                    ));
                }
            }
        }
        let e = errors(r, a);
        let t = against_truth(r, a, masks[0].1, masks[1].1);
        let mut out = Outputs::new()
            .with("rmse", Scalar(e.rmse))
            .with("psnr", Scalar(psnr(e.peak, e.rmse)))
            .with("mean_abs", Scalar(e.mean_abs))
            .with("max_abs", Scalar(e.max_abs))
            .with("differing", Scalar(e.differing))
            .with("difference", e.difference);
        if let Some(v) = t.relative_rmse {
            out = out.with("relative_rmse", Scalar(v));
        }
        if let Some(v) = t.bias {
            out = out.with("bias", Scalar(v));
        }
        if let Some(v) = t.iou {
            out = out.with("iou", Scalar(v));
        }
        Ok(out)
    }
}

/// Errors against a ground truth: relative RMSE and bias over the masks' union (every pixel
/// without masks), and the masks' intersection over union.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgainstTruth {
    pub relative_rmse: Option<f64>,
    pub bias: Option<f64>,
    pub iou: Option<f64>,
}

/// `img` without its alpha channel where it is RGBA and `other` RGB of the same size, saying
/// so; else `img` itself.
fn rgb_beside<'a>(
    ctx: &NodeContext,
    port: &str,
    img: &'a Image,
    other: &Image,
) -> std::borrow::Cow<'a, Image> {
    let rgba_beside_rgb = img.channels == 4
        && other.channels == 3
        && (img.width, img.height) == (other.width, other.height);
    if !rgba_beside_rgb {
        return std::borrow::Cow::Borrowed(img);
    }
    ctx.warn(format!(
        "`{port}` is RGBA and the other image RGB: compared on RGB, its alpha left out"
    ));
    std::borrow::Cow::Owned(Image {
        width: img.width,
        height: img.height,
        channels: 3,
        data: img
            .data
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
    })
}

/// The `image` port's error when it is not the reference's size (width, height and channels).
pub fn same_size(reference: &Image, image: &Image) -> Result<(), NodeError> {
    let (r, i) = (reference, image);
    if (r.width, r.height, r.channels) == (i.width, i.height, i.channels) {
        return Ok(());
    }
    Err(NodeError::input(
        "image",
        format!(
            "{}×{}×{} does not match the reference's {}×{}×{}",
            i.width, i.height, i.channels, r.width, r.height, r.channels
        ),
    ))
}

/// Sums in pixel order, so the result does not depend on threads.
pub fn against_truth(
    r: &Image,
    a: &Image,
    reference_mask: Option<&Image>,
    mask: Option<&Image>,
) -> AgainstTruth {
    let on = |m: Option<&Image>, px: usize| m.map(|m| m.data[px * m.channels] > 0.5);
    let (mut sq, mut ref_sq, mut sum, mut ref_sum) = (0f64, 0f64, 0f64, 0f64);
    let (mut both, mut either) = (0usize, 0usize);
    let c = r.channels.max(1);
    for px in 0..r.width * r.height {
        let (mr, ma) = (on(reference_mask, px), on(mask, px));
        if let (Some(x), Some(y)) = (mr, ma) {
            both += (x && y) as usize;
            either += (x || y) as usize;
        }
        let selected = match (mr, ma) {
            (None, None) => true,
            (x, y) => x.unwrap_or(false) || y.unwrap_or(false),
        };
        if !selected {
            continue;
        }
        for k in 0..c {
            let (x, y) = (r.data[px * c + k] as f64, a.data[px * c + k] as f64);
            sq += (y - x) * (y - x);
            ref_sq += x * x;
            sum += y;
            ref_sum += x;
        }
    }
    AgainstTruth {
        relative_rmse: (ref_sq > 0.0).then(|| (sq / ref_sq).sqrt()),
        bias: (ref_sum > 0.0).then(|| sum / ref_sum - 1.0),
        iou: (reference_mask.is_some() && mask.is_some()).then(|| {
            if either == 0 {
                1.0
            } else {
                both as f64 / either as f64
            }
        }),
    }
}

pub struct Errors {
    pub rmse: f64,
    pub mean_abs: f64,
    pub max_abs: f64,
    pub peak: f64,
    pub differing: f64,
    pub difference: Image,
}

/// Sums in pixel order, so the result does not depend on threads.
pub fn errors(r: &Image, a: &Image) -> Errors {
    let peak = r.data.iter().fold(0f64, |m, v| m.max(*v as f64));
    let (mut sq, mut abs, mut max) = (0f64, 0f64, 0f64);
    let mut differing = 0usize;
    let diff: Vec<f32> = r
        .data
        .iter()
        .zip(&a.data)
        .map(|(x, y)| (x - y).abs())
        .collect();
    for px in diff.chunks_exact(r.channels.max(1)) {
        let mut off = false;
        for d in px {
            let d = *d as f64;
            sq += d * d;
            abs += d;
            max = max.max(d);
            off |= d > 0.01 * peak;
        }
        differing += off as usize;
    }
    let n = r.data.len().max(1) as f64;
    Errors {
        rmse: (sq / n).sqrt(),
        mean_abs: abs / n,
        max_abs: max,
        peak,
        differing: differing as f64 / (r.width * r.height).max(1) as f64,
        difference: Image {
            width: r.width,
            height: r.height,
            channels: r.channels,
            data: diff,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_match_hand_computed_values() {
        // Reference peak 1; one channel off by 0.5 in one of two pixels: RMSE sqrt(0.25/6).
        let r = Image {
            width: 2,
            height: 1,
            channels: 3,
            data: vec![1.0, 0.5, 0.5, 0.2, 0.2, 0.2],
        };
        let mut a = r.clone();
        a.data[4] = 0.7;
        let e = errors(&r, &a);
        assert!((e.rmse - (0.25f64 / 6.0).sqrt()).abs() < 1e-7);
        assert!((e.max_abs - 0.5).abs() < 1e-7);
        assert_eq!(e.differing, 0.5);
    }

    #[test]
    fn truth_errors_are_over_the_masks_union() {
        // Four grey pixels; the reference covers pixels 0–1, the image 1–2: IoU 1/3. Over pixels
        // 0–2 the reference is (1, 1, 0) and the image (1, 2, 1) per channel: relative RMSE
        // √((0 + 1 + 1)/(1 + 1)) = 1, bias 4/2 − 1 = 1.
        let grey = |v: [f32; 4]| Image {
            width: 4,
            height: 1,
            channels: 1,
            data: v.to_vec(),
        };
        let r = grey([1.0, 1.0, 0.0, 5.0]);
        let a = grey([1.0, 2.0, 1.0, 0.0]);
        let (rm, am) = (grey([1.0, 1.0, 0.0, 0.0]), grey([0.0, 1.0, 1.0, 0.0]));
        let t = against_truth(&r, &a, Some(&rm), Some(&am));
        assert!((t.iou.unwrap() - 1.0 / 3.0).abs() < 1e-12);
        assert!((t.relative_rmse.unwrap() - 1.0).abs() < 1e-12);
        assert!((t.bias.unwrap() - 1.0).abs() < 1e-12);
        // Without masks: every pixel, and no IoU; a black reference has no relative error.
        let t = against_truth(&r, &a, None, None);
        assert!(t.iou.is_none());
        assert!((t.bias.unwrap() - (4.0 / 7.0 - 1.0)).abs() < 1e-12);
        let black = grey([0.0; 4]);
        assert!(against_truth(&black, &a, None, None)
            .relative_rmse
            .is_none());
    }

    #[test]
    fn an_rgba_render_is_compared_on_rgb_and_says_so() {
        use mesoflow_testkit::node::OutputsExt;
        let rgb = Image {
            width: 2,
            height: 1,
            channels: 3,
            data: vec![1.0, 0.5, 0.5, 0.2, 0.2, 0.2],
        };
        let rgba = Image {
            width: 2,
            height: 1,
            channels: 4,
            data: vec![1.0, 0.5, 0.5, 1.0, 0.2, 0.2, 0.2, 0.0],
        };
        let inputs = Inputs::new()
            .with("reference", std::sync::Arc::new(rgb))
            .with("image", std::sync::Arc::new(rgba));
        let ctx = NodeContext::detached(None);
        let out =
            mesoflow_testkit::node::run_in(&ctx, &Compare, &Params::default(), &inputs).unwrap();
        assert_eq!(out.value::<Scalar>("rmse").0, 0.0);
        assert!(
            ctx.warnings().iter().any(|w| w.contains("alpha left out")),
            "{:?}",
            ctx.warnings()
        );
    }
}
