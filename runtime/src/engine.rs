//! The engine: a registry, the caches and the GPU, kept across runs so that sweeps and `watch`
//! reuse what earlier runs computed (`Resources`, which the scheduler runs with). [`Engine::run`]
//! checks what was asked for and has the scheduler execute one checked graph.

use crate::cache::{DiskCache, MemoryCache};
use crate::gpu::GpuProvider;
use crate::registry::Registry;
use crate::report::RunReport;
use crate::resources::Resources;
use crate::run::{RunObserver, RunOptions, RunOutcome};
use mesoflow_graph::CheckedGraph;
use std::collections::BTreeMap;
use std::sync::Arc;
use thiserror::Error;

/// Errors in how a run was asked for (the graph itself was already checked).
#[derive(Debug, Error, PartialEq)]
pub enum EngineError {
    #[error("--output {0}: no such node")]
    NoSuchNode(String),
    #[error("--output {0}: node `{1}` ({2}) has no output `{3}`")]
    NoSuchOutput(String, String, String, String),
}

pub struct EngineConfig {
    pub memory_budget: usize,
    /// `None` disables the disk cache.
    pub disk: Option<DiskCache>,
}

pub struct Engine {
    shared: Resources,
}

impl Engine {
    pub fn new(registry: Registry, config: EngineConfig) -> Self {
        Engine {
            shared: Resources {
                registry: Arc::new(registry),
                memory: Arc::new(MemoryCache::new(config.memory_budget)),
                disk: config.disk,
                gpu: Arc::new(GpuProvider::default()),
            },
        }
    }

    /// An engine with another registry (an embedding adds kinds of its own) that shares this
    /// one's memory cache, disk cache and GPU, so what earlier runs computed is still found.
    pub fn with_registry(&self, registry: Registry) -> Engine {
        Engine {
            shared: Resources {
                registry: Arc::new(registry),
                memory: self.shared.memory.clone(),
                disk: self.shared.disk.clone(),
                gpu: self.shared.gpu.clone(),
            },
        }
    }

    pub fn registry(&self) -> &Registry {
        &self.shared.registry
    }

    pub fn memory_cache(&self) -> &MemoryCache {
        &self.shared.memory
    }

    pub fn gpu(&self) -> &GpuProvider {
        &self.shared.gpu
    }

    /// Runs the graph; node failures are in the report (`ok: false`), not an `Err`.
    pub fn run(
        &self,
        graph: &CheckedGraph,
        opts: &RunOptions,
        observer: Arc<dyn RunObserver>,
    ) -> Result<RunReport, EngineError> {
        self.run_values(graph, opts, observer).map(|o| o.report)
    }

    /// The cache key of every node the requested outputs need, computed without running
    /// anything (parameters prepared, declared files hashed): what a cluster driver splits into
    /// units. A node whose key cannot be made maps to its error.
    pub fn keys(
        &self,
        graph: &CheckedGraph,
        opts: &RunOptions,
    ) -> BTreeMap<String, Result<crate::key::Key, String>> {
        crate::scheduler::keys(&self.shared, graph, opts)
    }

    /// What a run would do, without running anything: per node the requested outputs need,
    /// whether it would run (and why), be read from a cache, or not be needed.
    pub fn explain(
        &self,
        graph: &CheckedGraph,
        opts: &RunOptions,
    ) -> Vec<crate::scheduler::dry_run::Explained> {
        crate::scheduler::dry_run::dry_run(&self.shared, graph, opts)
    }

    /// [`Engine::run`], also handing back the values of the requested nodes.
    pub fn run_values(
        &self,
        graph: &CheckedGraph,
        opts: &RunOptions,
        observer: Arc<dyn RunObserver>,
    ) -> Result<RunOutcome, EngineError> {
        for o in &opts.outputs {
            let node = graph
                .nodes
                .iter()
                .find(|n| n.id == o.node)
                .ok_or_else(|| EngineError::NoSuchNode(o.to_string()))?;
            let sig = self.shared.registry.node(&node.kind).map(|n| n.signature());
            if sig.is_some_and(|s| s.output(&o.port).is_none()) {
                return Err(EngineError::NoSuchOutput(
                    o.to_string(),
                    o.node.clone(),
                    node.kind.clone(),
                    o.port.clone(),
                ));
            }
        }
        Ok(crate::scheduler::execute(
            &self.shared,
            graph,
            opts,
            observer,
        ))
    }
}

#[cfg(test)]
#[path = "engine_tests.rs"]
mod tests;
