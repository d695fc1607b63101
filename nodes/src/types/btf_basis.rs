//! `BtfBasis`: a BTF factorised into blocks, each `mean + Σ_k m_k(x) b_k(column)` (seed 003):
//! per-texel maps m_k (coefficient maps, or eigen-textures) and per-column basis vectors b_k
//! (eigen-ABRDFs, or per-direction weights).
//!
//! Columns are the `Btf` planes, index `pair·3 + channel`, in the basis's colour space (RGB, or
//! linear YCbCr whose channels are Y, Cb, Cr). A block covers a run of pairs and either all three
//! channels or one: the whole BTF (`texels`/`directions` layouts, RGB), one view's lights
//! (`per_view`), one channel (YCbCr, so luma and chroma get their own ranks). Every column belongs
//! to exactly one block. In a block with T = W·H texels, n columns and rank k, `maps` is T×k and
//! `basis` n×k, both column-major, columns ordered pair-major then channel; `mean` has n values
//! (mean over texels, `Centring::Columns`) or T values (mean over the block's columns,
//! `Centring::Texels`). Reconstruction is linear in the maps, which is what makes mipmapping them
//! exact (`btf.lod`).

use super::btf::{decode_pairs, encode_pairs, DirectionPair};
use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

/// Which mean a block removed before factorising.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Centring {
    /// Each column's mean over texels (texels are the samples: eigen-ABRDFs).
    Columns,
    /// Each texel's mean over the block's columns (the transpose: eigen-textures).
    Texels,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorSpace {
    Rgb,
    /// Linear-light BT.601 YCbCr: Y = 0.299 R + 0.587 G + 0.114 B, Cb = (B − Y)/1.772,
    /// Cr = (R − Y)/1.402.
    YCbCr,
}

impl ColorSpace {
    pub fn from_rgb(self, [r, g, b]: [f64; 3]) -> [f64; 3] {
        match self {
            ColorSpace::Rgb => [r, g, b],
            ColorSpace::YCbCr => {
                let y = 0.299 * r + 0.587 * g + 0.114 * b;
                [y, (b - y) / 1.772, (r - y) / 1.402]
            }
        }
    }

