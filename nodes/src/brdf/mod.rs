//! Per-pixel reflectance models fitted to captures: K-means for starting points, the
//! `brdf.fit_ward` node (the Ward lobe and its gradient are `reflectance::ward`), and the edit of
//! what it recovers (`brdf.edit`).

pub mod edit;
pub mod fit_normal;
pub mod fit_ward;
pub mod kmeans;
pub mod lm;
pub mod photometric;
