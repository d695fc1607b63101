//! `btf.pca`: full-matrix PCA of a BTF in the `texels` layout (rows texels, columns direction
//! pairs × RGB; seed 003): BTF ≈ mean + Σ_k d_k(x) e_k(pair, channel), truncated at a rank or at
//! the smallest rank meeting an error budget.
//!
//! Solver `exact`: the eigendecomposition of the Gram matrix on the smaller side (XᵀX or XXᵀ of the
//! centred matrix X), which gives the truncated SVD, the optimal rank-k approximation
//! (Eckart–Young), so the reported RMSE is √(Σ discarded σ² / N) with N = texels · columns.
//! Gram entries and projections are f64 dot products each summed in a fixed order, parallel over
//! entries, so results do not depend on the thread count; the small eigenproblem runs in faer.
//! (Still to come, issue 3: `randomized`, `per_view` and `directions` layouts, YCbCr.)

use crate::types::{Btf, BtfBasis};
use faer::{Mat, Side};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Number of components. Give at most one of `rank`, `max_rmse`, `energy`; none means rank 8.
    #[schemars(range(min = 0, max = 100000))]
    pub rank: Option<u32>,
    /// Use the smallest rank whose RMSE (linear units) is at most this.
    #[schemars(range(min = 0.0))]
    pub max_rmse: Option<f64>,
    /// Use the smallest rank keeping at least this fraction of the centred energy (Σσ²).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub energy: Option<f64>,
}

pub struct Pca;

/// PSNR is capped here: an exact reconstruction has infinite PSNR, which JSON cannot carry.
pub const PSNR_CAP_DB: f64 = 300.0;

/// 20·log10(peak / rmse) in dB, capped at [`PSNR_CAP_DB`]; peak is the reference's largest value.
pub fn psnr(peak: f64, rmse: f64) -> f64 {
    if rmse <= 0.0 || peak <= 0.0 {
        return if rmse <= 0.0 { PSNR_CAP_DB } else { 0.0 };
    }
    (20.0 * (peak / rmse).log10()).min(PSNR_CAP_DB)
}

