//! `btf.compare`: the error of a BTF against a reference — RMSE, PSNR and maximum absolute error
//! over texels × pairs × RGB, and the RMSE of every direction pair as an image (views down, lights
//! across, when the pairs form a views × lights grid; otherwise one row) and as a CSV table.

use super::pca::psnr;
use crate::types::{Btf, Image};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{
    Artifact, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar,
};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// File for the per-pair table (CSV), relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub table: String,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            table: "btf_errors.csv".into(),
        }
    }
}

pub struct Compare;

impl Node for Compare {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.compare",
            // 2: `relative_rmse`.
            version: 2,
            doc: "Error of a BTF against a reference: RMSE, relative RMSE, PSNR, max error, per-direction-pair RMSE (image and CSV).",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("reference", Btf::TYPE, "the reference BTF"),
                Port::input("btf", Btf::TYPE, "the BTF to assess"),
            ],
            outputs: vec![
                Port::output("rmse", "Scalar", "RMS error, linear units"),
                Port::output("relative_rmse", "Scalar", "RMS error over the reference's RMS value"),
                Port::output("psnr", "Scalar", "20·log10(reference max / rmse) dB, capped at 300"),
                Port::output("max_error", "Scalar", "largest absolute error"),
                Port::output("per_pair", Image::TYPE, "RMSE of each direction pair, grey"),
                Port::output("table", "File", "view θ, φ, light θ, φ, RMSE per pair (CSV)"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let (a, b) = (inputs.get::<Btf>("reference")?, inputs.get::<Btf>("btf")?);
        if (a.width, a.height) != (b.width, b.height) || a.pairs.len() != b.pairs.len() {
            return Err(NodeError::input(
                "btf",
                format!(
                    "is {}×{} with {} pairs, the reference {}×{} with {} pairs",
                    b.width,
                    b.height,
                    b.pairs.len(),
                    a.width,
                    a.height,
                    a.pairs.len()
                ),
            ));
        }
        if let Some(i) = a.pairs.iter().zip(&b.pairs).position(|(x, y)| x != y) {
            return Err(NodeError::input(
                "btf",
                format!("direction pair {i} differs from the reference's"),
            ));
        }
        let plane = 3 * a.width * a.height;
        // Per pair: (sum of squared errors, max abs error), each summed in order.
        let per: Vec<(f64, f64, f64)> = (0..a.pairs.len())
            .into_par_iter()
            .map(|k| {
                let (x, y) = (
                    &a.data[k * plane..(k + 1) * plane],
                    &b.data[k * plane..(k + 1) * plane],
                );
                x.iter().zip(y).fold((0.0, 0.0, 0.0), |(s, m, r), (u, v)| {
                    let d = (*u as f64 - *v as f64).abs();
                    (s + d * d, f64::max(m, d), r + (*u as f64) * (*u as f64))
                })
            })
            .collect();
        let sse: f64 = per.iter().map(|p| p.0).sum();
        let reference_ss: f64 = per.iter().map(|p| p.2).sum();
        let max_error = per.iter().fold(0.0, |m, p| f64::max(m, p.1));
        if !sse.is_finite() {
            return Err(NodeError::input(
                "btf",
                "contains values that are not finite",
            ));
        }
        let rmse = (sse / a.data.len().max(1) as f64).sqrt();
        let relative_rmse = (sse / reference_ss.max(f64::MIN_POSITIVE)).sqrt();
        let peak = a.peak();
        let pair_rmse: Vec<f32> = per
            .iter()
            .map(|(s, _, _)| (s / plane as f64).sqrt() as f32)
            .collect();
        let mut csv = String::from("pair,view_theta,view_phi,light_theta,light_phi,rmse\n");
        // Degrees rounded to 1e-9 so 30° prints as 30, not 29.999999999999996.
        let deg = |r: f64| (r.to_degrees() * 1e9).round() / 1e9;
        for (k, (pair, e)) in a.pairs.iter().zip(&pair_rmse).enumerate() {
            csv.push_str(&format!(
                "{k},{},{},{},{},{e}\n",
                deg(pair.view.theta),
                deg(pair.view.phi),
                deg(pair.light.theta),
                deg(pair.light.phi)
            ));
        }
        let (rows, cols) = grid_shape(a);
        let grid = Image {
            width: cols,
            height: rows,
            channels: 1,
            data: pair_rmse,
        };
        Ok(Outputs::new()
            .with("rmse", Scalar(rmse))
            .with("relative_rmse", Scalar(relative_rmse))
            .with("psnr", Scalar(psnr(peak, rmse)))
            .with("max_error", Scalar(max_error))
            .with("per_pair", grid)
            .with(
                "table",
                Artifact {
                    path: p.table.clone(),
                    bytes: csv.into_bytes(),
                },
            ))
    }
}

/// (views, lights) when pair k = view (k / lights) × light (k % lights) for every k.
fn grid_shape(b: &Btf) -> (usize, usize) {
    let n = b.pairs.len();
    let lights = b
        .pairs
        .iter()
        .take_while(|p| p.view == b.pairs[0].view)
        .count()
        .max(1);
    let is_grid = n.is_multiple_of(lights)
        && b.pairs.iter().enumerate().all(|(k, p)| {
            p.view == b.pairs[k - k % lights].view && p.light == b.pairs[k % lights].light
        });
    if is_grid {
        (n / lights, lights)
    } else {
        (1, n)
    }
}
