//! Mesostructure distance functions (thesis ch. 4): tabulation from a height field or a mesh tile,
//! and compression of the table.

pub mod compress;
pub mod mesh_tile;
pub mod tabulate;
