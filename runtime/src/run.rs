//! What one run is asked for and what it hands back: the options (`RunOptions`, `DeviceMode`),
//! the observer that hears about it as it goes, and its outcome. The engine and the scheduler
//! both take these from here; neither imports the other's types.

use crate::node::Outputs;
use crate::report::{NodeReport, RunReport};
use mesoflow_graph::PortRef;
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

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

/// Hears about a run as it goes (the command line draws progress bars from this).
pub trait RunObserver: Send + Sync {
    fn node_started(&self, _id: &str, _kind: &str, _device: &str) {}
    fn progress(&self, _id: &str, _done: u64, _total: u64) {}
    fn node_finished(&self, _report: &NodeReport) {}
}

pub struct SilentObserver;
impl RunObserver for SilentObserver {}

/// What holds for every run of a session (a command, a studio, a Python process): the device
/// policy, the caches, verification, the cancel flag and the folders runs are confined to.
/// Built once per session; each run's [`RunOptions`] carries a copy.
#[derive(Clone, Debug)]
pub struct RunPolicy {
    pub device: DeviceMode,
    /// A GPU node without an adapter fails instead of falling back (`MESOFLOW_REQUIRE_GPU=1`).
    pub require_gpu: bool,
    /// Read and write the caches.
    pub use_cache: bool,
    /// Recompute cache hits and fail on a mismatch.
    pub verify_cache: bool,
    pub cancel: Arc<AtomicBool>,
    /// Folders every input file must lie in, links followed, when it is hashed and when its node
    /// opens it (the studio's folders); `None`: anywhere.
    pub confine: Option<crate::confine::Confinement>,
}

impl Default for RunPolicy {
    /// Automatic device choice, `require_gpu` from the environment, caches read and written, no
    /// verification, a fresh cancel flag, no confinement.
    fn default() -> Self {
        RunPolicy {
            device: DeviceMode::Auto,
            require_gpu: require_gpu_from_env(),
            use_cache: true,
            verify_cache: false,
            cancel: Arc::new(AtomicBool::new(false)),
            confine: None,
        }
    }
}

/// One run: what it runs on and where (graph name, folders, outputs, the cluster's fields) and the
/// session's [`RunPolicy`].
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// The graph's path as the user gave it; it goes into the report.
    pub graph_name: String,
    /// Folder that relative input paths resolve against (the graph file's folder).
    pub base_dir: PathBuf,
    /// Folder that relative output paths resolve against.
    pub out_dir: PathBuf,
    /// Outputs to produce; empty means every sink of the graph.
    pub outputs: Vec<PortRef>,
    /// Only these nodes may be computed; any other node whose value is not in a cache fails
    /// with [`NOT_IN_CACHE`] instead of running (a cluster job runs its unit, never its inputs;
    /// the driver's final pass computes nothing). `None`: every node may run.
    pub compute_only: Option<BTreeSet<String>>,
    /// Write every computed value to the disk cache, also those of kinds that are cheaper to
    /// recompute than to read (`NodeSpec::disk_cache` false): a cluster job hands its values
    /// over to other jobs only through the cache.
    pub cache_everything: bool,
    pub policy: RunPolicy,
}

/// Whether `MESOFLOW_REQUIRE_GPU=1` asks that GPU nodes never fall back to their CPU path: the
/// one place the variable is read ([`RunPolicy::default`]; the command line also refuses a value
/// other than 0 or 1 at start-up).
pub fn require_gpu_from_env() -> bool {
    std::env::var("MESOFLOW_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// The start of the error of a node that a `compute_only` run would have had to compute.
pub const NOT_IN_CACHE: &str = "not in the cache, and not computed here";

impl RunOptions {
    /// A run of every sink under `policy`.
    pub fn new(graph_name: &str, base_dir: PathBuf, out_dir: PathBuf, policy: RunPolicy) -> Self {
        RunOptions {
            graph_name: graph_name.into(),
            base_dir,
            out_dir,
            outputs: Vec::new(),
            compute_only: None,
            cache_everything: false,
            policy,
        }
    }

    /// Options for another run of the same session: this one's graph name, folders and policy,
    /// none of its per-run fields (outputs, compute_only, cache_everything).
    pub fn same_policy(&self) -> RunOptions {
        RunOptions::new(
            &self.graph_name,
            self.base_dir.clone(),
            self.out_dir.clone(),
            self.policy.clone(),
        )
    }
}

/// A run's report and the values of the nodes it was asked for (by default the sinks), by node
/// id: what an embedding (the Python package) hands back to its caller. A node that failed or
/// was cancelled has no entry.
pub struct RunOutcome {
    pub report: RunReport,
    pub values: BTreeMap<String, Outputs>,
}
