//! Subsurface scattering (seed 004, thesis ch. 5): materials, diffusion profiles.

pub mod dipole;
pub mod material;
pub mod profile;
