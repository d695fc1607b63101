//! The parts of the command line that other front ends (the Python package) share, so that what
//! they write is the same: sweep tables and charts. Everything else of the command line is in the
//! `mesoflow` binary (`main.rs`).

pub mod chart;
pub mod sweep_table;
