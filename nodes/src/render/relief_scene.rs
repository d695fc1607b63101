//! What `render.relief` shades a pixel from, prepared once from the graph's inputs: the height
//! field, its gradients and reflectance maps, the mesh's texel aspect and the search's settings.
//! Both the CPU path (`relief.rs`) and the GPU pass (`relief_gpu.rs`) read it.

use crate::support::raytrace::light::Light;
use crate::types::Mesh;

/// Everything a pixel's shading reads, prepared once.
pub struct Relief<'a> {
    pub mesh: &'a Mesh,
    pub width: usize,
    pub height: usize,
    /// Heights in texels, row-major.
    pub heights: Vec<f32>,
    pub top: f32,
    /// max − min of the heights, texels (the search's depth).
    pub depth: f32,
    /// Per texel (∂h/∂x, ∂h/∂y) on the grid (y down), or the normal map's slopes.
    pub grad: Vec<[f32; 2]>,
    /// Per texel ρd RGB, ρs, α.
    pub maps: Vec<[f32; 5]>,
    /// Per vertex the texel aspect (k_u, k_v): 1 where the mapping keeps the tile's proportions.
    pub aspect: Vec<[f32; 2]>,
    pub tiling: [f64; 2],
    pub light: Light,
    /// Directions a pixel integrates an environment light over.
    pub environment_samples: u32,
    pub linear_steps: u32,
    pub binary_steps: u32,
    pub shadows: bool,
    pub background: [f64; 3],
}
