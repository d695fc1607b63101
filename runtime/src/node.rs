//! The node contract. A node kind is a pure function of its parameters, its inputs and the files
//! it declares it reads; it gets a [`NodeContext`] for progress, cancellation, warnings and the GPU.

use crate::gpu::Gpu;
use crate::value::{Value, ValueRef};
use mesoflow_graph::{DevicePreference, InputSpec, KindSignature, OutputSpec, TypeSet};
use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use thiserror::Error;

/// What went wrong inside a node. The scheduler adds the node id.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum NodeError {
    #[error("parameter `{param}`: {message}")]
    Param { param: String, message: String },
    #[error("input `{port}`: {message}")]
    Input { port: String, message: String },
    #[error("{path}: {message}")]
    File { path: String, message: String },
    #[error("GPU: {0}")]
    Gpu(String),
    #[error("cancelled")]
    Cancelled,
    #[error("{0}")]
    Failed(String),
}

impl NodeError {
    pub fn param(param: &str, message: impl Into<String>) -> Self {
        NodeError::Param {
            param: param.into(),
            message: message.into(),
        }
    }
    pub fn input(port: &str, message: impl Into<String>) -> Self {
        NodeError::Input {
            port: port.into(),
            message: message.into(),
        }
    }
    pub fn file(path: &Path, message: impl ToString) -> Self {
        NodeError::File {
            path: path.display().to_string(),
            message: message.to_string(),
        }
    }
}

/// Declaration of a port, for [`NodeSpec`].
#[derive(Clone, Debug)]
pub struct Port {
    pub name: &'static str,
    pub ty: TypeSet,
    pub required: bool,
    pub doc: &'static str,
}

impl Port {
    pub fn input(name: &'static str, ty: &str, doc: &'static str) -> Port {
        Port {
            name,
            ty: TypeSet::one(ty),
            required: true,
            doc,
        }
    }
    pub fn optional(name: &'static str, ty: &str, doc: &'static str) -> Port {
        Port {
            name,
            ty: TypeSet::one(ty),
            required: false,
            doc,
        }
    }
    pub fn any_of(name: &'static str, types: &[&str], doc: &'static str) -> Port {
        Port {
            name,
            ty: TypeSet::any_of(types.iter().copied()),
            required: true,
            doc,
        }
    }
    pub fn output(name: &'static str, ty: &str, doc: &'static str) -> Port {
        Port {
            name,
            ty: TypeSet::one(ty),
            required: true,
            doc,
        }
    }
    /// An output that is sometimes absent: a metric that needs a truth input which is not
    /// connected is left out (never reported as 0).
    pub fn optional_output(name: &'static str, ty: &str, doc: &'static str) -> Port {
        Port {
            name,
            ty: TypeSet::one(ty),
            required: false,
            doc,
        }
    }
}

/// A kind's static description.
#[derive(Clone, Debug)]
pub struct NodeSpec {
    pub kind: &'static str,
    /// Bump whenever the outputs for the same inputs change: it is part of every cache key.
    pub version: u32,
    pub doc: &'static str,
    pub device: DevicePreference,
    pub inputs: Vec<Port>,
    pub outputs: Vec<Port>,
    /// False when recomputing is cheaper than reading the disk cache.
    pub disk_cache: bool,
}

/// A node kind. Implement this, then add one line to the registry in `mesoflow-nodes`.
pub trait Node: Send + Sync + 'static {
    /// Parameters, with defaults (`#[serde(default)]`) and doc comments that become the schema.
    type Params: Serialize + DeserializeOwned + JsonSchema + Send + Sync + 'static;

    fn spec(&self) -> NodeSpec;

    /// Checks of parameter values that the JSON Schema cannot express (relations between
    /// parameters, sizes that must fit memory). It runs when the graph is validated, before any
    /// upstream work, and again before `run`.
    fn check(&self, _params: &Self::Params) -> Result<(), NodeError> {
        Ok(())
    }

    /// Timings the node reports through [`NodeContext::timing`], as (name, doc): they go into the
    /// run report beside the node's wall time, never into its cached outputs, because the same
    /// inputs give the same value but not the same time.
    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[]
    }

    /// Files the node will read, resolved against `base` (the graph's folder); their contents enter
    /// the cache key. Called before `run`.
    fn files(&self, _params: &Self::Params, _base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(Vec::new())
    }

    fn run(
        &self,
        ctx: &NodeContext,
        params: &Self::Params,
        inputs: &Inputs,
    ) -> Result<Outputs, NodeError>;
}

