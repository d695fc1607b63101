//! `HeightField`: a periodic tile of heights, row-major with row 0 at the top, heights in texel
//! units (a height of 1.0 is one texel spacing), so slopes need no further scale.

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{ArrayView, Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct HeightField {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl HeightField {
    pub const TYPE: &'static str = "HeightField";

    /// Central-difference gradients (∂h/∂u, ∂h/∂v) at every sample, periodic, row-major.
    pub fn gradients(&self) -> Vec<[f32; 2]> {
        (0..self.height as isize)
            .flat_map(|j| (0..self.width as isize).map(move |i| (i, j)))
            .map(|(i, j)| {
                [
                    0.5 * (self.at_wrapped(i + 1, j) - self.at_wrapped(i - 1, j)),
                    0.5 * (self.at_wrapped(i, j + 1) - self.at_wrapped(i, j - 1)),
                ]
            })
            .collect()
    }

    /// A field of `width`×`height` samples with sample (x, y) = f(x, y).
    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Self {
        let data = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        HeightField {
            width,
            height,
            data,
        }
    }

    /// Height at (x, y), wrapping around the tile in both directions.
    pub fn at_wrapped(&self, x: isize, y: isize) -> f32 {
        let xi = x.rem_euclid(self.width as isize) as usize;
        let yi = y.rem_euclid(self.height as isize) as usize;
        self.data[yi * self.width + xi]
    }

    pub fn min_max(&self) -> (f32, f32) {
        self.data
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let data = d.f32s()?;
        if data.len() != width * height {
            return Err(DecodeError::new(Self::TYPE, "size does not match the data"));
        }
        Ok(Arc::new(HeightField {
            width,
            height,
            data,
        }))
    }
}

impl Value for HeightField {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 4
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64)
            .u64(self.height as u64)
            .f32s(&self.data);
    }
    /// NPY layout: (H, W) f32, heights in texels.
    fn as_array(&self) -> Option<ArrayView<'_>> {
        Some(ArrayView {
            shape: vec![self.height, self.width],
            data: &self.data,
        })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