    pub fn to_rgb(self, [y, cb, cr]: [f64; 3]) -> [f64; 3] {
        match self {
            ColorSpace::Rgb => [y, cb, cr],
            ColorSpace::YCbCr => {
                let r = y + 1.402 * cr;
                let b = y + 1.772 * cb;
                [r, (y - 0.299 * r - 0.114 * b) / 0.587, b]
            }
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct BasisBlock {
    pub first_pair: usize,
    pub pair_count: usize,
    /// `None`: all three channels; `Some(c)`: channel c only.
    pub channel: Option<u8>,
    pub centring: Centring,
    pub mean: Vec<f32>,
    pub maps: Vec<f32>,
    pub basis: Vec<f32>,
    pub singular: Vec<f32>,
}

impl BasisBlock {
    pub fn rank(&self) -> usize {
        self.singular.len()
    }

    pub fn channels(&self) -> usize {
        if self.channel.is_some() {
            1
        } else {
            3
        }
    }

    pub fn cols(&self) -> usize {
        self.pair_count * self.channels()
    }

    /// The global column (`pair·3 + channel`) of the block's column j.
    pub fn column(&self, j: usize) -> usize {
        match self.channel {
            Some(c) => (self.first_pair + j) * 3 + c as usize,
            None => self.first_pair * 3 + j,
        }
    }

    /// Stored f32 values.
    pub fn floats(&self) -> usize {
        self.mean.len() + self.maps.len() + self.basis.len() + self.singular.len()
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct BtfBasis {
    pub width: usize,
    pub height: usize,
    pub pairs: Vec<DirectionPair>,
    pub color: ColorSpace,
    pub blocks: Vec<BasisBlock>,
}

impl BtfBasis {
    pub const TYPE: &'static str = "BtfBasis";

    pub fn texels(&self) -> usize {
        self.width * self.height
    }

    pub fn columns(&self) -> usize {
        self.pairs.len() * 3
    }

    /// For every global column, (block index, column within the block); `None` if uncovered.
    pub fn column_owners(&self) -> Vec<Option<(usize, usize)>> {
        let mut owners = vec![None; self.columns()];
        for (bi, b) in self.blocks.iter().enumerate() {
            for j in 0..b.cols() {
                if let Some(o) = owners.get_mut(b.column(j)) {
                    *o = Some((bi, j));
                }
            }
        }
        owners
    }

    /// Structural consistency: sizes agree and every column has exactly one block.
    pub fn check(&self) -> Result<(), String> {
        let t = self.texels();
        let mut seen = vec![0u8; self.columns()];
        for (i, b) in self.blocks.iter().enumerate() {
            let k = b.rank();
            let mean_len = match b.centring {
                Centring::Columns => b.cols(),
                Centring::Texels => t,
            };
            if b.first_pair + b.pair_count > self.pairs.len()
                || b.channel.is_some_and(|c| c > 2)
                || b.mean.len() != mean_len
                || b.maps.len() != t * k
                || b.basis.len() != b.cols() * k
            {
                return Err(format!("block {i}: sizes do not match"));
            }
            for j in 0..b.cols() {
                seen[b.column(j)] += 1;
            }
        }
        match seen.iter().position(|&s| s != 1) {
            Some(c) => Err(format!(
                "column {c} is covered by {} blocks, not 1",
                seen[c]
            )),
            None => Ok(()),
        }
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let pairs = decode_pairs(d)?;
        let color = match d.u64()? {
            0 => ColorSpace::Rgb,
            _ => ColorSpace::YCbCr,
        };
        let count = d.u64()? as usize;
        let mut blocks = Vec::with_capacity(count.min(1 << 16));
        for _ in 0..count {
            let first_pair = d.u64()? as usize;
            let pair_count = d.u64()? as usize;
            let channel = match d.u64()? {
                3 => None,
                c => Some(c as u8),
            };
            let centring = match d.u64()? {
                0 => Centring::Columns,
                _ => Centring::Texels,
            };
            blocks.push(BasisBlock {
                first_pair,
                pair_count,
                channel,
                centring,
                mean: d.f32s()?,
                maps: d.f32s()?,
                basis: d.f32s()?,
                singular: d.f32s()?,
            });
        }
        let b = BtfBasis {
            width,
            height,
            pairs,
            color,
            blocks,
        };
        b.check().map_err(|e| DecodeError::new(Self::TYPE, e))?;
        Ok(Arc::new(b))
    }
}

impl Value for BtfBasis {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        4 * self.blocks.iter().map(|b| b.floats()).sum::<usize>() + 32 * self.pairs.len()
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64).u64(self.height as u64);
        encode_pairs(out, &self.pairs);
        out.u64(match self.color {
            ColorSpace::Rgb => 0,
            ColorSpace::YCbCr => 1,
        });
        out.u64(self.blocks.len() as u64);
        for b in &self.blocks {
            out.u64(b.first_pair as u64)
                .u64(b.pair_count as u64)
                .u64(b.channel.map_or(3, |c| c as u64))
                .u64(match b.centring {
                    Centring::Columns => 0,
                    Centring::Texels => 1,
                })
                .f32s(&b.mean)
                .f32s(&b.maps)
                .f32s(&b.basis)
                .f32s(&b.singular);
        }
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ycbcr_round_trips_and_has_bt601_luma() {
        let c = ColorSpace::YCbCr;
        for rgb in [[1.0, 0.0, 0.0], [0.2, 0.7, 0.1], [0.5, 0.5, 0.5]] {
            let back = c.to_rgb(c.from_rgb(rgb));
            for i in 0..3 {
                assert!((back[i] - rgb[i]).abs() < 1e-12);
            }
        }
        // Grey has no chroma and luma equal to the grey level (BT.601 weights sum to 1).
        let g = c.from_rgb([0.5, 0.5, 0.5]);
        assert!((g[0] - 0.5).abs() < 1e-12 && g[1].abs() < 1e-12 && g[2].abs() < 1e-12);
    }
}
