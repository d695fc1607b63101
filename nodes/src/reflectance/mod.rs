//! The reflectance models, in one place: Lambert, Ward (isotropic and anisotropic) and
//! Cook–Torrance with GGX in the vector form the capture and the reference renderer evaluate
//! (`models`), isotropic Ward over direction pairs with its gradient for the fits (`ward`), and
//! the Beckmann Cook–Torrance the weathered samples are made with (`cook_torrance`).

pub mod cook_torrance;
pub mod models;
pub mod ward;
