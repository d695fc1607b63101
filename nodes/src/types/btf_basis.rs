//! `BtfBasis`: a BTF factorised as mean + Σ_k d_k(x) e_k(pair, channel) (texels layout, seed 003):
//! per-texel coefficient maps d_k and eigen-ABRDFs e_k over the direction pairs × RGB.
//!
//! With T = W·H texels and C = pairs·3 columns (column = pair·3 + channel, the `Btf` plane
//! order): `mean` has C values, `coeffs` is T×k column-major (k coefficient maps), `basis` is C×k
//! column-major, `singular` the k singular values, largest first.

use super::btf::{decode_pairs, encode_pairs, DirectionPair};
use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct BtfBasis {
    pub width: usize,
    pub height: usize,
    pub pairs: Vec<DirectionPair>,
    pub rank: usize,
    pub mean: Vec<f32>,
    pub coeffs: Vec<f32>,
    pub basis: Vec<f32>,
    pub singular: Vec<f32>,
}

impl BtfBasis {
    pub const TYPE: &'static str = "BtfBasis";

    pub fn texels(&self) -> usize {
        self.width * self.height
    }

    pub fn columns(&self) -> usize {
        self.pairs.len() * 3
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let pairs = decode_pairs(d)?;
        let rank = d.u64()? as usize;
        let b = BtfBasis {
            width,
            height,
            pairs,
            rank,
            mean: d.f32s()?,
            coeffs: d.f32s()?,
            basis: d.f32s()?,
            singular: d.f32s()?,
        };
        let ok = b.mean.len() == b.columns()
            && b.coeffs.len() == b.texels() * rank
            && b.basis.len() == b.columns() * rank
            && b.singular.len() == rank;
        if !ok {
            return Err(DecodeError::new(Self::TYPE, "sizes do not match"));
        }
        Ok(Arc::new(b))
    }
}

impl Value for BtfBasis {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        4 * (self.mean.len() + self.coeffs.len() + self.basis.len() + self.singular.len())
            + 32 * self.pairs.len()
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64).u64(self.height as u64);
        encode_pairs(out, &self.pairs);
        out.u64(self.rank as u64)
            .f32s(&self.mean)
            .f32s(&self.coeffs)
            .f32s(&self.basis)
            .f32s(&self.singular);
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