impl Node for Pca {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.pca",
            version: 1,
            doc: "Full-matrix PCA of a BTF (texels layout, exact): mean + k coefficient maps × eigen-ABRDFs; rank or error budget.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("btf", Btf::TYPE, "the BTF to compress")],
            outputs: vec![
                Port::output("basis", BtfBasis::TYPE, "mean, coefficient maps, basis, singular values"),
                Port::output("rank", "Scalar", "components kept"),
                Port::output("rmse", "Scalar", "RMS error over texels × pairs × RGB, linear units (Eckart–Young)"),
                Port::output("psnr", "Scalar", "20·log10(max / rmse) dB, capped at 300"),
                Port::output("compression_ratio", "Scalar", "f32 BTF bytes / f32 basis bytes"),
                Port::output("compression_ratio_8bit", "Scalar", "8-bit BTF bytes / f32 basis bytes"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let btf = inputs.get::<Btf>("btf")?;
        let (t, c) = (btf.width * btf.height, btf.pairs.len() * 3);
        if let Some(bad) = btf.data.iter().position(|v| !v.is_finite()) {
            let pair = bad / (3 * t);
            return Err(NodeError::input(
                "btf",
                format!(
                    "value {} (direction pair {pair}) is not finite",
                    btf.data[bad]
                ),
            ));
        }
        let budgets = [p.rank.is_some(), p.max_rmse.is_some(), p.energy.is_some()];
        if budgets.iter().filter(|b| **b).count() > 1 {
            return Err(NodeError::param(
                "rank",
                "give at most one of `rank`, `max_rmse`, `energy`",
            ));
        }
        let full = t.min(c);
        if let Some(r) = p.rank.filter(|r| *r as usize > full) {
            return Err(NodeError::param(
                "rank",
                format!("{r} exceeds min(texels, columns) = min({t}, {c}) = {full}, the largest possible rank"),
            ));
        }
        let col = |j: usize| &btf.data[j * t..(j + 1) * t];
        // Column means, then the centred matrix in f64 (column-major, T×C).
        let mean: Vec<f64> = (0..c)
            .into_par_iter()
            .map(|j| col(j).iter().map(|&v| v as f64).sum::<f64>() / t as f64)
            .collect();
        let mean_ref = &mean;
        let x: Vec<f64> = (0..c)
            .into_par_iter()
            .flat_map_iter(|j| col(j).iter().map(move |&v| v as f64 - mean_ref[j]))
            .collect();
        let x = &x;
        ctx.check_cancel()?;
        let xcol = |j: usize| &x[j * t..(j + 1) * t];
        let total: f64 = (0..c)
            .into_par_iter()
            .map(|j| xcol(j).iter().map(|v| v * v).sum::<f64>())
            .collect::<Vec<_>>()
            .iter()
            .sum();

        // Gram matrix on the smaller side; entry (a, b) is a dot product summed in order.
        let by_columns = c <= t;
        let n = full;
        let row = |i: usize| (0..c).map(move |j| x[j * t + i]);
        let entries: Vec<(usize, usize)> =
            (0..n).flat_map(|a| (0..=a).map(move |b| (a, b))).collect();
        let values: Vec<f64> = entries
            .par_iter()
            .map(|&(a, b)| {
                if by_columns {
                    dot(xcol(a), xcol(b))
                } else {
                    row(a).zip(row(b)).map(|(u, v)| u * v).sum()
                }
            })
            .collect();
        ctx.check_cancel()?;
        ctx.progress(1, 3);
        let mut gram = Mat::<f64>::zeros(n, n);
        for (&(a, b), &v) in entries.iter().zip(&values) {
            gram[(a, b)] = v;
            gram[(b, a)] = v;
        }
        let evd = gram.self_adjoint_eigen(Side::Lower).map_err(|e| {
            NodeError::Failed(format!("eigendecomposition did not converge: {e:?}"))
        })?;
        let eig: Vec<f64> = (0..n)
            .map(|i| evd.S().column_vector()[i].max(0.0))
            .collect();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eig[b].total_cmp(&eig[a]).then(a.cmp(&b)));
        let lambda: Vec<f64> = order.iter().map(|&i| eig[i]).collect();
        ctx.progress(2, 3);

        // Discarded energy from the tail eigenvalues directly (no cancellation against `total`).
        let samples = (t * c) as f64;
        let tail = |k: usize| lambda[k..].iter().rev().sum::<f64>();
        let rmse_at = |k: usize| (tail(k) / samples).sqrt();
        let k = match (p.rank, p.max_rmse, p.energy) {
            (Some(r), _, _) => r as usize,
            (_, Some(m), _) => (0..=n).find(|&k| rmse_at(k) <= m).unwrap_or(n),
            (_, _, Some(e)) => (0..=n)
                .find(|&k| total <= 0.0 || 1.0 - tail(k) / total >= e)
                .unwrap_or(n),
            _ => 8.min(n),
        };
        // Components with σ² below this are numerically zero: their directions are noise.
        let floor = lambda.first().copied().unwrap_or(0.0) * 1e-24;
        let vecs = evd.U();
        let eig_ref = &eig;
        let (coeffs, basis): (Vec<f64>, Vec<f64>) = if by_columns {
            // Gram = XᵀX: eigenvectors are the basis e_k; coefficient maps d_k = X e_k.
            let basis: Vec<f64> = order[..k]
                .iter()
                .flat_map(|&i| (0..c).map(move |j| vecs[(j, i)]))
                .collect();
            let basis_ref = &basis;
            let coeffs = (0..k)
                .into_par_iter()
                .flat_map_iter(|kk| {
                    let e = &basis_ref[kk * c..(kk + 1) * c];
                    (0..t).map(move |i| (0..c).map(|j| x[j * t + i] * e[j]).sum::<f64>())
                })
                .collect();
            (coeffs, basis)
        } else {
            // Gram = XXᵀ: eigenvectors u_k; d_k = σ_k u_k and e_k = Xᵀ u_k / σ_k.
            let coeffs: Vec<f64> = order[..k]
                .iter()
                .flat_map(|&i| (0..t).map(move |r| vecs[(r, i)] * eig_ref[i].sqrt()))
                .collect();
            let basis = order[..k]
                .par_iter()
                .flat_map_iter(|&i| {
                    let s = eig_ref[i].sqrt();
                    (0..c).map(move |j| {
                        if eig_ref[i] > floor {
                            (0..t).map(|r| x[j * t + r] * vecs[(r, i)]).sum::<f64>() / s
                        } else {
                            0.0
                        }
                    })
                })
                .collect();
            (coeffs, basis)
        };
        ctx.progress(3, 3);
        let rmse = rmse_at(k);
        let peak = btf.peak();
        let stored = (c + t * k + c * k + k) as f64 * 4.0;
        let basis = BtfBasis {
            width: btf.width,
            height: btf.height,
            pairs: btf.pairs.clone(),
            rank: k,
            mean: mean.iter().map(|v| *v as f32).collect(),
            coeffs: coeffs.iter().map(|v| *v as f32).collect(),
            basis: basis.iter().map(|v| *v as f32).collect(),
            singular: lambda[..k].iter().map(|l| l.sqrt() as f32).collect(),
        };
        Ok(Outputs::new()
            .with("basis", basis)
            .with("rank", Scalar(k as f64))
            .with("rmse", Scalar(rmse))
            .with("psnr", Scalar(psnr(peak, rmse)))
            .with("compression_ratio", Scalar(samples * 4.0 / stored))
            .with("compression_ratio_8bit", Scalar(samples / stored)))
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::capture::{self, Capture};
    use crate::btf::directions::DirectionSet;
    use crate::types::HeightField;
    use mesoflow_runtime::ValueRef;
    use std::sync::Arc;

    /// A small captured BTF: `n`² texels, `views` × `lights` pairs.
    fn captured(n: usize, views: &[[f64; 2]], lights: &[[f64; 2]]) -> Btf {
        let p = crate::heightfield::procedural::Params {
            pattern: crate::heightfield::procedural::Pattern::Cells,
            size: n as u32,
            depth: 3.0,
            count: 2,
            ..Default::default()
        };
        let hf = HeightField::from_fn(n, n, |x, y| {
            (p.depth
                * crate::heightfield::procedural::unit_height(
                    &p,
                    x as f64 / n as f64,
                    y as f64 / n as f64,
                )) as f32
        });
        let params = capture::Params {
            views: DirectionSet::List(views.to_vec()),
            lights: DirectionSet::List(lights.to_vec()),
            brdf: crate::btf::brdf::Model::Ward,
            ..Default::default()
        };
        let out = Capture
            .run(
                &NodeContext::detached(None),
                &params,
                &Inputs::new().with("height", Arc::new(hf)),
            )
            .unwrap();
        out.get("btf")
            .unwrap()
            .as_any()
            .downcast_ref::<Btf>()
            .unwrap()
            .clone()
    }

    fn pca(btf: &Btf, p: Params) -> Result<Outputs, NodeError> {
        Pca.run(
            &NodeContext::detached(None),
            &p,
            &Inputs::new().with("btf", Arc::new(btf.clone()) as ValueRef),
        )
    }

    fn scalar(o: &Outputs, name: &str) -> f64 {
        o.get(name).unwrap().as_scalar().unwrap()
    }

    /// Singular values of the centred matrix by faer's SVD: an algorithm independent of the Gram
    /// eigendecomposition under test.
    fn reference_singular_values(b: &Btf) -> Vec<f64> {
        let (t, c) = (b.width * b.height, b.pairs.len() * 3);
        let m = Mat::<f64>::from_fn(t, c, |i, j| {
            let col = &b.data[j * t..(j + 1) * t];
            col[i] as f64 - col.iter().map(|v| *v as f64).sum::<f64>() / t as f64
        });
        let s = m
            .thin_svd()
            .unwrap()
            .S()
            .column_vector()
            .iter()
            .copied()
            .collect::<Vec<f64>>();
        let mut s = s;
        s.sort_by(|a, b| b.total_cmp(a));
        s
    }

    #[test]
    fn exact_rmse_is_eckart_young_and_matches_the_reconstruction() {
        let lights = [[0.0, 0.0], [45.0, 90.0], [75.0, 200.0]];
        // 8² texels × 6 pairs: columns (18) ≤ texels (64), Gram = XᵀX;
        // 3² texels × 6 pairs: texels (9) < columns (18), Gram = XXᵀ.
        for n in [8, 3] {
            let btf = captured(n, &[[0.0, 0.0], [60.0, 30.0]], &lights);
            let sigma = reference_singular_values(&btf);
            let samples = btf.data.len() as f64;
            for rank in [1u32, 3, 6] {
                let out = pca(
                    &btf,
                    Params {
                        rank: Some(rank),
                        ..Default::default()
                    },
                )
                .unwrap();
                let basis = out
                    .get("basis")
                    .unwrap()
                    .as_any()
                    .downcast_ref::<BtfBasis>()
                    .unwrap();
                // Eckart–Young: the best rank-k error is the discarded singular values.
                let ey =
                    (sigma[rank as usize..].iter().map(|s| s * s).sum::<f64>() / samples).sqrt();
                let rmse = scalar(&out, "rmse");
                // 1e-4 relative, plus the Gram route's floor: its eigenvalues carry errors of
                // about ε·σ₀² (ε = 2^-52), so an RMSE near zero is only known to
                // √(n·ε)·σ₀/√N; 1e-7·σ₀/√N is above that. (Reached here at full numerical rank:
                // a grey material makes R, G and B columns equal.)
                let floor = 1e-7 * sigma[0] / samples.sqrt();
                assert!(
                    (rmse - ey).abs() <= 1e-4 * ey + floor,
                    "n {n} rank {rank}: {rmse} vs {ey}"
                );
                for (k, s) in basis.singular.iter().enumerate() {
                    // f32 storage of σ: 1e-6 relative.
                    assert!(
                        (*s as f64 - sigma[k]).abs() <= 1e-6 * sigma[0],
                        "σ{k}: {s} vs {}",
                        sigma[k]
                    );
                }
                // The reconstruction's measured error is the reported one. Tolerance: coefficients
                // and basis are stored as f32, adding ~1e-7 relative to each reconstructed value.
                let rec = crate::btf::reconstruct::reconstruct(basis);
                let cmp = crate::btf::compare::Compare
                    .run(
                        &NodeContext::detached(None),
                        &crate::btf::compare::Params::default(),
                        &Inputs::new()
                            .with("reference", Arc::new(btf.clone()))
                            .with("btf", Arc::new(rec)),
                    )
                    .unwrap();
                let measured = scalar(&cmp, "rmse");
                // Below the floor the reconstruction's own f32 rounding (≈ 6e-8 of each value)
                // dominates: compare against that instead.
                let f32_floor = 1e-7 * btf.peak();
                assert!(
                    (measured - rmse).abs() <= 1e-4 * rmse + f32_floor,
                    "n {n} rank {rank}: measured {measured} vs reported {rmse}"
                );
            }
        }
    }

    #[test]
    fn error_budgets_pick_the_smallest_sufficient_rank() {
        let btf = captured(
            8,
            &[[0.0, 0.0], [45.0, 0.0]],
            &[[30.0, 0.0], [60.0, 120.0], [75.0, 300.0]],
        );
        let sigma = reference_singular_values(&btf);
        let samples = btf.data.len() as f64;
        let ey = |k: usize| (sigma[k..].iter().map(|s| s * s).sum::<f64>() / samples).sqrt();
        let target = ey(4) * 1.001; // rank 4 meets it, rank 3 does not
        assert!(ey(3) > target);
        let out = pca(
            &btf,
            Params {
                max_rmse: Some(target),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(scalar(&out, "rank"), 4.0);
        let total: f64 = sigma.iter().map(|s| s * s).sum();
        let kept2: f64 = sigma[..2].iter().map(|s| s * s).sum();
        let out = pca(
            &btf,
            Params {
                energy: Some(kept2 / total * 0.999),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(scalar(&out, "rank"), 2.0);
        let e = pca(
            &btf,
            Params {
                rank: Some(2),
                energy: Some(0.9),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(matches!(e, NodeError::Param { .. }), "{e}");
    }

    #[test]
    fn ill_posed_inputs_give_clear_errors_or_exact_answers() {
        let btf = captured(3, &[[0.0, 0.0]], &[[0.0, 0.0], [45.0, 0.0]]);
        // min(texels 9, columns 6) = 6.
        let e = pca(
            &btf,
            Params {
                rank: Some(7),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("min(9, 6) = 6"), "{e}");
        // A constant BTF: everything is the mean; rank 0 suffices, no NaN anywhere.
        let constant = Btf {
            data: vec![0.25; btf.data.len()],
            ..btf.clone()
        };
        let out = pca(
            &constant,
            Params {
                max_rmse: Some(0.0),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(scalar(&out, "rank"), 0.0);
        assert_eq!(scalar(&out, "rmse"), 0.0);
        assert_eq!(scalar(&out, "psnr"), PSNR_CAP_DB);
        let out = pca(
            &constant,
            Params {
                rank: Some(2),
                ..Default::default()
            },
        )
        .unwrap();
        let b = out
            .get("basis")
            .unwrap()
            .as_any()
            .downcast_ref::<BtfBasis>()
            .unwrap();
        assert!(b.coeffs.iter().chain(&b.basis).all(|v| v.is_finite()));
        // A NaN sample names its direction pair.
        let mut bad = btf.clone();
        let plane = 3 * 9;
        bad.data[plane + 4] = f32::NAN;
        let e = pca(&bad, Params::default()).unwrap_err();
        assert!(e.to_string().contains("direction pair 1"), "{e}");
    }
}
