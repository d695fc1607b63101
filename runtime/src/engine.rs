//! The engine: a registry, the caches and the GPU, kept across runs so that sweeps and `watch`
//! reuse what earlier runs computed. [`Engine::run`] executes one checked graph.

use crate::cache::{DiskCache, MemoryCache};
use crate::gpu::GpuProvider;
use crate::node::Outputs;
use crate::registry::Registry;
use crate::report::{NodeReport, RunReport};
use mesoflow_graph::{CheckedGraph, PortRef};
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use thiserror::Error;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DeviceMode {
    /// GPU nodes use the GPU when an adapter exists, else their CPU path (with a warning).
    #[default]
    Auto,
    /// Every node takes its CPU path.
    Cpu,
    /// GPU nodes must get the GPU; a missing adapter fails them.
    Gpu,
}

/// Errors in how a run was asked for (the graph itself was already checked).
#[derive(Debug, Error, PartialEq)]
pub enum EngineError {
    #[error("--output {0}: no such node")]
    NoSuchNode(String),
    #[error("--output {0}: node `{1}` ({2}) has no output `{3}`")]
    NoSuchOutput(String, String, String, String),
}

/// Hears about a run as it goes (the command line draws progress bars from this).
pub trait RunObserver: Send + Sync {
    fn node_started(&self, _id: &str, _kind: &str, _device: &str) {}
    fn progress(&self, _id: &str, _done: u64, _total: u64) {}
    fn node_finished(&self, _report: &NodeReport) {}
}

pub struct SilentObserver;
impl RunObserver for SilentObserver {}

pub struct EngineConfig {
    pub memory_budget: usize,
    /// `None` disables the disk cache.
    pub disk: Option<DiskCache>,
}

pub struct RunOptions {
    /// The graph's path as the user gave it; it goes into the report.
    pub graph_name: String,
    /// Folder that relative input paths resolve against (the graph file's folder).
    pub base_dir: PathBuf,
    /// Folder that relative output paths resolve against.
    pub out_dir: PathBuf,
    /// Outputs to produce; empty means every sink of the graph.
    pub outputs: Vec<PortRef>,
    pub device: DeviceMode,
    /// A GPU node without an adapter fails instead of falling back (`MESOFLOW_REQUIRE_GPU=1`).
    pub require_gpu: bool,
    /// Read and write the caches.
    pub use_cache: bool,
    /// Recompute cache hits and fail on a mismatch.
    pub verify_cache: bool,
    pub cancel: Arc<AtomicBool>,
    /// Only these nodes may be computed; any other node whose value is not in a cache fails
    /// with [`NOT_IN_CACHE`] instead of running (a cluster job runs its unit, never its inputs;
    /// the driver's final pass computes nothing). `None`: every node may run.
    pub compute_only: Option<BTreeSet<String>>,
    /// Write every computed value to the disk cache, also those of kinds that are cheaper to
    /// recompute than to read (`NodeSpec::disk_cache` false): a cluster job hands its values
    /// over to other jobs only through the cache.
    pub cache_everything: bool,
}

/// The start of the error of a node that a `compute_only` run would have had to compute.
pub const NOT_IN_CACHE: &str = "not in the cache, and not computed here";

impl RunOptions {
    pub fn new(graph_name: &str, base_dir: PathBuf, out_dir: PathBuf) -> Self {
        RunOptions {
            graph_name: graph_name.into(),
            base_dir,
            out_dir,
            outputs: Vec::new(),
            device: DeviceMode::Auto,
            require_gpu: false,
            use_cache: true,
            verify_cache: false,
            cancel: Arc::new(AtomicBool::new(false)),
            compute_only: None,
            cache_everything: false,
        }
    }
}

pub struct Engine {
    pub(crate) registry: Arc<Registry>,
    pub(crate) memory: Arc<MemoryCache>,
    pub(crate) disk: Option<DiskCache>,
    pub(crate) gpu: Arc<GpuProvider>,
}

/// A run's report and the values of the nodes it was asked for (by default the sinks), by node
/// id: what an embedding (the Python package) hands back to its caller. A node that failed or
/// was cancelled has no entry.
pub struct RunOutcome {
    pub report: RunReport,
    pub values: BTreeMap<String, Outputs>,
}

impl Engine {
    pub fn new(registry: Registry, config: EngineConfig) -> Self {
        Engine {
            registry: Arc::new(registry),
            memory: Arc::new(MemoryCache::new(config.memory_budget)),
            disk: config.disk,
            gpu: Arc::new(GpuProvider::default()),
        }
    }

    /// An engine with another registry (an embedding adds kinds of its own) that shares this
    /// one's memory cache, disk cache and GPU, so what earlier runs computed is still found.
    pub fn with_registry(&self, registry: Registry) -> Engine {
        Engine {
            registry: Arc::new(registry),
            memory: self.memory.clone(),
            disk: self.disk.clone(),
            gpu: self.gpu.clone(),
        }
    }

    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    pub fn memory_cache(&self) -> &MemoryCache {
        &self.memory
    }

    pub fn gpu(&self) -> &GpuProvider {
        &self.gpu
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
        crate::scheduler::keys(self, graph, opts)
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
            let sig = self.registry.node(&node.kind).map(|n| n.signature());
            if sig.is_some_and(|s| s.output(&o.port).is_none()) {
                return Err(EngineError::NoSuchOutput(
                    o.to_string(),
                    o.node.clone(),
                    node.kind.clone(),
                    o.port.clone(),
                ));
            }
        }
        Ok(crate::scheduler::execute(self, graph, opts, observer))
    }
}