/// Receives what nodes report while running.
pub trait ProgressSink: Send + Sync {
    fn progress(&self, node: &str, done: u64, total: u64);
    fn warn(&self, node: &str, message: String);
}

/// What a running node may use besides its inputs.
pub struct NodeContext {
    pub(crate) node: String,
    pub(crate) base_dir: PathBuf,
    pub(crate) cancel: Arc<AtomicBool>,
    pub(crate) gpu: Option<Arc<Gpu>>,
    pub(crate) sink: Arc<dyn ProgressSink>,
    pub(crate) timings: std::sync::Mutex<BTreeMap<String, f64>>,
    /// The warnings given so far, kept with the value in the caches.
    pub(crate) warnings: std::sync::Mutex<Vec<String>>,
    /// The run's confinement, checked when an input path is resolved.
    pub(crate) confine: Option<crate::confine::Confinement>,
    /// The run's disk cache, for what a node derives from its inputs ([`NodeContext::load_derived`]);
    /// `None` without one (`--no-cache`, a detached context).
    pub(crate) derived: Option<crate::cache::DiskCache>,
}

impl NodeContext {
    /// A context for calling a node directly (tests, benchmarks): no progress, no GPU unless given.
    pub fn detached(gpu: Option<Arc<Gpu>>) -> NodeContext {
        struct Quiet;
        impl ProgressSink for Quiet {
            fn progress(&self, _: &str, _: u64, _: u64) {}
            fn warn(&self, _: &str, _: String) {}
        }
        NodeContext {
            node: "detached".into(),
            base_dir: PathBuf::from("."),
            cancel: Arc::new(AtomicBool::new(false)),
            gpu,
            sink: Arc::new(Quiet),
            timings: Default::default(),
            warnings: Default::default(),
            confine: None,
            derived: None,
        }
    }

    /// The same context resolving input paths against `base` (for calling file readers directly).
    pub fn with_base(mut self, base: PathBuf) -> NodeContext {
        self.base_dir = base;
        self
    }

