//! `btf.reconstruct`: a `BtfBasis` back to a `Btf`, value(pair, channel, x) = mean + Σ_k d_k(x) e_k.

use crate::types::{Btf, BtfBasis};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {}

pub struct Reconstruct;

/// The full BTF of a basis; each value summed over k in order (f64), so thread count is irrelevant.
pub fn reconstruct(b: &BtfBasis) -> Btf {
    let (t, c, k) = (b.texels(), b.columns(), b.rank);
    let mut data = vec![0f32; t * c];
    data.par_chunks_mut(t).enumerate().for_each(|(j, column)| {
        for (i, out) in column.iter_mut().enumerate() {
            let mut v = b.mean[j] as f64;
            for kk in 0..k {
                v += b.coeffs[kk * t + i] as f64 * b.basis[kk * c + j] as f64;
            }
            *out = v as f32;
        }
    });
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
            version: 1,
            doc: "Expands a PCA basis back into a BTF (mean + Σ coefficient map × basis).",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("basis", BtfBasis::TYPE, "the factorised BTF")],
            outputs: vec![Port::output("btf", Btf::TYPE, "the reconstruction")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, _p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("btf", reconstruct(inputs.get::<BtfBasis>("basis")?)))
    }
}
