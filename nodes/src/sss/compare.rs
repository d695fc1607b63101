//! `sss.compare`: how far a diffusion profile is from a reference (usually the Monte Carlo one):
//! the signed relative error of the total diffuse reflectance per channel, and the r-weighted L1
//! error ∫|Rd − Rd_ref| 2πr dr / ∫Rd_ref 2πr dr, which weighs radii by the energy they carry
//! (the quantity a renderer integrates), on the reference's grid.

use crate::types::DiffusionProfile;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {}

pub struct Compare;

const CHANNELS: [&str; 3] = ["r", "g", "b"];

impl Node for Compare {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        let total = "(total − reference total)/reference total";
        let l1 = "r-weighted L1 error of Rd(r), relative to the reference's total";
        let outputs = vec![
            Port::optional_output("total_error_r", "Scalar", total),
            Port::optional_output("total_error_g", "Scalar", total),
            Port::optional_output("total_error_b", "Scalar", total),
            Port::optional_output("l1_r", "Scalar", l1),
            Port::optional_output("l1_g", "Scalar", l1),
            Port::optional_output("l1_b", "Scalar", l1),
            Port::optional_output(
                "total_error",
                "Scalar",
                "largest |total_error_c| over the channels",
            ),
            Port::optional_output("l1", "Scalar", "mean of l1_r, l1_g, l1_b"),
        ];
        NodeSpec {
            kind: "sss.compare",
            version: 1,
            doc: "Error of a diffusion profile against a reference: relative error of the total reflectance and r-weighted L1 error of Rd(r), per channel.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("reference", DiffusionProfile::TYPE, "the reference (montecarlo)"),
                Port::input("profile", DiffusionProfile::TYPE, "the profile to measure"),
            ],
            outputs,
            disk_cache: false,
        }
    }

    fn run(&self, ctx: &NodeContext, _p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let reference = inputs.get::<DiffusionProfile>("reference")?;
        let profile = inputs.get::<DiffusionProfile>("profile")?;
        let e = compare(reference, profile).map_err(|m| NodeError::input("reference", m))?;
        // A channel whose reference carries no energy has no relative error: those metrics are
        // absent (with a warning), never 0 or infinite.
        let mut out = Outputs::new();
        for (c, name) in CHANNELS.iter().enumerate() {
            match (e.total[c], e.l1[c]) {
                (Some(t), Some(l)) => {
                    out = out
                        .with(&format!("total_error_{name}"), Scalar(t))
                        .with(&format!("l1_{name}"), Scalar(l));
                }
                _ => ctx.warn(format!(
                    "the reference's channel {name} carries no energy: no relative error for it"
                )),
            }
        }
        if let (Some(t), Some(l)) = (
            e.total.iter().copied().collect::<Option<Vec<f64>>>(),
            e.l1.iter().copied().collect::<Option<Vec<f64>>>(),
        ) {
            let worst = t.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            out = out
                .with("total_error", Scalar(worst))
                .with("l1", Scalar(l.iter().sum::<f64>() / 3.0));
        }
        Ok(out)
    }
}

/// Per channel; `None` where the reference's channel is zero (a relative error is undefined).
pub struct Errors {
    pub total: [Option<f64>; 3],
    pub l1: [Option<f64>; 3],
}

/// Rd of `p` at radius r: linear in ln r between grid points, the first value inside the grid,
/// 0 beyond it (the grid holds 99.9% of the energy).
pub fn sample(p: &DiffusionProfile, c: usize, r: f64) -> f64 {
    let radii = &p.radii;
    let i = radii.partition_point(|&x| x < r);
    if i == 0 {
        return p.rd[c][0];
    }
    if i >= radii.len() {
        return 0.0;
    }
    let t = (r.ln() - radii[i - 1].ln()) / (radii[i].ln() - radii[i - 1].ln());
    p.rd[c][i - 1] * (1.0 - t) + p.rd[c][i] * t
}

pub fn compare(reference: &DiffusionProfile, p: &DiffusionProfile) -> Result<Errors, String> {
    if reference.radii.len() < 2 {
        return Err("the reference profile has fewer than two radii".into());
    }
    let mut total = [None; 3];
    let mut l1 = [None; 3];
    for c in 0..3 {
        let t = reference.total[c];
        total[c] = (t > 0.0).then(|| (p.total[c] - t) / t);
        // Trapezoids in ln r on the reference's grid.
        let radii = &reference.radii;
        let f = |i: usize| {
            let r = radii[i];
            (sample(p, c, r) - reference.rd[c][i]).abs() * 2.0 * PI * r * r
        };
        let g = |i: usize| reference.rd[c][i] * 2.0 * PI * radii[i] * radii[i];
        let (mut num, mut den) = (0.0, 0.0);
        for i in 1..radii.len() {
            let h = radii[i].ln() - radii[i - 1].ln();
            num += 0.5 * (f(i - 1) + f(i)) * h;
            den += 0.5 * (g(i - 1) + g(i)) * h;
        }
        l1[c] = (den > 0.0).then(|| num / den);
    }
    Ok(Errors { total, l1 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(rd: impl Fn(f64) -> f64, total: f64) -> DiffusionProfile {
        let radii: Vec<f64> = (0..400).map(|i| 1e-3 * 1.03f64.powi(i)).collect();
        let v: Vec<f64> = radii.iter().map(|&r| rd(r)).collect();
        DiffusionProfile {
            model: "test".into(),
            rd: [v.clone(), v.clone(), v],
            cdf: Default::default(),
            radii,
            total: [total; 3],
            mfp: [1.0; 3],
        }
    }

    #[test]
    fn identical_profiles_have_no_error_and_a_scaled_one_has_the_scale() {
        let a = profile(|r| (-r).exp(), 1.0);
        let e = compare(&a, &a).unwrap();
        assert!(e.total.iter().chain(&e.l1).all(|v| *v == Some(0.0)));
        // 1.1 × Rd: the L1 error is exactly 0.1 of the reference energy (interpolation is exact
        // on the shared grid), the total error is what the totals say.
        let b = profile(|r| 1.1 * (-r).exp(), 1.1);
        let e = compare(&a, &b).unwrap();
        let near = |v: &Option<f64>| v.is_some_and(|v| (v - 0.1).abs() < 1e-12);
        assert!(e.l1.iter().all(near), "{:?}", e.l1);
        assert!(e.total.iter().all(near));
    }

    #[test]
    fn a_zero_reference_has_no_relative_error() {
        let zero = profile(|_| 0.0, 0.0);
        let b = profile(|r| (-r).exp(), 1.0);
        let e = compare(&zero, &b).unwrap();
        assert!(e.total.iter().chain(&e.l1).all(Option::is_none));
    }

    #[test]
    fn interpolation_between_grids_is_log_linear() {
        let a = profile(|r| r.ln(), 1.0);
        // ln r is linear in ln r: exact between grid points; 0 beyond the grid.
        let r = 0.5 * (a.radii[10] + a.radii[11]);
        assert!((sample(&a, 0, r) - r.ln()).abs() < 1e-12);
        assert_eq!(sample(&a, 1, 1e9), 0.0);
    }
}
