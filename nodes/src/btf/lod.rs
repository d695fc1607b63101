//! `btf.lod`: continuous level of detail of a PCA basis (seed 003, eq. 5). The coefficient maps
//! (and per-texel means) are mipmapped with a box filter; level λ = L + f (0 ≤ f < 1) is
//! `Σ_{k=L}^{max} w_k band_k` with `w_k = min(max(1 − λ + k, 0), 1)`, where band_k is the
//! difference between mip level k and level k+1 (nearest-upsampled) and the coarsest band is the
//! coarsest level. The sum telescopes to `(1 − f)·mip_L + f·up(mip_{L+1})` at level L's
//! resolution, which is what is computed. Reconstruction is linear in the maps, so the level-k
//! basis reconstructs exactly the box-downsampled full reconstruction.

use crate::types::{BasisBlock, BtfBasis, Centring};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Level λ ≥ 0: 0 is the full resolution, each unit halves it; fractions blend two levels.
    #[schemars(range(min = 0.0, max = 16.0))]
    pub level: f64,
}

pub struct Lod;

/// Box average of `factor`×`factor` squares of a W×H map (W, H divisible by `factor`).
pub fn box_down(map: &[f32], w: usize, h: usize, factor: usize) -> Vec<f64> {
    let (ow, oh) = (w / factor, h / factor);
    let norm = (factor * factor) as f64;
    (0..ow * oh)
        .map(|o| {
            let (ox, oy) = (o % ow, o / ow);
            let mut s = 0.0;
            for y in oy * factor..(oy + 1) * factor {
                for x in ox * factor..(ox + 1) * factor {
                    s += map[y * w + x] as f64;
                }
            }
            s / norm
        })
        .collect()
}

/// One W×H map at level λ = level + frac, at the resolution of `level`.
fn map_at(map: &[f32], w: usize, h: usize, level: usize, frac: f64) -> Vec<f32> {
    let fine = box_down(map, w, h, 1 << level);
    if frac == 0.0 {
        return fine.iter().map(|v| *v as f32).collect();
    }
    let coarse = box_down(map, w, h, 2 << level);
    let (fw, cw) = (w >> level, w >> (level + 1));
    fine.iter()
        .enumerate()
        .map(|(i, v)| {
            let (x, y) = (i % fw, i / fw);
            ((1.0 - frac) * v + frac * coarse[(y / 2) * cw + x / 2]) as f32
        })
        .collect()
}

/// The basis at level λ.
pub fn at_level(b: &BtfBasis, lambda: f64) -> Result<BtfBasis, String> {
    if !(lambda.is_finite() && lambda >= 0.0) {
        return Err(format!("{lambda} is not a level ≥ 0"));
    }
    let level = lambda.floor() as usize;
    let frac = lambda - level as f64;
    let deepest = level + usize::from(frac > 0.0);
    let factor = 1usize << deepest;
    if !b.width.is_multiple_of(factor) || !b.height.is_multiple_of(factor) {
        return Err(format!(
            "level {lambda} needs the {}×{} maps halved {deepest} times, but they are not divisible by {factor}",
            b.width, b.height
        ));
    }
    let (w, h) = (b.width, b.height);
    let t = w * h;
    let blocks = b
        .blocks
        .par_iter()
        .map(|blk| {
            let maps = (0..blk.rank())
                .flat_map(|k| map_at(&blk.maps[k * t..(k + 1) * t], w, h, level, frac))
                .collect();
            let mean = match blk.centring {
                Centring::Columns => blk.mean.clone(),
                Centring::Texels => map_at(&blk.mean, w, h, level, frac),
            };
            BasisBlock {
                mean,
                maps,
                ..blk.clone()
            }
        })
        .collect();
    Ok(BtfBasis {
        width: w >> level,
        height: h >> level,
        pairs: b.pairs.clone(),
        color: b.color,
        blocks,
    })
}

