//! Built-in weathered samples with ground truth, for the appearance-manifold pipeline.

pub mod sample;
