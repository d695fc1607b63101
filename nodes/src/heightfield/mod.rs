//! Mesostructure height fields: procedural tiles, reading from files, and normal maps.

pub mod array;
pub mod edit;
pub mod from_normals;
pub mod grid;
pub mod normal_noise;
pub mod normals;
pub mod procedural;
pub mod raycast;
pub mod read;
