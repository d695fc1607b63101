//! Point sets for appearance manifolds: read from text, from NPY arrays, or made synthetically.

pub mod array;
pub mod read;
pub mod synthetic;
