//! Bidirectional texture functions: direction sets, reflectance models and synthetic capture.

pub mod brdf;
pub mod capture;
pub mod directions;
