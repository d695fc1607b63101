//! `BrdfMap`: an isotropic Ward BRDF per pixel, W×H, five parameters each — ρd (R, G, B), ρs,
//! α — f64, row-major pixels. NPY: (H, W, 5) f64 in that parameter order.

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

/// Parameters per pixel: ρd R, G, B, ρs, α.
pub const WARD_PARAMS: usize = 5;

#[derive(Clone, Debug, PartialEq)]
pub struct BrdfMap {
    pub width: usize,
    pub height: usize,
    /// (y · W + x) · 5 + parameter.
    pub data: Vec<f64>,
}

impl BrdfMap {
    pub const TYPE: &'static str = "BrdfMap";

    pub fn pixel(&self, i: usize) -> &[f64] {
        &self.data[i * WARD_PARAMS..(i + 1) * WARD_PARAMS]
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let data = (0..width * height * WARD_PARAMS)
            .map(|_| d.f64())
            .collect::<Result<_, _>>()?;
        Ok(Arc::new(BrdfMap {
            width,
            height,
            data,
        }))
    }
}

impl Value for BrdfMap {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 8
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64).u64(self.height as u64);
        for x in &self.data {
            out.f64(*x);
        }
    }
    fn as_array_f64(&self) -> Option<(Vec<usize>, Vec<f64>)> {
        Some((
            vec![self.height, self.width, WARD_PARAMS],
            self.data.clone(),
        ))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
