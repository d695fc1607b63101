//! Subsurface scattering (seed 004, thesis ch. 5): materials, diffusion profiles.

pub mod compare;
pub mod diffusion;
pub mod dipole;
pub mod material;
pub mod montecarlo;
pub mod octree;
pub mod points;
pub mod profile;
pub mod render;
