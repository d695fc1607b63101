//! Operations on images: error against a reference, side-by-side layout.

pub mod compare;
pub mod row;
