//! Operations on images: error against a reference, side-by-side layout, blur, ramps.

pub mod blur;
pub mod colorize;
pub mod compare;
pub mod difference;
pub mod flip;
pub mod ramp;
pub mod row;
