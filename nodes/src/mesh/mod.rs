//! Meshes: built-in primitives and OBJ files, the geometry `render.mesh` draws, and the true
//! mesostructure displaced onto them.

pub mod displace;
pub mod primitive;
pub mod read;
pub mod write;
