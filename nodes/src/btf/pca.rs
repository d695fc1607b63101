//! `btf.pca`: PCA compression of a BTF (seed 003; Sattler et al. 2003 for `per_view`).
//!
//! The BTF is a T×C matrix (rows texels, columns direction pairs × channels), which is exactly the
//! `Btf` buffer read column-major, so no copy is made for RGB. Layouts:
//! - `texels`: rows are samples; column means removed; maps are per-texel coefficient maps, basis
//!   vectors eigen-ABRDFs;
//! - `directions`: the transpose; each texel's mean over directions removed; maps are
//!   eigen-textures, basis vectors per-direction weights (the SVD of the transpose has the same
//!   singular vectors, so only the centring differs);
//! - `per_view`: one `texels` factorization per view over its lights (Sattler et al.).
//!
//! Colour `ycbcr` converts to linear YCbCr (one extra copy of the BTF) and factors Y, Cb and Cr
//! separately with `rank` and `chroma_rank` (seed 003: 8 Y, 2 Cb, 2 Cr).
//!
//! Solvers (see `factor`): `exact` is the truncated SVD — dense Gram eigendecomposition when the
//! block's smaller side is ≤ 1024, else subspace iteration converged to a 1e-6·σ₀ residual;
//! `randomized` is Halko et al. with `oversampling` and `power_iterations`. Error budgets
//! (`max_rmse`, `energy`) pick the smallest rank meeting them per block: exactly from all singular
//! values on the dense route, from growing sketches otherwise.
//!
//! The reported RMSE is the reconstruction's (before f32 storage of the factors): for RGB the
//! projection residual ‖X‖² − ‖XV‖², which for `exact` is the Eckart–Young value; for YCbCr the
//! error measured in RGB after the inverse transform.

use super::factor::{self, Block, Factors, Stop};
use crate::types::{BasisBlock, Btf, BtfBasis, Centring, ColorSpace};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// Rows texels, columns pairs × channels: coefficient maps and eigen-ABRDFs.
    #[default]
    Texels,
    /// The transpose: eigen-textures and per-direction weights.
    Directions,
    /// One factorization per view over its lights (Sattler et al. 2003).
    PerView,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// The truncated SVD (dense Gram eigendecomposition, or subspace iteration to convergence).
    #[default]
    Exact,
    /// Halko, Martinsson & Tropp's randomized SVD.
    Randomized,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Color {
    #[default]
    Rgb,
    /// Linear YCbCr, luma with `rank` components and each chroma channel with `chroma_rank`.
    Ycbcr,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// What the rows of the factorised matrix are: `texels` (coefficient maps × eigen-ABRDFs), `directions` (eigen-textures × per-direction weights) or `per_view` (one factorisation per view).
    pub layout: Layout,
    /// `exact` truncated SVD or `randomized` (Halko et al.): faster on large BTFs, with `power_iterations` for accuracy.
    pub solver: Solver,
    /// Components per block (luma with `ycbcr`). Give at most one of `rank`, `max_rmse`,
    /// `energy`; none means rank 8.
    #[schemars(range(min = 0, max = 100000))]
    pub rank: Option<u32>,
    /// Smallest rank whose RMSE (linear units; per block, in the block's channel) is at most this.
    #[schemars(range(min = 0.0))]
    pub max_rmse: Option<f64>,
    /// Smallest rank keeping at least this fraction of each block's centred energy (Σσ²).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub energy: Option<f64>,
    /// Colour space of the factorisation: `rgb`, or `ycbcr` (luma at `rank`, chroma at `chroma_rank`).
    pub color: Color,
    /// Components of each chroma channel with `ycbcr`; default max(1, luma rank / 4).
    #[schemars(range(min = 0, max = 100000))]
    pub chroma_rank: Option<u32>,
    /// Randomized: extra sketch vectors beyond the rank (Halko's p).
    #[schemars(range(min = 0, max = 1000))]
    pub oversampling: u32,
    /// Randomized: power iterations (Halko's q).
    #[schemars(range(min = 0, max = 100))]
    pub power_iterations: u32,
    /// Randomized: seed of the Gaussian test matrix.
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            layout: Layout::Texels,
            solver: Solver::Exact,
            rank: None,
            max_rmse: None,
            energy: None,
            color: Color::Rgb,
            chroma_rank: None,
            oversampling: 10,
            power_iterations: 2,
            seed: 0,
        }
    }
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

