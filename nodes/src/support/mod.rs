//! What the kinds share and no kind is: vector geometry, the ray tracer and its views, optics,
//! the GPU device, memory budgets, progress, random numbers, and the image and NPY file formats.

pub mod formats;
pub mod geometry;
pub mod gpu;
pub mod memory;
pub mod npy;
pub mod optics;
pub mod progress;
pub mod raytrace;
pub mod rng;
pub mod sh;