impl Node for Lod {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.lod",
            version: 1,
            doc: "Continuous level of detail of a PCA basis: box-mipmapped coefficient maps blended with w_k = min(max(1−λ+k,0),1).",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("basis", BtfBasis::TYPE, "the full-resolution basis")],
            outputs: vec![
                Port::output("basis", BtfBasis::TYPE, "the basis at level λ (resolution of ⌊λ⌋)"),
                Port::output("width", "Scalar", "texels across at this level"),
            ],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let b = inputs.get::<BtfBasis>("basis")?;
        let out = at_level(b, p.level).map_err(|e| NodeError::param("level", e))?;
        let width = out.width;
        Ok(Outputs::new()
            .with("basis", out)
            .with("width", Scalar(width as f64)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::reconstruct::reconstruct;
    use crate::types::{Btf, ColorSpace, Direction, DirectionPair};

    /// A basis with hashed content: two blocks (one per-column centred, one per-texel centred).
    fn basis(w: usize, h: usize) -> BtfBasis {
        let t = w * h;
        let r = |s: u64, i: usize| {
            crate::support::rng::unit(crate::support::rng::hash(s, &[i as u64])) as f32
        };
        let pair = |v: f64| DirectionPair {
            view: Direction::degrees(v, 0.0),
            light: Direction::degrees(0.0, 0.0),
        };
        let block = |first_pair, centring, seed: u64| {
            let (cols, k) = (3, 2);
            BasisBlock {
                first_pair,
                pair_count: 1,
                channel: None,
                centring,
                mean: (0..if centring == Centring::Texels {
                    t
                } else {
                    cols
                })
                    .map(|i| r(seed, i))
                    .collect(),
                maps: (0..t * k).map(|i| r(seed + 1, i) - 0.5).collect(),
                basis: (0..cols * k).map(|i| r(seed + 2, i)).collect(),
                singular: vec![2.0, 1.0],
            }
        };
        BtfBasis {
            width: w,
            height: h,
            pairs: vec![pair(0.0), pair(30.0)],
            color: ColorSpace::Rgb,
            blocks: vec![
                block(0, Centring::Columns, 10),
                block(1, Centring::Texels, 20),
            ],
        }
    }

    /// Box-downsampling of a BTF's planes, written independently of `box_down`.
    fn downsample(b: &Btf, f: usize) -> Vec<f64> {
        let (w, h) = (b.width, b.height);
        let (ow, oh) = (w / f, h / f);
        let mut out = vec![0f64; b.data.len() / (f * f)];
        for plane in 0..b.pairs.len() * 3 {
            for y in 0..h {
                for x in 0..w {
                    out[plane * ow * oh + (y / f) * ow + x / f] +=
                        b.data[plane * w * h + y * w + x] as f64 / (f * f) as f64;
                }
            }
        }
        out
    }

    #[test]
    fn integer_levels_reconstruct_the_box_downsampled_btf() {
        let b = basis(16, 8);
        let full = reconstruct(&b);
        for level in 0..=3 {
            let lod = at_level(&b, level as f64).unwrap();
            assert_eq!((lod.width, lod.height), (16 >> level, 8 >> level));
            let rec = reconstruct(&lod);
            let reference = downsample(&full, 1 << level);
            // The bound; both sides are sums of f32 products, so ~1e-7 apart.
            for (a, r) in rec.data.iter().zip(&reference) {
                assert!((*a as f64 - r).abs() <= 1e-5, "level {level}: {a} vs {r}");
            }
        }
    }

    #[test]
    fn fractional_levels_blend_adjacent_levels_with_the_seed_weights() {
        let b = basis(8, 8);
        let lod = at_level(&b, 1.25).unwrap();
        let (l1, l2) = (
            reconstruct(&at_level(&b, 1.0).unwrap()),
            reconstruct(&at_level(&b, 2.0).unwrap()),
        );
        let rec = reconstruct(&lod);
        // w_1 = min(max(1 − 1.25 + 1, 0), 1) = 0.75 on band 1; bands 2.. weigh 1: 0.75·L1 + 0.25·L2.
        for plane in 0..6 {
            for y in 0..4 {
                for x in 0..4 {
                    let want = 0.75 * l1.data[plane * 16 + y * 4 + x] as f64
                        + 0.25 * l2.data[plane * 4 + (y / 2) * 2 + x / 2] as f64;
                    let got = rec.data[plane * 16 + y * 4 + x] as f64;
                    assert!((got - want).abs() <= 1e-5, "{got} vs {want}");
                }
            }
        }
        let e = at_level(&basis(12, 8), 3.0).unwrap_err();
        assert!(e.contains("not divisible by 8"), "{e}");
        assert!(at_level(&b, f64::NAN).is_err());
    }
}
