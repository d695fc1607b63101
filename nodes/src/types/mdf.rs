//! `Mdf`: a mesostructure distance function (thesis ch. 4), tabulated. For each view direction
//! and each texel of the reference plane (the top of the mesostructure shell), the distance in
//! texels along the ray that enters the plane at the texel centre, travelling against the view
//! direction, to the first mesostructure hit; `+∞` where the ray meets nothing.
//!
//! Layout: view-major planes, `data[(view · H + y) · W + x]`, row 0 at the top of the tile.
//! `depth` is the shell thickness in texels (reference plane to shell bottom), which the renderer
//! maps onto its own shell thickness.

use super::btf::Direction;
use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{ArrayView, Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct Mdf {
    pub width: usize,
    pub height: usize,
    pub views: Vec<Direction>,
    /// Shell thickness in texels.
    pub depth: f64,
    pub data: Vec<f32>,
}

impl Mdf {
    pub const TYPE: &'static str = "Mdf";

    pub fn plane(&self, view: usize) -> &[f32] {
        let n = self.width * self.height;
        &self.data[view * n..(view + 1) * n]
    }

    /// Distance at texel (x, y) for view `view`, the texel already within the tile (as
    /// `texel_taps` gives them): [`Mdf::at`] without the wrap.
    pub fn at_texel(&self, view: usize, x: usize, y: usize) -> f32 {
        debug_assert!(x < self.width && y < self.height);
        self.data[(view * self.height + y) * self.width + x]
    }

    /// Distance at texel (x, y) (wrapping) for view `view`.
    pub fn at(&self, view: usize, x: isize, y: isize) -> f32 {
        let xi = x.rem_euclid(self.width as isize) as usize;
        let yi = y.rem_euclid(self.height as isize) as usize;
        self.data[(view * self.height + yi) * self.width + xi]
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let width = d.u64()? as usize;
        let height = d.u64()? as usize;
        let depth = d.f64()?;
        let n = d.u64()? as usize;
        let mut views = Vec::with_capacity(n.min(1 << 16));
        for _ in 0..n {
            views.push(Direction {
                theta: d.f64()?,
                phi: d.f64()?,
            });
        }
        let data = d.f32s()?;
        if data.len() != width * height * views.len() {
            return Err(DecodeError::new(Self::TYPE, "size does not match the data"));
        }
        Ok(Arc::new(Mdf {
            width,
            height,
            views,
            depth,
            data,
        }))
    }
}

impl Value for Mdf {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 4
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.width as u64)
            .u64(self.height as u64)
            .f64(self.depth)
            .u64(self.views.len() as u64);
        for v in &self.views {
            out.f64(v.theta).f64(v.phi);
        }
        out.f32s(&self.data);
    }
    /// NPY layout: (views, H, W) f32, texels, +inf for no hit.
    fn as_array(&self) -> Option<ArrayView<'_>> {
        Some(ArrayView {
            shape: vec![self.views.len(), self.height, self.width],
            data: &self.data,
        })
    }
    /// `{"depth": texels, "views": [[θ, φ], …]}` in degrees, in the array's order.
    fn array_sidecar(&self) -> Option<String> {
        let views: Vec<[f64; 2]> = self
            .views
            .iter()
            .map(|d| [d.theta.to_degrees(), d.phi.to_degrees()])
            .collect();
        let doc = serde_json::json!({
            "layout": "(views, H, W) f32, distance in texels along the ray, +inf = no hit",
            "depth": self.depth,
            "views": views,
        });
        serde_json::to_string_pretty(&doc).ok()
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
