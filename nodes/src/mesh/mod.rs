//! Meshes: built-in primitives and OBJ files, the geometry `render.mesh` draws.

pub mod primitive;
pub mod read;
