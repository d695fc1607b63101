//! mesoflow's executor: the node contract, opaque values, Merkle cache keys, the memory and disk
//! caches, the GPU device shared by a run, the demand-driven scheduler and the run report.
//!
//! The runtime knows no algorithm and no domain type: values reach it as [`Value`] trait objects
//! that report their type name and size and encode themselves for the disk cache.

pub mod atomic_file;
pub mod cache;
pub mod codec;
pub mod confine;
pub mod engine;
pub mod explain;
pub mod gpu;
pub mod gpu_memo;
pub mod key;
pub mod node;
mod node_panic;
pub mod producer;
pub mod progress;
pub mod registry;
pub mod report;
mod resources;
pub mod run;
mod scheduler;
pub mod value;

pub use atomic_file::write_atomic;
pub use confine::Confinement;
pub use engine::{Engine, EngineConfig, EngineError};
pub use gpu::{Gpu, GpuProvider};
pub use key::{Key, KEY_SCHEME};
pub use node::{DynNode, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Prepared};
pub use progress::ProgressSteps;
pub use registry::Registry;
pub use report::{NodeReport, NodeStatus, RunReport, Warning};
pub use run::{
    require_gpu_from_env, DeviceMode, RunObserver, RunOptions, RunOutcome, RunPolicy,
    SilentObserver, NOT_IN_CACHE,
};
pub use scheduler::dry_run::Explained;
pub use value::{ArrayView, Artifact, Artifacts, Scalar, Value, ValueRef};
