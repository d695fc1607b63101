//! `image.flip`: the FLIP perceived difference between a reference and a test image (Andersson et
//! al. 2020), or HDR-FLIP for linear renders (Andersson et al. 2021), at the viewer's pixels per
//! degree. Reports the mean, 95th percentile and maximum over the image or over a mask (the
//! pixels where an object is seen, so a black background does not dilute the mean), the error map
//! and a colour-mapped preview of it.

pub mod color;
pub mod filters;
pub mod hdr;
pub mod ldr;

use crate::types::Image;
use ldr::Rgb;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Pixels per degree of FLIP's reference viewing condition: a 0.7 m wide 3840-pixel monitor seen
/// from 0.7 m.
pub const DEFAULT_PPD: f64 = 0.7 * (3840.0 / 0.7) * std::f64::consts::PI / 180.0;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Display images with values in [0, 1] (larger values are clipped).
    Ldr,
    /// Linear radiance of any range: exposures from the reference, ACES tone mapping, the largest
    /// error over the exposures.
    #[default]
    Hdr,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Viewer {
    /// Distance from the viewer to the display, metres (1 mm to 1 km).
    #[schemars(range(min = 0.001, max = 1000.0))]
    pub distance_m: f64,
    /// Width of the displayed image, metres (1 mm to 1 km); the image's pixel width spans it.
    #[schemars(range(min = 0.001, max = 1000.0))]
    pub width_m: f64,
}

impl Viewer {
    /// Pixels per degree at the display centre for an image `pixels` wide (FLIP's formula).
    pub fn ppd(&self, pixels: usize) -> f64 {
        self.distance_m * (pixels as f64 / self.width_m) * std::f64::consts::PI / 180.0
    }
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Pixels per degree of visual angle; default 67.02 (a 0.7 m wide 4K monitor at 0.7 m). Give
    /// this or `viewer`, not both.
    #[schemars(range(min = 0.5, max = 10000.0))]
    pub ppd: Option<f64>,
    /// Viewing condition from which the pixels per degree follow, with the image's width.
    pub viewer: Option<Viewer>,
    /// `hdr` (default: mesoflow images are linear radiance) or `ldr` (display values in [0, 1]).
    pub mode: Mode,
    /// Measure only the pixels where either image is not black (mesoflow renders an object on a
    /// black background, which would dilute the mean); with `mask`, the pixels both select.
    pub object_only: bool,
}

impl Params {
    pub fn ppd_for(&self, width: usize) -> f64 {
        match (self.ppd, self.viewer) {
            (Some(p), _) => p,
            (None, Some(v)) => v.ppd(width),
            (None, None) => DEFAULT_PPD,
        }
    }
}

pub struct Flip;

impl Node for Flip {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.flip",
            version: 2,
            doc: "FLIP perceived difference (LDR-FLIP, or HDR-FLIP for linear renders) at the viewer's pixels per degree: mean, p95 and max over the image or a mask, the error map and a magma preview.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("reference", Image::TYPE, "the reference image (linear)"),
                Port::input("test", Image::TYPE, "the image to judge, same size"),
                Port::optional(
                    "mask",
                    Image::TYPE,
                    "pixels to measure (first channel > 0), e.g. where an object is seen; same size",
                ),
            ],
            outputs: vec![
                Port::output("mean", "Scalar", "mean FLIP error over the measured pixels, in [0, 1]"),
                Port::output("p95", "Scalar", "95th percentile (linear interpolation, as numpy's default)"),
                Port::output("max", "Scalar", "largest FLIP error"),
                Port::output("map", Image::TYPE, "per-pixel FLIP error, one channel"),
                Port::output("preview", Image::TYPE, "the error map through the magma colour map (linear RGB)"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        if p.ppd.is_some() && p.viewer.is_some() {
            return Err(NodeError::param(
                "viewer",
                "give `ppd` or `viewer`, not both",
            ));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let r = inputs.get::<Image>("reference")?;
        let t = inputs.get::<Image>("test")?;
        let mask = inputs.opt::<Image>("mask")?;
        let e = evaluate(r, t, mask, p, |k, n| ctx.progress(k as u64, n as u64))?;
        if let Some(ex) = e.exposures.as_ref().filter(|ex| ex.count > 20) {
            ctx.warn(format!(
                "HDR-FLIP took {} exposures ({:.1} to {:.1} stops): the reference's median luminance is near 0 (mostly background); `object_only` or a mask sets the range from the object's pixels",
                ex.count, ex.start, ex.stop
            ));
        }
        let image = |channels: usize, data: Vec<f32>| Image {
            width: r.width,
            height: r.height,
            channels,
            data,
        };
        let preview = e.map.iter().flat_map(|v| magma(*v)).collect();
        Ok(Outputs::new()
            .with("mean", Scalar(e.stats.mean))
            .with("p95", Scalar(e.stats.p95))
            .with("max", Scalar(e.stats.max))
            .with("map", image(1, e.map))
            .with("preview", image(3, preview)))
    }
}

/// A FLIP evaluation: the per-pixel map, its statistics over the measured pixels, and for HDR
/// the exposures taken.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub map: Vec<f32>,
    pub stats: Stats,
    pub ppd: f64,
    pub exposures: Option<hdr::Exposures>,
}

