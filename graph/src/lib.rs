//! mesoflow's pipeline language: the graph-file model, port types, the catalog of node kinds a
//! graph is checked against, and the static checks that run before anything executes.
//!
//! This crate knows nothing about execution, GPUs or algorithms, so an editor or linter can load,
//! edit and check a pipeline without building wgpu.

// Graph errors are built only on the cold path of a failed check and are collected into vectors,
// so their size (several strings each, for precise messages) costs nothing that matters.
#![allow(clippy::result_large_err)]

pub mod catalog;
pub mod check;
pub mod edit;
pub mod error;
pub mod file;
pub mod interface;
pub mod params;
pub mod port_ref;
pub mod ports;
pub mod schema;
pub mod source_edit;
pub mod subgraph;
mod suggest;
pub mod values;

pub use catalog::{Catalog, DevicePreference, InputSpec, KindSignature, OutputSpec, TypedProblem};
pub use check::{check, CheckedGraph, CheckedNode, Edge};
pub use edit::{parse_override, Override};
pub use error::{GraphError, GraphErrors};
pub use file::{GraphFile, NodeDecl, PortRef, FORMAT_VERSION};
pub use ports::TypeSet;
pub use suggest::{did_you_mean, nearest};
