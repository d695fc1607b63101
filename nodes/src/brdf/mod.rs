//! Per-pixel reflectance models fitted to captures: the isotropic Ward lobe with its gradient,
//! K-means for starting points, and the `brdf.fit_ward` node.

pub mod fit_normal;
pub mod fit_ward;
pub mod kmeans;
pub mod lm;
pub mod photometric;
pub mod ward;
