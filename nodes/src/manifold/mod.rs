//! Appearance manifolds (thesis ch. 6; Wang et al. 2006): the kNN graph, geodesic distances and
//! Isomap over point sets (`points/`).

pub mod degree;
pub mod eigen;
pub mod evolve;
pub mod graph;
pub mod isomap;
pub mod kdtree;
pub mod knn;
pub mod path;
pub mod rank;
pub mod transfer;
