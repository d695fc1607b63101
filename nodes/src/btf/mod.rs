//! Bidirectional texture functions: direction sets, reflectance models, synthetic capture, PCA
//! compression, reconstruction and comparison.

pub mod brdf;
pub mod capture;
pub mod compare;
pub mod directions;
pub mod factor;
pub mod pca;
pub mod reconstruct;
