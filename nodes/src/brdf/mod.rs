//! Per-pixel reflectance models fitted to captures: the isotropic Ward lobe with its gradient,
//! K-means for starting points, the `brdf.fit_ward` node, and the edits of what it recovers
//! (`brdf.edit`, `material.transfer`).

pub mod edit;
pub mod fit_normal;
pub mod fit_ward;
pub mod kmeans;
pub mod lm;
pub mod photometric;
pub mod transfer;
pub mod ward;
