//! mesoflow's node kinds: the algorithms, one folder per stage, and [`registry::builtin`], the list of kinds
//! a graph can use. Nodes know nothing about scheduling or caching; each is a pure function of its
//! parameters, inputs and declared files.

pub mod brdf;
pub mod btf;
pub mod debug;
pub mod export;
pub mod heightfield;
pub mod image;
pub mod manifold;
pub mod material;
pub mod mdf;
pub mod mesh;
pub mod npy;
pub mod points;
pub mod qh;
pub mod reflectance;
pub mod registry;
pub mod render;
pub mod scalar;
pub mod scene;
pub mod sss;
pub mod support;
pub mod synthesis;
pub mod types;
pub mod weathering;
