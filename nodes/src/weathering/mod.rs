//! Built-in weathered samples with ground truth, for the appearance-manifold pipeline.

pub mod cook_torrance;
pub mod sample;