    /// The same context keeping derived data ([`NodeContext::load_derived`]) in `cache`
    /// (for calling a node directly).
    pub fn with_derived(mut self, cache: crate::cache::DiskCache) -> NodeContext {
        self.derived = Some(cache);
        self
    }
    pub fn node_id(&self) -> &str {
        &self.node
    }
    /// Reports `done` of `total` units of work.
    pub fn progress(&self, done: u64, total: u64) {
        self.sink.progress(&self.node, done, total);
    }
    /// A documented, non-fatal problem; it appears in the run report's warnings, and again in
    /// those of every run that takes the value from a cache.
    pub fn warn(&self, message: impl Into<String>) {
        let message = message.into();
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(message.clone());
        self.sink.warn(&self.node, message);
    }
    /// The warnings given so far (tests that call nodes directly read them).
    pub fn warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
    /// Records a timing of this computation (declared in [`Node::timings`]) for the run report.
    /// A value that is not finite is dropped: an unknown time is absent, never 0 or NaN.
    pub fn timing(&self, name: &str, value: f64) {
        if value.is_finite() {
            self.timings
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert(name.to_string(), value);
        }
    }
    /// The timings recorded so far (tests and benchmarks that call nodes directly read them).
    pub fn timings(&self) -> BTreeMap<String, f64> {
        self.timings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
    pub fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
    /// `Err(Cancelled)` once the run was cancelled; call it between units of work.
    pub fn check_cancel(&self) -> Result<(), NodeError> {
        if self.is_cancelled() {
            Err(NodeError::Cancelled)
        } else {
            Ok(())
        }
    }
    /// The GPU, when the scheduler placed this node on the GPU lane; `None` means: take the CPU path.
    pub fn gpu(&self) -> Option<&Gpu> {
        self.gpu.as_deref()
    }
    /// Bytes this node derived from its inputs on an earlier run, in this process or another:
    /// data that is costly to make and not a value of the graph (a large mesh's BVH), stored
    /// by [`NodeContext::store_derived`] under `kind` (what it is, with its format's version)
    /// and `key` (the hash of what it was made from). `None` without a disk cache, on a miss,
    /// or for an entry that fails its checksum (removed, so the next store replaces it).
    pub fn load_derived(&self, kind: &str, key: &[u8; 32]) -> Option<Vec<u8>> {
        let cache = self.derived.as_ref()?;
        let key = derived_key(kind, key);
        match cache.get_bytes(&key, kind) {
            Ok(found) => found,
            Err(crate::cache::DiskError::Corrupt { .. }) => {
                cache.remove(&key);
                None
            }
            Err(_) => None,
        }
    }

    /// Keeps `bytes` for [`NodeContext::load_derived`] in the run's disk cache, an entry like a
    /// value's (counted by `cache stats` under `kind`, collected by `cache gc`); `seconds` is
    /// what making them cost. Best effort: without a disk cache, or where it cannot be
    /// written, nothing is kept and the next run derives them again.
    pub fn store_derived(&self, kind: &str, key: &[u8; 32], bytes: &[u8], seconds: f64) {
        if let Some(cache) = &self.derived {
            let record = crate::cache::Record {
                seconds,
                ..Default::default()
            };
            let _ = cache.put_bytes(&derived_key(kind, key), kind, bytes, &record);
        }
    }

    /// Resolves parameter `param`'s input path `p` against the graph's folder, as the node is
    /// about to open it. A path that does not exist is an error naming the parameter and the
    /// folder it was resolved against; in a confined run (the studio) so is one that resolves
    /// outside the run's folders, whatever it was when the graph was checked.
    pub fn input_path(&self, param: &str, p: &str) -> Result<PathBuf, NodeError> {
        let path = self.base_dir.join(p);
        if !path.exists() {
            return Err(NodeError::param(
                param,
                format!(
                    "{p}: no such file or folder (a relative path resolves against the graph's folder, {})",
                    self.base_dir.display()
                ),
            ));
        }
        crate::confine::admit(self.confine.as_ref(), &path).map_err(|m| NodeError::file(&path, m))
    }
}

/// A derived entry's cache key: its kind and its own key hashed apart from every value's key.
fn derived_key(kind: &str, key: &[u8; 32]) -> crate::key::Key {
    let mut h = blake3::Hasher::new();
    h.update(b"mesoflow derived\0");
    h.update(kind.as_bytes());
    h.update(b"\0");
    h.update(key);
    crate::key::Key(*h.finalize().as_bytes())
}

/// A node's inputs by port name.
#[derive(Default, Clone)]
pub struct Inputs {
    pub(crate) values: BTreeMap<String, ValueRef>,
}

impl Inputs {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn with(mut self, port: &str, v: ValueRef) -> Self {
        self.values.insert(port.into(), v);
        self
    }
    /// A connected input of type `T`.
    pub fn get<T: Value>(&self, port: &str) -> Result<&T, NodeError> {
        self.opt(port)?
            .ok_or_else(|| NodeError::input(port, "not connected"))
    }
    /// An optional input of type `T`.
    pub fn opt<T: Value>(&self, port: &str) -> Result<Option<&T>, NodeError> {
        match self.values.get(port) {
            None => Ok(None),
            Some(v) => v.as_any().downcast_ref::<T>().map(Some).ok_or_else(|| {
                NodeError::input(
                    port,
                    format!(
                        "got a {} value of an unexpected representation",
                        v.type_name()
                    ),
                )
            }),
        }
    }
    /// The value as the runtime holds it, for nodes that accept several types.
    pub fn value(&self, port: &str) -> Result<&ValueRef, NodeError> {
        self.values
            .get(port)
            .ok_or_else(|| NodeError::input(port, "not connected"))
    }
}

/// A node's outputs by port name.
#[derive(Default, Clone, Debug)]
pub struct Outputs {
    pub values: BTreeMap<String, ValueRef>,
}

impl Outputs {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn with(mut self, port: &str, v: impl Value) -> Self {
        self.values.insert(port.into(), Arc::new(v));
        self
    }
    pub fn get(&self, port: &str) -> Option<&ValueRef> {
        self.values.get(port)
    }
    pub fn byte_size(&self) -> usize {
        self.values.values().map(|v| v.byte_size()).sum()
    }
}

/// Parameters after the defaults were applied: the typed value and its canonical JSON.
pub struct Prepared {
    pub(crate) params: Box<dyn std::any::Any + Send + Sync>,
    pub canonical: serde_json::Value,
}

impl Prepared {
    /// For a [`DynNode`] implemented outside this crate: `canonical` is what enters the cache
    /// key, so it must hold everything the output depends on.
    pub fn new(params: Box<dyn std::any::Any + Send + Sync>, canonical: serde_json::Value) -> Self {
        Prepared { params, canonical }
    }

