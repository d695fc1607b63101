//! `Btf`: a bidirectional texture function, W×H texels seen under a list of (view, light)
//! direction pairs, linear RGB f32.
//!
//! Layout: **planar and pair-major**, `data[((pair · 3 + channel) · H + y) · W + x]`, pairs ordered
//! view-major (all lights of view 0, then view 1, …). Why:
//! - each (pair, channel) is one contiguous W·H plane, so the `texels` PCA matrix (rows texels,
//!   columns pairs × channels) *is* this buffer read as a column-major matrix: no copy, and the
//!   Gram matrix is plane-by-plane dot products over contiguous memory;
//! - a direction pair's image is contiguous, which is what capture and file I/O produce and
//!   consume (one image per pair), in parallel over pairs;
//! - per-view work (Sattler et al.'s per-view PCA) takes one contiguous run of all its lights.

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{ArrayView, Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

/// A direction in the tangent frame, radians: θ from the normal, φ from +x towards +y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Direction {
    pub theta: f64,
    pub phi: f64,
}

impl Direction {
    pub fn degrees(theta: f64, phi: f64) -> Self {
        Direction {
            theta: theta.to_radians(),
            phi: phi.to_radians(),
        }
    }

    /// Unit vector in the tangent frame (x, y, z), z along the normal.
    pub fn vector(&self) -> [f64; 3] {
        let s = self.theta.sin();
        [s * self.phi.cos(), s * self.phi.sin(), self.theta.cos()]
    }

    /// Angle between two directions, radians.
    pub fn angle_to(&self, other: &Direction) -> f64 {
        let (a, b) = (self.vector(), other.vector());
        (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .clamp(-1.0, 1.0)
            .acos()
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionPair {
    pub view: Direction,
    pub light: Direction,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Btf {
    pub width: usize,
    pub height: usize,
    pub pairs: Vec<DirectionPair>,
    pub data: Vec<f32>,
}

impl Btf {
    pub const TYPE: &'static str = "Btf";

    /// The three planes (R, G, B) of one direction pair.
    pub fn pair_image(&self, pair: usize) -> &[f32] {
        let n = 3 * self.width * self.height;
        &self.data[pair * n..(pair + 1) * n]
    }

    /// Index of the pair closest to (view, light), by the sum of the two angular distances.
    pub fn nearest_pair(&self, view: &Direction, light: &Direction) -> Option<usize> {
        self.pairs
            .iter()
            .enumerate()
            .map(|(i, p)| (i, p.view.angle_to(view) + p.light.angle_to(light)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }

    /// The largest value: the peak of PSNR.
    pub fn peak(&self) -> f64 {
        use rayon::prelude::*;
        // max is exact and associative, so the parallel reduction is deterministic.
        self.data
            .par_chunks(1 << 16)
            .map(|c| c.iter().fold(0f32, |m, v| m.max(*v)))
            .reduce(|| 0f32, f32::max) as f64
    }

    /// Index of the first value that is NaN or infinite.
    pub fn first_non_finite(&self) -> Option<usize> {
        use rayon::prelude::*;
        const CHUNK: usize = 1 << 16;
        self.data
            .par_chunks(CHUNK)
            .position_first(|c| c.iter().any(|v| !v.is_finite()))
            .and_then(|ci| {
                let start = ci * CHUNK;
                self.data[start..]
                    .iter()
                    .position(|v| !v.is_finite())
                    .map(|i| start + i)
            })
    }

    /// One pair as an interleaved RGB image.
    pub fn preview(&self, pair: usize) -> crate::types::Image {
        let planes = self.pair_image(pair);
        let n = self.width * self.height;
        let data = (0..n)
            .flat_map(|i| [planes[i], planes[n + i], planes[2 * n + i]])
            .collect();
        crate::types::Image {
            width: self.width,
            height: self.height,
            channels: 3,
            data,
        }
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let pairs = decode_pairs(d)?;
        let n = pairs.len();
        let data = d.f32s()?;
        if data.len() != n * 3 * width * height {
            return Err(DecodeError::new(Self::TYPE, "size does not match the data"));
        }
        Ok(Arc::new(Btf {
            width,
            height,
            pairs,
            data,
        }))
    }
}

/// The direction-pair list of a cache encoding (shared by `Btf` and `BtfBasis`).
pub(super) fn encode_pairs(out: &mut Encoder, pairs: &[DirectionPair]) {
    out.u64(pairs.len() as u64);
    for p in pairs {
        out.f64(p.view.theta)
            .f64(p.view.phi)
            .f64(p.light.theta)
            .f64(p.light.phi);
    }
}

pub(super) fn decode_pairs(d: &mut Decoder) -> Result<Vec<DirectionPair>, DecodeError> {
    let n = d.u64()? as usize;
    let mut pairs = Vec::with_capacity(n.min(1 << 20));
    for _ in 0..n {
        let view = Direction {
            theta: d.f64()?,
            phi: d.f64()?,
        };
        let light = Direction {
            theta: d.f64()?,
            phi: d.f64()?,
        };
        pairs.push(DirectionPair { view, light });
    }
    Ok(pairs)
}

impl Value for Btf {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 4 + self.pairs.len() * 32
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64).u64(self.height as u64);
        encode_pairs(out, &self.pairs);
        out.f32s(&self.data);
    }
    /// NPY layout: (pairs, 3, H, W) f32, linear RGB planes; pairs view-major.
    fn as_array(&self) -> Option<ArrayView<'_>> {
        Some(ArrayView {
            shape: vec![self.pairs.len(), 3, self.height, self.width],
            data: &self.data,
        })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