/// What one block asks of the solver.
enum Budget {
    Rank(usize),
    /// Largest allowed residual energy.
    Residual(f64),
    /// Fraction of the energy to keep.
    Energy(f64),
}

/// One block to factor: pairs, channel and the rank it gets.
struct Plan {
    first_pair: usize,
    pair_count: usize,
    channel: Option<u8>,
}

impl Plan {
    /// Cb or Cr, which get `chroma_rank`.
    fn chroma(&self) -> bool {
        self.channel.is_some_and(|c| c > 0)
    }
}

impl Node for Pca {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.pca",
            version: 2,
            doc: "PCA of a BTF: texels/directions/per_view layouts, exact or randomized SVD, rank or error budget, RGB or YCbCr.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("btf", Btf::TYPE, "the BTF to compress")],
            outputs: vec![
                Port::output("basis", BtfBasis::TYPE, "blocks of mean, maps, basis, singular values"),
                Port::output("rank", "Scalar", "components of the largest block (luma with ycbcr)"),
                Port::output("rmse", "Scalar", "RMS error over texels × pairs × RGB, linear units"),
                Port::output("psnr", "Scalar", "20·log10(max / rmse) dB, capped at 300"),
                Port::output("compression_ratio", "Scalar", "f32 BTF bytes / f32 basis bytes"),
                Port::output("compression_ratio_8bit", "Scalar", "8-bit BTF bytes / f32 basis bytes"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        let budgets = [p.rank.is_some(), p.max_rmse.is_some(), p.energy.is_some()];
        if budgets.iter().filter(|b| **b).count() > 1 {
            return Err(NodeError::param(
                "rank",
                "give at most one of `rank`, `max_rmse`, `energy`",
            ));
        }
        if p.chroma_rank.is_some() && p.color != Color::Ycbcr {
            return Err(NodeError::param(
                "chroma_rank",
                "only applies with \"color\": \"ycbcr\"",
            ));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let btf = inputs.get::<Btf>("btf")?;
        let t = btf.width * btf.height;
        if let Some(bad) = btf.first_non_finite() {
            let pair = bad / (3 * t);
            return Err(NodeError::input(
                "btf",
                format!(
                    "value {} (direction pair {pair}) is not finite",
                    btf.data[bad]
                ),
            ));
        }
        let plans = plan(btf, p);
        let (color, converted) = match p.color {
            Color::Rgb => (ColorSpace::Rgb, None),
            Color::Ycbcr => (ColorSpace::YCbCr, Some(to_color(btf, ColorSpace::YCbCr))),
        };
        let data = converted.as_deref().unwrap_or(&btf.data);
        let centring = match p.layout {
            Layout::Directions => Centring::Texels,
            _ => Centring::Columns,
        };
        let luma_rank = p.rank.map(|r| r as usize);
        let chroma_rank = p
            .chroma_rank
            .map(|r| r as usize)
            .or(luma_rank.map(|r| (r / 4).max(1)));

        let mut blocks = Vec::with_capacity(plans.len());
        let mut residual = 0.0;
        for (done, pl) in plans.iter().enumerate() {
            ctx.check_cancel()?;
            let (offset, stride, cols) = match pl.channel {
                Some(c) => ((pl.first_pair * 3 + c as usize) * t, 3 * t, pl.pair_count),
                None => (pl.first_pair * 3 * t, t, pl.pair_count * 3),
            };
            let x = Block::new(data, t, cols, offset, stride, centring);
            let full = t.min(cols);
            let (param, wanted) = if pl.chroma() {
                ("chroma_rank", chroma_rank)
            } else {
                ("rank", luma_rank)
            };
            let budget = match (wanted, p.max_rmse, p.energy) {
                (Some(r), _, _) => {
                    if r > full {
                        return Err(NodeError::param(
                            param,
                            format!(
                                "{r} exceeds min(texels, columns) = min({t}, {cols}) = {full}, the largest possible rank{}",
                                if plans.len() > 1 { " of a block" } else { "" }
                            ),
                        ));
                    }
                    Budget::Rank(r)
                }
                (_, Some(m), _) => Budget::Residual(m * m * (t * cols) as f64),
                (_, _, Some(e)) => Budget::Energy(e),
                _ => Budget::Rank(8.min(full)),
            };
            let f = solve(&x, &budget, p, ctx).map_err(NodeError::Failed)?;
            if let Some(worst) = f.unconverged {
                ctx.warn(format!(
                    "exact solver stopped after {} iterations with relative residual {worst:.2e} (target {:.0e})",
                    factor::EXACT_MAX_ITERATIONS,
                    factor::EXACT_TOLERANCE
                ));
            }
            residual += f.residual;
            blocks.push(to_block(pl, centring, &x, &f));
            ctx.progress(done as u64 + 1, plans.len() as u64);
        }
        let basis = BtfBasis {
            width: btf.width,
            height: btf.height,
            pairs: btf.pairs.clone(),
            color,
            blocks,
        };
        let samples = btf.data.len() as f64;
        let rmse = match color {
            ColorSpace::Rgb => (residual / samples.max(1.0)).sqrt(),
            // The transform is not orthogonal: measure the error in RGB.
            ColorSpace::YCbCr => measured_rmse(btf, &basis),
        };
        let rank = basis
            .blocks
            .iter()
            .filter(|b| b.channel.is_none_or(|c| c == 0))
            .map(|b| b.rank())
            .max()
            .unwrap_or(0);
        let stored = basis
            .blocks
            .iter()
            .map(|b| b.floats())
            .sum::<usize>()
            .max(1) as f64
            * 4.0;
        Ok(Outputs::new()
            .with("basis", basis)
            .with("rank", Scalar(rank as f64))
            .with("rmse", Scalar(rmse))
            .with("psnr", Scalar(psnr(btf.peak(), rmse)))
            .with("compression_ratio", Scalar(samples * 4.0 / stored))
            .with("compression_ratio_8bit", Scalar(samples / stored)))
    }
}

/// The blocks a layout and colour space ask for.
fn plan(btf: &Btf, p: &Params) -> Vec<Plan> {
    let runs: Vec<(usize, usize)> = match p.layout {
        Layout::PerView => {
            let mut runs: Vec<(usize, usize)> = Vec::new();
            for (i, pair) in btf.pairs.iter().enumerate() {
                match runs.last_mut() {
                    Some((first, count)) if btf.pairs[*first].view == pair.view => *count += 1,
                    _ => runs.push((i, 1)),
                }
            }
            runs
        }
        _ => vec![(0, btf.pairs.len())],
    };
    runs.into_iter()
        .flat_map(|(first_pair, pair_count)| {
            let channels: Vec<Option<u8>> = match p.color {
                Color::Rgb => vec![None],
                Color::Ycbcr => vec![Some(0), Some(1), Some(2)],
            };
            channels.into_iter().map(move |channel| Plan {
                first_pair,
                pair_count,
                channel,
            })
        })
        .collect()
}

/// The BTF's planes converted to another colour space (same layout).
fn to_color(btf: &Btf, color: ColorSpace) -> Vec<f32> {
    let t = btf.width * btf.height;
    let mut out = vec![0f32; btf.data.len()];
    out.par_chunks_mut(3 * t.max(1))
        .zip(btf.data.par_chunks(3 * t.max(1)))
        .for_each(|(dst, src)| {
            for i in 0..t {
                let c = color.from_rgb([src[i] as f64, src[t + i] as f64, src[2 * t + i] as f64]);
                for ch in 0..3 {
                    dst[ch * t + i] = c[ch] as f32;
                }
            }
        });
    out
}

/// RMSE of the basis's reconstruction against the BTF, pair by pair (sums in pair order).
fn measured_rmse(btf: &Btf, basis: &BtfBasis) -> f64 {
    let t = btf.width * btf.height;
    let owners = basis.column_owners();
    let per_pair: Vec<f64> = (0..btf.pairs.len())
        .into_par_iter()
        .map(|pair| {
            let mut out = vec![0f32; 3 * t];
            super::reconstruct::pair_into(basis, &owners, pair, &mut out);
            out.iter()
                .zip(btf.pair_image(pair))
                .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
                .sum::<f64>()
        })
        .collect();
    (per_pair.iter().sum::<f64>() / btf.data.len().max(1) as f64).sqrt()
}

/// Factor one block to its budget with the chosen solver.
fn solve(x: &Block, budget: &Budget, p: &Params, ctx: &NodeContext) -> Result<Factors, String> {
    let n = x.rows.min(x.cols);
    let meets = |residual: f64| match *budget {
        Budget::Rank(_) => true,
        Budget::Residual(r) => residual <= r,
        Budget::Energy(e) => x.energy <= 0.0 || 1.0 - residual / x.energy >= e,
    };
    let cancelled = || ctx.is_cancelled();
    if p.solver == Solver::Exact && n <= factor::DENSE_MAX {
        let pick = |lambda: &[f64]| match *budget {
            Budget::Rank(k) => k,
            _ => (0..=n)
                .find(|&k| meets(lambda[k..].iter().rev().sum::<f64>()))
                .unwrap_or(n),
        };
        return factor::dense(x, &pick).map(|(f, _)| f);
    }
    let run = |k: usize| match p.solver {
        Solver::Exact => factor::iterative(x, k, k.max(10), Stop::Converged, p.seed, &cancelled),
        Solver::Randomized => factor::iterative(
            x,
            k,
            p.oversampling as usize,
            Stop::PowerIterations(p.power_iterations as usize),
            p.seed,
            &cancelled,
        ),
    };
    if let Budget::Rank(k) = *budget {
        return run(k);
    }
    // Budgets: grow the rank until the residual meets it, then keep the smallest rank whose
    // estimated residual (the solved residual plus the σ² dropped) still does.
    let mut k = 8.min(n);
    loop {
        let f = run(k)?;
        if meets(f.residual) || k == n {
            let mut keep = k;
            while keep > 0
                && meets(f.residual + f.sigma[keep - 1..k].iter().map(|s| s * s).sum::<f64>())
            {
                keep -= 1;
            }
            return Ok(truncate(x, f, keep));
        }
        k = (2 * k).min(n);
    }
}

/// The first `keep` components of a factorization, with the residual recomputed from D.
fn truncate(x: &Block, f: Factors, keep: usize) -> Factors {
    let k = f.sigma.len();
    if keep == k {
        return f;
    }
    let v = f.v.subcols(0, keep).to_owned();
    let d = f.d.subcols(0, keep).to_owned();
    let kept: f64 = (0..keep)
        .map(|kk| d.col_as_slice(kk).iter().map(|v| v * v).sum::<f64>())
        .sum();
    Factors {
        v,
        d,
        sigma: f.sigma[..keep].to_vec(),
        residual: (x.energy - kept).max(0.0),
        unconverged: f.unconverged,
    }
}

fn to_block(pl: &Plan, centring: Centring, x: &Block, f: &Factors) -> BasisBlock {
    let k = f.sigma.len();
    let col_major = |m: &faer::Mat<f64>| -> Vec<f32> {
        (0..k)
            .flat_map(|kk| {
                m.col_as_slice(kk)
                    .iter()
                    .map(|v| *v as f32)
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    BasisBlock {
        first_pair: pl.first_pair,
        pair_count: pl.pair_count,
        channel: pl.channel,
        centring,
        mean: x.mean.iter().map(|v| *v as f32).collect(),
        maps: col_major(&f.d),
        basis: col_major(&f.v),
        singular: f.sigma.iter().map(|s| *s as f32).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::capture::{self, Capture};
    use crate::btf::directions::DirectionSet;
    use crate::types::HeightField;
    use faer::Mat;
    use mesoflow_runtime::ValueRef;
    use mesoflow_testkit::node::OutputsExt;
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
            brdf: crate::reflectance::models::Model::Ward,
            ..Default::default()
        };
        let out = mesoflow_testkit::node::run(
            &Capture,
            &params,
            &Inputs::new().with("height", Arc::new(hf)),
        )
        .unwrap();
        out.value::<Btf>("btf").clone()
    }

    fn pca(btf: &Btf, p: Params) -> Result<Outputs, NodeError> {
        // As the engine does: the parameter checks, then the run.
        Pca.check(&p)?;
        mesoflow_testkit::node::run(
            &Pca,
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
        singular_values(&m)
    }

    /// faer's dense SVD, largest first.
    fn singular_values(m: &Mat<f64>) -> Vec<f64> {
        let mut s: Vec<f64> = m
            .thin_svd()
            .unwrap()
            .S()
            .column_vector()
            .iter()
            .copied()
            .collect();
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
                let basis = &basis_of(&out);
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
                for (k, s) in basis.blocks[0].singular.iter().enumerate() {
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
                let cmp = mesoflow_testkit::node::run(
                    &crate::btf::compare::Compare,
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
        let b = basis_of(&out);
        assert!(b.blocks[0]
            .maps
            .iter()
            .chain(&b.blocks[0].basis)
            .all(|v| v.is_finite()));
        // A NaN sample names its direction pair.
        let mut bad = btf.clone();
        let plane = 3 * 9;
        bad.data[plane + 4] = f32::NAN;
        let e = pca(&bad, Params::default()).unwrap_err();
        assert!(e.to_string().contains("direction pair 1"), "{e}");
    }

    fn basis_of(o: &Outputs) -> BtfBasis {
        o.value::<BtfBasis>("basis").clone()
    }

    /// RMSE of the reconstruction, computed here from the samples (independent of the node's
    /// residual bookkeeping).
    fn measured(btf: &Btf, b: &BtfBasis) -> f64 {
        let rec = crate::btf::reconstruct::reconstruct(b);
        let s: f64 = rec
            .data
            .iter()
            .zip(&btf.data)
            .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
            .sum();
        (s / btf.data.len() as f64).sqrt()
    }

    fn grid_btf(n: usize) -> Btf {
        captured(
            n,
            &[[0.0, 0.0], [30.0, 0.0], [60.0, 90.0]],
            &[[0.0, 0.0], [30.0, 60.0], [45.0, 180.0], [70.0, 270.0]],
        )
    }

    #[test]
    fn directions_layout_is_the_transposed_pca() {
        // Centring each texel over its 36 columns, then the SVD: singular values of that matrix
        // by faer's dense SVD are the reference.
        let btf = grid_btf(8);
        let (t, c) = (64, btf.pairs.len() * 3);
        let m = Mat::<f64>::from_fn(t, c, |i, j| {
            let row_mean = (0..c).map(|jj| btf.data[jj * t + i] as f64).sum::<f64>() / c as f64;
            btf.data[j * t + i] as f64 - row_mean
        });
        let sigma = singular_values(&m);
        let out = pca(
            &btf,
            Params {
                layout: Layout::Directions,
                rank: Some(5),
                ..Default::default()
            },
        )
        .unwrap();
        let b = basis_of(&out);
        assert_eq!(b.blocks[0].centring, Centring::Texels);
        assert_eq!(b.blocks[0].mean.len(), t);
        let ey = (sigma[5..].iter().map(|s| s * s).sum::<f64>() / btf.data.len() as f64).sqrt();
        let rmse = scalar(&out, "rmse");
        // Eckart–Young to 1e-4 relative (the bound) and the reconstruction agrees to
        // f32 storage (1e-7 of the peak).
        assert!((rmse - ey).abs() <= 1e-4 * ey, "{rmse} vs {ey}");
        assert!((measured(&btf, &b) - rmse).abs() <= 1e-4 * rmse + 1e-7 * btf.peak());
    }

    #[test]
    fn per_view_factors_each_view_and_beats_the_global_basis_at_equal_rank() {
        let btf = grid_btf(8);
        let out = pca(
            &btf,
            Params {
                layout: Layout::PerView,
                rank: Some(2),
                ..Default::default()
            },
        )
        .unwrap();
        let b = basis_of(&out);
        assert_eq!(b.blocks.len(), 3);
        assert!(b
            .blocks
            .iter()
            .all(|blk| blk.pair_count == 4 && blk.rank() == 2));
        let rmse = scalar(&out, "rmse");
        assert!((measured(&btf, &b) - rmse).abs() <= 1e-4 * rmse + 1e-7 * btf.peak());
        // Independent check per view: the Eckart–Young error of each view's own matrix.
        let t = 64;
        let mut discarded = 0.0;
        for v in 0..3 {
            let cols = 12;
            let m = Mat::<f64>::from_fn(t, cols, |i, j| {
                let col = &btf.data[(v * cols + j) * t..(v * cols + j + 1) * t];
                col[i] as f64 - col.iter().map(|x| *x as f64).sum::<f64>() / t as f64
            });
            let s = singular_values(&m);
            discarded += s[2..].iter().map(|x| x * x).sum::<f64>();
        }
        let ey = (discarded / btf.data.len() as f64).sqrt();
        assert!((rmse - ey).abs() <= 1e-4 * ey, "{rmse} vs {ey}");
        let global = pca(
            &btf,
            Params {
                rank: Some(2),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(rmse < scalar(&global, "rmse"));
        assert!(scalar(&out, "compression_ratio") < scalar(&global, "compression_ratio"));
    }

    #[test]
    fn ycbcr_gives_chroma_its_own_rank_and_reports_the_rgb_error() {
        let btf = grid_btf(8);
        let out = pca(
            &btf,
            Params {
                color: Color::Ycbcr,
                rank: Some(8),
                chroma_rank: Some(2),
                ..Default::default()
            },
        )
        .unwrap();
        let b = basis_of(&out);
        let ranks: Vec<usize> = b.blocks.iter().map(|blk| blk.rank()).collect();
        assert_eq!(ranks, vec![8, 2, 2]);
        assert_eq!(scalar(&out, "rank"), 8.0);
        let rmse = scalar(&out, "rmse");
        // The node measures in RGB after the inverse transform; so does `measured`, from the
        // f32-stored factors: they agree to that storage (1e-7 of the peak).
        assert!((measured(&btf, &b) - rmse).abs() <= 1e-6 * rmse + 1e-7 * btf.peak());
        let e = pca(
            &btf,
            Params {
                chroma_rank: Some(2),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("chroma_rank"), "{e}");
    }

    #[test]
    fn randomized_is_within_two_percent_of_exact() {
        // 4 views × 10 lights: a grey material makes R = G = B, so the numerical rank is at most
        // the 40 pairs, above rank 16 + oversampling 10.
        let lights: Vec<[f64; 2]> = (0..10)
            .map(|i| [10.0 + 6.0 * i as f64, 37.0 * i as f64])
            .collect();
        let btf = captured(
            16,
            &[[0.0, 0.0], [30.0, 0.0], [45.0, 120.0], [60.0, 250.0]],
            &lights,
        );
        let exact = |rank| {
            pca(
                &btf,
                Params {
                    rank: Some(rank),
                    ..Default::default()
                },
            )
            .unwrap()
        };
        for rank in [4u32, 8, 16] {
            let e = scalar(&exact(rank), "rmse");
            let r = pca(
                &btf,
                Params {
                    solver: Solver::Randomized,
                    rank: Some(rank),
                    ..Default::default()
                },
            )
            .unwrap();
            // The bound: within 2% of exact with default parameters.
            let ratio = scalar(&r, "rmse") / e;
            assert!((1.0 - 1e-5..=1.02).contains(&ratio), "rank {rank}: {ratio}");
        }
        // A budget on the randomized path meets it.
        let target = scalar(&exact(6), "rmse") * 1.01;
        let r = pca(
            &btf,
            Params {
                solver: Solver::Randomized,
                max_rmse: Some(target),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(scalar(&r, "rmse") <= target);
        assert!(scalar(&r, "rank") <= 7.0, "{}", scalar(&r, "rank"));
    }
}
