//! Example-based texture synthesis: texture optimisation (Kwatra et al. 2005) with guidance
//! channels, on a PatchMatch nearest-patch search.

pub mod optimize;
pub mod patches;
pub mod texture;