/// FLIP of `test` against `reference` (linear images of the same size), statistics over the
/// pixels where `mask`'s first channel is positive (all pixels without one).
pub fn evaluate(
    r: &Image,
    t: &Image,
    mask: Option<&Image>,
    p: &Params,
    progress: impl FnMut(usize, usize),
) -> Result<Evaluation, NodeError> {
    same_size("test", r, t)?;
    if let Some(m) = mask {
        same_size("mask", r, m)?;
    }
    let ppd = p.ppd_for(r.width);
    if !(ppd.is_finite() && ppd >= 0.5) {
        return Err(NodeError::param(
            "viewer",
            format!(
                "gives {ppd} pixels per degree for a {}-pixel image; need at least 0.5",
                r.width
            ),
        ));
    }
    let clip = p.mode == Mode::Ldr;
    let (rr, tt) = (to_rgb("reference", r, clip)?, to_rgb("test", t, clip)?);
    let lit = |img: &Image, i: usize| {
        let c = img.channels.max(1);
        img.data[i * c..(i + 1) * c].iter().any(|v| *v != 0.0)
    };
    let keep: Vec<bool> = (0..r.width * r.height)
        .map(|i| {
            mask.is_none_or(|m| m.data[i * m.channels.max(1)] > 0.0)
                && (!p.object_only || lit(r, i) || lit(t, i))
        })
        .collect();
    let restricted = mask.is_some() || p.object_only;
    let (map, exposures) = match p.mode {
        Mode::Ldr => {
            let mut progress = progress;
            let m = ldr::flip_map(&rr, &tt, ppd);
            progress(1, 1);
            (m, None)
        }
        Mode::Hdr => {
            let sel = restricted.then_some(keep.as_slice());
            let (m, ex) = hdr::hdr_flip_map(&rr, &tt, ppd, sel, progress);
            (m, Some(ex))
        }
    };
    let selected: Vec<f32> = map
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(v, _)| *v)
        .collect();
    let stats = Stats::of(&selected).ok_or_else(|| match mask {
        Some(_) => NodeError::input(
            "mask",
            "selects no pixel (first channel is 0 everywhere, or nothing is seen there)",
        ),
        None => NodeError::param(
            "object_only",
            "both images are black everywhere: no object pixel to measure",
        ),
    })?;
    Ok(Evaluation {
        map,
        stats,
        ppd,
        exposures,
    })
}

fn same_size(port: &str, r: &Image, a: &Image) -> Result<(), NodeError> {
    if (r.width, r.height) != (a.width, a.height) {
        return Err(NodeError::input(
            port,
            format!(
                "{}×{} does not match the reference's {}×{}",
                a.width, a.height, r.width, r.height
            ),
        ));
    }
    if r.width == 0 || r.height == 0 {
        return Err(NodeError::input("reference", "image is empty"));
    }
    Ok(())
}

/// Planes of linear RGB: grey is replicated, alpha dropped. Non-finite values are refused and
/// negative ones (no light is negative; they come from filtering) clamp to 0.
fn to_rgb(port: &str, img: &Image, clip: bool) -> Result<Rgb, NodeError> {
    let n = img.width * img.height;
    if img.data.iter().any(|v| !v.is_finite()) {
        return Err(NodeError::input(port, "contains NaN or infinite values"));
    }
    let c = img.channels.max(1);
    let planes: [Vec<f32>; 3] = [0, 1, 2].map(|k| {
        (0..n)
            .into_par_iter()
            .map(|i| {
                let v = img.data[i * c + if c >= 3 { k } else { 0 }].max(0.0);
                if clip {
                    v.min(1.0)
                } else {
                    v
                }
            })
            .collect()
    });
    Ok(Rgb {
        width: img.width,
        height: img.height,
        planes,
    })
}

/// Summary statistics of an error map, summed in pixel order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stats {
    pub mean: f64,
    pub p95: f64,
    pub max: f64,
}

impl Stats {
    pub fn of(values: &[f32]) -> Option<Stats> {
        if values.is_empty() {
            return None;
        }
        let mean = values.iter().map(|v| *v as f64).sum::<f64>() / values.len() as f64;
        let mut all: Vec<f64> = values.iter().map(|v| *v as f64).collect();
        let max = all.iter().copied().fold(f64::NEG_INFINITY, |a, b| {
            if b.total_cmp(&a).is_gt() {
                b
            } else {
                a
            }
        });
        Some(Stats {
            mean,
            p95: percentile(&mut all, 0.95),
            max,
        })
    }
}