    /// The parameters as [`Prepared::new`] received them.
    pub fn params(&self) -> &(dyn std::any::Any + Send + Sync) {
        self.params.as_ref()
    }
}

/// The object-safe face of [`Node`], which the registry stores.
pub trait DynNode: Send + Sync {
    fn spec(&self) -> &NodeSpec;
    fn signature(&self) -> &KindSignature;
    fn prepare(
        &self,
        params: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<Prepared, NodeError>;
    fn files(&self, p: &Prepared, base: &Path) -> Result<Vec<PathBuf>, NodeError>;
    fn timings(&self) -> &'static [(&'static str, &'static str)];
    fn run(&self, ctx: &NodeContext, p: &Prepared, inputs: &Inputs) -> Result<Outputs, NodeError>;
}

pub(crate) struct Erased<N: Node> {
    pub node: N,
    pub spec: NodeSpec,
    pub signature: KindSignature,
}

impl<N: Node> Erased<N> {
    pub fn new(node: N) -> Self {
        let spec = node.spec();
        let schema = schemars::schema_for!(N::Params);
        let signature = KindSignature {
            kind: spec.kind.into(),
            version: spec.version,
            device: spec.device,
            doc: spec.doc.into(),
            inputs: spec
                .inputs
                .iter()
                .map(|p| InputSpec {
                    name: p.name.into(),
                    ty: p.ty.clone(),
                    required: p.required,
                    doc: p.doc.into(),
                })
                .collect(),
            outputs: spec
                .outputs
                .iter()
                .map(|p| OutputSpec {
                    name: p.name.into(),
                    ty: p.ty.to_string(),
                    doc: p.doc.into(),
                })
                .collect(),
            params: schema.into(),
            timings: node
                .timings()
                .iter()
                .map(|(name, doc)| OutputSpec {
                    name: (*name).into(),
                    ty: "Scalar".into(),
                    doc: (*doc).into(),
                })
                .collect(),
        };
        Erased {
            node,
            spec,
            signature,
        }
    }

    fn typed<'a>(&self, p: &'a Prepared) -> Result<&'a N::Params, NodeError> {
        p.params.downcast_ref::<N::Params>().ok_or_else(|| {
            NodeError::Failed("internal: parameters prepared for another kind".into())
        })
    }
}

impl<N: Node> DynNode for Erased<N> {
    fn spec(&self) -> &NodeSpec {
        &self.spec
    }
    fn signature(&self) -> &KindSignature {
        &self.signature
    }
    fn prepare(
        &self,
        params: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<Prepared, NodeError> {
        let typed: N::Params = serde_json::from_value(serde_json::Value::Object(params.clone()))
            .map_err(|e| NodeError::param("params", e.to_string()))?;
        self.node.check(&typed)?;
        // The canonical form includes every default, so omitting a parameter and writing its
        // default give the same cache key.
        let canonical =
            serde_json::to_value(&typed).map_err(|e| NodeError::param("params", e.to_string()))?;
        Ok(Prepared {
            params: Box::new(typed),
            canonical,
        })
    }
    fn files(&self, p: &Prepared, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        self.node.files(self.typed(p)?, base)
    }
    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        self.node.timings()
    }
    fn run(&self, ctx: &NodeContext, p: &Prepared, inputs: &Inputs) -> Result<Outputs, NodeError> {
        self.node.run(ctx, self.typed(p)?, inputs)
    }
}
