//! `image.blur`: separable Gaussian blur (edges clamped), e.g. the low-frequency layout of a
//! degree map used as a synthesis guide.

use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Standard deviation in pixels (0 = copy), at most 1000.
    #[schemars(range(min = 0.0, max = 1000.0))]
    pub sigma: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params { sigma: 2.0 }
    }
}

pub struct Blur;

impl Node for Blur {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.blur",
            version: 1,
            doc: "Separable Gaussian blur of standard deviation `sigma` pixels, edges clamped.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("image", Image::TYPE, "the image")],
            outputs: vec![Port::output("image", Image::TYPE, "blurred, same channels")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let img = inputs.get::<Image>("image")?;
        Ok(Outputs::new().with("image", blur(img, p.sigma)))
    }
}

/// Normalised Gaussian taps out to 3σ.
fn kernel(sigma: f64) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as i64;
    let taps: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = taps.iter().sum();
    taps.iter().map(|t| (t / sum) as f32).collect()
}

pub fn blur(img: &Image, sigma: f64) -> Image {
    if sigma == 0.0 || img.data.is_empty() {
        return img.clone();
    }
    let k = kernel(sigma);
    let r = (k.len() / 2) as i64;
    let (w, h, c) = (img.width, img.height, img.channels);
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = vec![0.0f32; src.len()];
        out.par_chunks_mut(w * c).enumerate().for_each(|(y, row)| {
            for x in 0..w {
                for ch in 0..c {
                    let mut s = 0.0f32;
                    for (t, kv) in k.iter().enumerate() {
                        let o = t as i64 - r;
                        let (sx, sy) = if horizontal {
                            ((x as i64 + o).clamp(0, w as i64 - 1) as usize, y)
                        } else {
                            (x, (y as i64 + o).clamp(0, h as i64 - 1) as usize)
                        };
                        s += kv * src[(sy * w + sx) * c + ch];
                    }
                    row[x * c + ch] = s;
                }
            }
        });
        out
    };
    let data = pass(&pass(&img.data, true), false);
    Image {
        data,
        ..img.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_constants_and_the_mean_of_an_impulse() {
        let flat = Image {
            width: 7,
            height: 5,
            channels: 3,
            data: vec![0.4; 105],
        };
        assert!(blur(&flat, 1.5).data.iter().all(|v| (v - 0.4).abs() < 1e-6));
        // An impulse far from the edges spreads to a Gaussian: total kept (taps normalised),
        // and the variance along x is the normal's truncated at ±3σ: σ²(1 − 6φ(3)/(2Φ(3) − 1))
        // = 0.9733σ² = 8.76 for σ = 3, within 2% for sampling at integers.
        let mut imp = Image {
            width: 41,
            height: 41,
            channels: 1,
            data: vec![0.0; 41 * 41],
        };
        imp.data[20 * 41 + 20] = 1.0;
        let b = blur(&imp, 3.0);
        let total: f32 = b.data.iter().sum();
        assert!((total - 1.0).abs() < 1e-5);
        let var: f32 = (0..41 * 41)
            .map(|i| b.data[i] * ((i % 41) as f32 - 20.0).powi(2))
            .sum();
        assert!((var - 8.76).abs() < 0.18, "{var}");
    }
}