/// Linear interpolation between the closest ranks (numpy's default `percentile`). The two
/// ranks are selected, not sorted for (a 1080p map is 2 M values): the same values as a sort
/// would put there. Reorders `values`.
fn percentile(values: &mut [f64], q: f64) -> f64 {
    let pos = q * (values.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = (lo + 1).min(values.len() - 1);
    let (_, at_lo, above) = values.select_nth_unstable_by(lo, f64::total_cmp);
    let at_lo = *at_lo;
    let at_hi = if hi == lo {
        at_lo
    } else {
        // The next rank is the least of those above.
        above
            .iter()
            .copied()
            .min_by(f64::total_cmp)
            .unwrap_or(at_lo)
    };
    at_lo + (pos - lo as f64) * (at_hi - at_lo)
}

/// Matplotlib's magma at nine evenly spaced points (sRGB-encoded), interpolated linearly and
/// decoded to linear light so a PNG write shows the familiar colours.
fn magma(v: f32) -> [f32; 3] {
    const STOPS: [[f32; 3]; 9] = [
        [0.001462, 0.000466, 0.013866],
        [0.078815, 0.054184, 0.211667],
        [0.232077, 0.059889, 0.437695],
        [0.390384, 0.100379, 0.501864],
        [0.550287, 0.161158, 0.505719],
        [0.716387, 0.214982, 0.474720],
        [0.868793, 0.287728, 0.409303],
        [0.967671, 0.439703, 0.359810],
        [0.987053, 0.991438, 0.749504],
    ];
    let x = v.clamp(0.0, 1.0) * 8.0;
    let i = (x.floor() as usize).min(7);
    let f = x - i as f32;
    [0, 1, 2].map(|c| {
        let s = STOPS[i][c] + f * (STOPS[i + 1][c] - STOPS[i][c]);
        crate::types::srgb_to_linear(s)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_only_ignores_the_black_background() {
        // A 4×1 image whose object is the first pixel: with `object_only` the statistics are
        // that pixel's error alone; without, the mean of all four (the filters spread some error
        // onto the black pixels, so the two differ but neither is what the other measures).
        let r = Image {
            width: 4,
            height: 1,
            channels: 1,
            data: vec![0.5, 0.0, 0.0, 0.0],
        };
        let t = Image {
            data: vec![0.25, 0.0, 0.0, 0.0],
            ..r.clone()
        };
        let all = evaluate(&r, &t, None, &Params::default(), |_, _| {}).unwrap();
        let obj = Params {
            object_only: true,
            ..Default::default()
        };
        let only = evaluate(&r, &t, None, &obj, |_, _| {}).unwrap();
        assert_eq!(only.stats.mean, all.map[0] as f64);
        assert_eq!(only.stats.max, all.map[0] as f64);
        let mean4 = all.map.iter().map(|v| *v as f64).sum::<f64>() / 4.0;
        assert!((all.stats.mean - mean4).abs() < 1e-12);
        let black = Image {
            data: vec![0.0; 4],
            ..r.clone()
        };
        assert!(evaluate(&black, &black, None, &obj, |_, _| {})
            .unwrap_err()
            .to_string()
            .contains("object_only"));
    }

    #[test]
    fn percentile_matches_numpy() {
        // numpy.percentile([1, 2, 3, 4, 10], 95) = 8.8 (position 3.8 between 4 and 10).
        let s = Stats::of(&[3.0, 1.0, 10.0, 2.0, 4.0]).unwrap();
        assert!((s.p95 - 8.8).abs() < 1e-9);
        assert_eq!(s.max, 10.0);
        assert!((s.mean - 4.0).abs() < 1e-9);
        assert!(Stats::of(&[]).is_none());
        // Selection gives what a sort gives, ties and all.
        let v: Vec<f32> = (0..1001).map(|i| ((i * 7919) % 97) as f32 / 7.0).collect();
        let mut sorted: Vec<f64> = v.iter().map(|x| *x as f64).collect();
        sorted.sort_by(f64::total_cmp);
        let pos: f64 = 0.95 * 1000.0;
        let lo = pos.floor() as usize;
        let want = sorted[lo] + (pos - lo as f64) * (sorted[lo + 1] - sorted[lo]);
        let s = Stats::of(&v).unwrap();
        assert_eq!(s.p95.to_bits(), want.to_bits());
        assert_eq!(s.max, sorted[1000]);
    }

    #[test]
    fn default_ppd_is_flips() {
        // flip-evaluator 1.7 reports ppd 67.02064514160156 (f32) for its defaults.
        assert!((DEFAULT_PPD - 67.020_645).abs() < 1e-5);
        let v = Viewer {
            distance_m: 0.7,
            width_m: 0.7,
        };
        assert!((v.ppd(3840) - DEFAULT_PPD).abs() < 1e-12);
    }
}
