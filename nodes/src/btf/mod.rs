//! Bidirectional texture functions: direction sets, reflectance models, synthetic capture, PCA
//! compression, reconstruction and comparison.

pub mod array;
pub mod capture;
pub mod compare;
pub mod directions;
pub mod factor;
pub mod interreflect;
pub mod lod;
pub mod pca;
pub mod read_ubo2003;
pub mod read_ubo2014;
pub mod reconstruct;
pub mod ubo2003;
pub mod ubo2014;
pub mod write_ubo2003;
pub mod write_ubo2014;
