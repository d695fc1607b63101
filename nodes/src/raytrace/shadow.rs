//! Shadow maps: the distance from a light's camera to the nearest surface per texel, and the
//! biased test of whether the light sees a point. `render.mesh` builds one of the displaced
//! mesostructure (`render::shade`), `sss.render` and `qh.render` one of the mesh.

use super::camera::Camera;
use crate::geometry::V3;

/// A shadow map: distance along the light camera's ray to the displaced surface per texel.
pub struct ShadowMap {
    pub camera: Camera,
    pub depth: Vec<f64>,
    /// Depth bias, world units (two texels' footprint at the scene).
    pub bias: f64,
}

/// Two shadow-map texels' footprint across the scene: enough for the slopes a texel spans.
pub fn shadow_bias(radius: f64, size: u32) -> f64 {
    2.0 * (2.0 * radius / size as f64)
}

impl ShadowMap {
    /// Whether the light sees `p` (nearest shadow-map texel, biased comparison). The bias grows
    /// as the light grazes the surface (`cos_light`, local), where one texel spans more depth.
    pub fn lit(&self, p: V3, cos_light: f64) -> bool {
        let Some((x, y, t)) = self.camera.project(p) else {
            return true;
        };
        let (w, h) = (self.camera.width as f64, self.camera.height as f64);
        if !(0.0..w).contains(&x) || !(0.0..h).contains(&y) {
            return true;
        }
        let i = y as usize * self.camera.width as usize + x as usize;
        t <= self.depth[i] + self.bias / cos_light.max(0.1)
    }
}
