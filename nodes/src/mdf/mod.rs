//! Mesostructure distance functions (thesis ch. 4): tabulation from a height field.

pub mod compress;
pub mod tabulate;
