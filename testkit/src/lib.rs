//! mesoflow's test kit, a dev-only crate that the tests and benches of every package use: skips
//! that say so (`skip`), one node run as the engine runs it (`node`), NPY files made by hand (`npy`), the `mesoflow` binary and its reports (`cli`), the benches' options
//! (`args`), a pool of a given size (`threads`), and the scenes and sweeps that a test holds to a bound and a bench charts
//! (`plan_sweep`, `truth_scenes`), written once for both.

pub mod args;
pub mod cli;
pub mod node;
pub mod npy;
pub mod pbrt;
pub mod plan_families;
pub mod plan_sweep;
pub mod scenes;
pub mod skip;
pub mod threads;
pub mod truth_scenes;

pub use skip::{skip, skip_unless_required};
