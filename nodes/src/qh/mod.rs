//! Quasi-homogeneous materials (thesis ch. 5; Tong et al. 2005): locally inhomogeneous,
//! globally homogeneous — a fitted homogeneous dipole for the global light transport.

pub mod fit_dipole;
pub mod render;
pub mod white_table;
