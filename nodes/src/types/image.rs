//! `Image`: linear-light f32 pixels, 1 (grey), 3 (RGB) or 4 (RGBA) interleaved channels, row 0 at
//! the top. sRGB exists only at the file boundary (8-bit reads and PNG writes).

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{ArrayView, Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Image {
    pub const TYPE: &'static str = "Image";

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let channels = d.u64()? as usize;
        let data = d.f32s()?;
        if data.len() != width * height * channels || !matches!(channels, 1 | 3 | 4) {
            return Err(DecodeError::new(Self::TYPE, "size does not match the data"));
        }
        Ok(Arc::new(Image {
            width,
            height,
            channels,
            data,
        }))
    }
}

impl Value for Image {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 4
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64)
            .u64(self.height as u64)
            .u64(self.channels as u64)
            .f32s(&self.data);
    }
    /// NPY layout: (H, W, C) f32, linear.
    fn as_array(&self) -> Option<ArrayView<'_>> {
        Some(ArrayView {
            shape: vec![self.height, self.width, self.channels],
            data: &self.data,
        })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// sRGB transfer function, encoded value to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear to sRGB-encoded value (inputs clamped to [0, 1]).
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if c <= 0.0031308 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_matches_the_standard() {
        // IEC 61966-2-1: 0.5 linear encodes to 0.7354; 8-bit 188 decodes to 0.5029.
        assert!((linear_to_srgb(0.5) - 0.735_356_6).abs() < 1e-6);
        assert!((srgb_to_linear(188.0 / 255.0) - 0.502_886).abs() < 1e-5);
        for i in 0..=255 {
            let c = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-6);
        }
    }
}
