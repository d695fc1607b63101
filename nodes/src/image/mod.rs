//! Operations on images: error against a reference, side-by-side layout, blur, ramps.

pub mod array;
pub mod blur;
pub mod colorize;
pub mod compare;
pub mod difference;
pub mod flip;
pub mod ramp;
pub mod read;
pub mod row;
pub mod write;
