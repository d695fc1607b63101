//! `NormalMap`: unit surface normals in the tangent frame (z out of the surface, x along +u, y
//! along +v = up the image), three interleaved f32 per texel, row 0 at the top.

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{ArrayView, Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct NormalMap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl NormalMap {
    pub const TYPE: &'static str = "NormalMap";

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let data = d.f32s()?;
        if data.len() != width * height * 3 {
            return Err(DecodeError::new(Self::TYPE, "size does not match the data"));
        }
        Ok(Arc::new(NormalMap {
            width,
            height,
            data,
        }))
    }
}

impl Value for NormalMap {
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
    /// NPY layout: (H, W, 3) f32, unit vectors.
    fn as_array(&self) -> Option<ArrayView<'_>> {
        Some(ArrayView {
            shape: vec![self.height, self.width, 3],
            data: &self.data,
        })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
