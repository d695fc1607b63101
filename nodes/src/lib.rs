//! mesoflow's node kinds: the algorithms, one folder per stage, and [`registry`], the list of kinds
//! a graph can use. Nodes know nothing about scheduling or caching; each is a pure function of its
//! parameters, inputs and declared files.

pub mod brdf;
pub mod btf;
pub mod geometry;
pub mod gpu;
pub mod heightfield;
pub mod image;
pub mod io;
pub mod manifold;
pub mod mdf;
pub mod memory;
pub mod mesh;
pub mod optics;
pub mod progress;
pub mod qh;
pub mod raytrace;
mod registry;
pub mod render;
pub mod rng;
pub mod sss;
pub mod synthesis;
pub mod types;
pub mod util;
pub mod weathering;

pub use registry::registry;
