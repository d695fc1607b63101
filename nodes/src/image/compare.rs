//! `image.compare`: the error of an image against a reference of the same size — RMSE, PSNR
//! (against the reference's peak), mean and max absolute error, the fraction of pixels off by more
//! than 1% of the peak, and a false-colour-free difference image (|a − b| per channel).

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
            version: 1,
            doc: "Error of an image against a reference: RMSE, PSNR, mean/max absolute error, fraction of pixels off by > 1% of the peak, difference image.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("reference", Image::TYPE, "the reference image"),
                Port::input("image", Image::TYPE, "the image to measure"),
            ],
            outputs: vec![
                Port::output("rmse", "Scalar", "root-mean-square error over all samples"),
                Port::output("psnr", "Scalar", "20·log10(reference peak / rmse) dB, capped at 300"),
                Port::output("mean_abs", "Scalar", "mean absolute error"),
                Port::output("max_abs", "Scalar", "largest absolute error"),
                Port::output("differing", "Scalar", "fraction of pixels with a channel off by > 1% of the peak"),
                Port::output("difference", Image::TYPE, "|image − reference| per channel"),
            ],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, _p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let r = inputs.get::<Image>("reference")?;
        let a = inputs.get::<Image>("image")?;
        if (r.width, r.height, r.channels) != (a.width, a.height, a.channels) {
            return Err(NodeError::input(
                "image",
                format!(
                    "{}×{}×{} does not match the reference's {}×{}×{}",
                    a.width, a.height, a.channels, r.width, r.height, r.channels
                ),
            ));
        }
        let e = errors(r, a);
        Ok(Outputs::new()
            .with("rmse", Scalar(e.rmse))
            .with("psnr", Scalar(psnr(e.peak, e.rmse)))
            .with("mean_abs", Scalar(e.mean_abs))
            .with("max_abs", Scalar(e.max_abs))
            .with("differing", Scalar(e.differing))
            .with("difference", e.difference))
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
}
