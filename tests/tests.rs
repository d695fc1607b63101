//! The integration tests: one crate, one binary, a module per subject (the layout of ripgrep's
//! `tests/`), so the whole suite links once. `common` holds the helpers every module shares;
//! `cargo test --release --test tests MODULE::` runs one module.

mod btf_edit;
mod cache;
mod cancel;
mod commands;
mod common;
mod devices;
mod docs;
mod every_graph;
mod explain;
mod export;
mod families;
mod flip_peer;
mod hostile;
mod interreflection;
mod plan;
mod plan_families;
mod plan_probe;
mod plan_truth;
mod plan_verify;
mod reference_peer;
mod shipped_graphs;
mod slurm;
mod static_checks;
mod studio;
mod subgraphs;
mod translucency;
mod truth;
mod ubo2014;
