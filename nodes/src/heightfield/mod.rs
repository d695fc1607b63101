//! Mesostructure height fields: procedural tiles, reading from files, and normal maps.

pub mod normals;
pub mod procedural;
pub mod raycast;
pub mod read;
