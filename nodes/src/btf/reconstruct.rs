//! `btf.reconstruct`: a `BtfBasis` back to a `Btf`: per block, value = mean + Σ_k m_k(x) b_k(column),
//! then the colour space back to RGB.

use crate::types::{Btf, BtfBasis, Centring, ColorSpace};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// View direction [θ, φ] of the `preview` output (the nearest pair is shown).
    pub preview_view: [f64; 2],
    /// Light direction [θ, φ] of the `preview` output.
    pub preview_light: [f64; 2],
}

impl Default for Params {
    fn default() -> Self {
        Params {
            preview_view: [0.0, 0.0],
            preview_light: [45.0, 0.0],
        }
    }
}

pub struct Reconstruct;

/// Writes one direction pair's three RGB planes (3·T values) into `out`. `owners` is
/// [`BtfBasis::column_owners`]. Each value is summed over k in order (f64), so the thread count
/// is irrelevant.
pub fn pair_into(b: &BtfBasis, owners: &[Option<(usize, usize)>], pair: usize, out: &mut [f32]) {
    let t = b.texels();
    let mut planes = [vec![0f64; t], vec![0f64; t], vec![0f64; t]];
    for (ch, plane) in planes.iter_mut().enumerate() {
        let Some((bi, j)) = owners[pair * 3 + ch] else {
            continue;
        };
        let blk = &b.blocks[bi];
        let (k, n) = (blk.rank(), blk.cols());
        for (i, v) in plane.iter_mut().enumerate() {
            let mut s = match blk.centring {
                Centring::Columns => blk.mean[j] as f64,
                Centring::Texels => blk.mean[i] as f64,
            };
            for kk in 0..k {
                s += blk.maps[kk * t + i] as f64 * blk.basis[kk * n + j] as f64;
            }
            *v = s;
        }
    }
    for i in 0..t {
        let rgb = match b.color {
            ColorSpace::Rgb => [planes[0][i], planes[1][i], planes[2][i]],
            c => c.to_rgb([planes[0][i], planes[1][i], planes[2][i]]),
        };
        for ch in 0..3 {
            out[ch * t + i] = rgb[ch] as f32;
        }
    }
}

/// The full BTF of a basis.
pub fn reconstruct(b: &BtfBasis) -> Btf {
    let t = b.texels();
    let owners = b.column_owners();
    let mut data = vec![0f32; t * b.columns()];
    data.par_chunks_mut(3 * t.max(1))
        .enumerate()
        .for_each(|(pair, out)| pair_into(b, &owners, pair, out));
    Btf {
        width: b.width,
        height: b.height,
        pairs: b.pairs.clone(),
        data,
    }
}

impl Node for Reconstruct {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.reconstruct",
            version: 2,
            doc: "Expands a PCA basis back into an RGB BTF (per block: mean + Σ map × basis).",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("basis", BtfBasis::TYPE, "the factorised BTF")],
            outputs: vec![
                Port::output("btf", Btf::TYPE, "the reconstruction"),
                Port::output(
                    "preview",
                    crate::types::Image::TYPE,
                    "the pair nearest (preview_view, preview_light)",
                ),
            ],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let btf = reconstruct(inputs.get::<BtfBasis>("basis")?);
        let d = |a: [f64; 2]| crate::types::Direction::degrees(a[0], a[1]);
        let preview = btf
            .nearest_pair(&d(p.preview_view), &d(p.preview_light))
            .map(|i| btf.preview(i))
            .ok_or_else(|| NodeError::input("basis", "has no direction pairs"))?;
        Ok(Outputs::new().with("btf", btf).with("preview", preview))
    }
}
