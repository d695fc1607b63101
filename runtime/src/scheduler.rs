//! Demand-driven execution of one checked graph.
//!
//! 1. **Plan**: the requested outputs (by default the sinks) and their ancestors.
//! 2. **Key**: in topological order, apply parameter defaults, hash declared files, and derive each
//!    node's Merkle key from its inputs' keys.
//! 3. **Demand**: from the requested nodes upwards, look each key up (memory, then disk). A hit
//!    ends the walk on that branch: its ancestors are not needed and are reported as skipped.
//!    With `--verify-cache` a hit is still recomputed, so its inputs are demanded too.
//! 4. **Execute**: the misses run as soon as their inputs are ready, CPU nodes on rayon, GPU nodes
//!    one at a time on the GPU lane. A failure stops its dependants; independent nodes finish.
//!    Cancellation stops dispatching and running nodes see the flag.

use crate::engine::{DeviceMode, Engine, RunObserver, RunOptions};
use crate::key::{self, Key, KeyParts};
use crate::node::{DynNode, Inputs, NodeContext, NodeError, Outputs, Prepared, ProgressSink};
use crate::report::{NodeReport, NodeStatus, RunReport, Warning};
use crate::value::{Artifact, Artifacts};
use mesoflow_graph::{CheckedGraph, DevicePreference};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Instant;

struct Sink {
    observer: Arc<dyn RunObserver>,
    warnings: Mutex<Vec<Warning>>,
}

impl Sink {
    fn push(&self, node: &str, message: String) {
        tracing::warn!(node, "{message}");
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(Warning {
                node: node.into(),
                message,
            });
    }
}

impl ProgressSink for Sink {
    fn progress(&self, node: &str, done: u64, total: u64) {
        self.observer.progress(node, done, total);
    }
    fn warn(&self, node: &str, message: String) {
        self.push(node, message);
    }
}

/// Per-node state of one run.
struct Slot {
    node: Arc<dyn DynNode>,
    prepared: Option<Arc<Prepared>>,
    key: Option<Key>,
    outputs: Option<Outputs>,
    report: Option<NodeReport>,
    /// A cached value to compare against (`--verify-cache`).
    expected: Option<(Outputs, NodeStatus)>,
}

struct Done {
    idx: usize,
    result: Result<Outputs, NodeError>,
    seconds: f64,
    device: &'static str,
    verified: bool,
}

fn device_name(d: DevicePreference) -> &'static str {
    match d {
        DevicePreference::Cpu => "cpu",
        DevicePreference::Gpu => "gpu",
    }
}

fn metrics(outputs: &Outputs) -> BTreeMap<String, f64> {
    outputs
        .values
        .iter()
        .filter_map(|(name, v)| v.as_scalar().map(|x| (name.clone(), x)))
        .collect()
}

pub(crate) fn execute(
    engine: &Engine,
    graph: &CheckedGraph,
    opts: &RunOptions,
    observer: Arc<dyn RunObserver>,
) -> RunReport {
    let t0 = Instant::now();
    let sink = Arc::new(Sink {
        observer: observer.clone(),
        warnings: Mutex::new(Vec::new()),
    });
    let n = graph.nodes.len();
    let index: BTreeMap<&str, usize> = graph
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.id.as_str(), i))
        .collect();
    let upstream: Vec<Vec<usize>> = graph
        .nodes
        .iter()
        .map(|node| {
            let set: BTreeSet<usize> = node
                .inputs
                .iter()
                .filter_map(|e| index.get(e.from.node.as_str()).copied())
                .collect();
            set.into_iter().collect()
        })
        .collect();

    let mut downstream: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (j, ups) in upstream.iter().enumerate() {
        for &u in ups {
            downstream[u].push(j);
        }
    }

    // 1. Plan.
    let requested: BTreeSet<usize> = if opts.outputs.is_empty() {
        graph
            .sinks()
            .iter()
            .filter_map(|id| index.get(id).copied())
            .collect()
    } else {
        opts.outputs
            .iter()
            .filter_map(|o| index.get(o.node.as_str()).copied())
            .collect()
    };
    let mut needed = vec![false; n];
    for &i in &requested {
        needed[i] = true;
    }
    for i in (0..n).rev() {
        if needed[i] {
            for &u in &upstream[i] {
                needed[u] = true;
            }
        }
    }

    // 2. Key.
    let mut slots: Vec<Option<Slot>> = Vec::with_capacity(n);
    let mut read_files = BTreeSet::new();
    for (i, cn) in graph.nodes.iter().enumerate() {
        if !needed[i] {
            slots.push(None);
            continue;
        }
        let Some(node) = engine.registry.node(&cn.kind).cloned() else {
            slots.push(None);
            continue;
        };
        let mut slot = Slot {
            node,
            prepared: None,
            key: None,
            outputs: None,
            report: None,
            expected: None,
        };
        let failed_input = upstream[i]
            .iter()
            .find(|&&u| slots[u].as_ref().is_none_or(|s| s.key.is_none()));
        let keyed = match failed_input {
            Some(&u) => Err((
                NodeStatus::Cancelled,
                format!("not run: input node `{}` failed", graph.nodes[u].id),
            )),
            None => prepare_and_key(
                &slot.node,
                cn,
                &slots,
                &index,
                &opts.base_dir,
                &mut read_files,
            )
            .map_err(|e| (NodeStatus::Failed, e.to_string())),
        };
        match keyed {
            Ok((prepared, key)) => {
                slot.prepared = Some(Arc::new(prepared));
                slot.key = Some(key);
            }
            Err((status, error)) => {
                slot.report = Some(failure(cn, &slot.node, status, error, None))
            }
        }
        slots.push(Some(slot));
    }

    // 3. Demand.
    let mut demanded = vec![false; n];
    for &i in &requested {
        demanded[i] = true;
    }
    let mut compute = vec![false; n];
    for i in (0..n).rev() {
        if !demanded[i] {
            continue;
        }
        let Some(slot) = slots[i].as_mut() else {
            continue;
        };
        let Some(key) = slot.key else { continue };
        let cn = &graph.nodes[i];
        let hit = if opts.use_cache {
            lookup(engine, &key, cn.id.as_str(), &sink)
        } else {
            None
        };
        match hit {
            Some((outputs, status, seconds)) if !opts.verify_cache => {
                let report = NodeReport {
                    id: cn.id.clone(),
                    kind: cn.kind.clone(),
                    device: device_name(planned_device(slot.node.spec().device, opts.device))
                        .into(),
                    status,
                    seconds,
                    bytes: outputs.byte_size() as u64,
                    key: key.hex(),
                    metrics: metrics(&outputs),
                    error: None,
                    verified: false,
                };
                slot.outputs = Some(outputs);
                slot.report = Some(report);
            }
            hit => {
                slot.expected = hit.map(|(o, s, _)| (o, s));
                compute[i] = true;
                for &u in &upstream[i] {
                    demanded[u] = true;
                }
            }
        }
    }

    let out_dir = opts.out_dir.clone();
    let mut files = Vec::new();
    for (slot, cn) in slots.iter().zip(&graph.nodes) {
        let Some(slot) = slot else { continue };
        if let Some(out) = &slot.outputs {
            write_artifacts(&cn.id, out, &out_dir, &sink, &mut files);
        }
        if let Some(r) = &slot.report {
            observer.node_finished(r);
        }
    }

    // 4. Execute.
    let mut waiting: Vec<usize> = (0..n)
        .map(|i| {
            if compute[i] {
                upstream[i].iter().filter(|&&u| compute[u]).count()
            } else {
                0
            }
        })
        .collect();
    let mut ready: BTreeSet<usize> = (0..n).filter(|&i| compute[i] && waiting[i] == 0).collect();
    let (tx, rx) = mpsc::channel::<Done>();
    let gpu_lane = Arc::new(Mutex::new(()));
    let mut running = 0usize;
    loop {
        while !opts.cancel.load(Ordering::Relaxed) {
            let Some(i) = ready.pop_first() else { break };
            if slots[i].as_ref().is_none_or(|s| s.report.is_some()) {
                continue; // failed while preparing
            }
            let cn = &graph.nodes[i];
            let mut inputs = Inputs::new();
            for e in &cn.inputs {
                let value = index
                    .get(e.from.node.as_str())
                    .and_then(|&u| slots[u].as_ref())
                    .and_then(|s| s.outputs.as_ref())
                    .and_then(|o| o.get(&e.from.port))
                    .cloned();
                if let Some(v) = value {
                    inputs = inputs.with(&e.port, v);
                }
            }
            let Some(slot) = slots[i].as_mut() else {
                continue;
            };
            let gpu = match choose_device(engine, slot.node.spec().device, opts) {
                Ok(gpu) => gpu,
                Err(message) => {
                    let r = failure(cn, &slot.node, NodeStatus::Failed, message, slot.key);
                    observer.node_finished(&r);
                    slot.report = Some(r);
                    cancel_dependants(i, graph, &upstream, &compute, &mut slots, &observer);
                    continue;
                }
            };
            if slot.node.spec().device == DevicePreference::Gpu
                && gpu.is_none()
                && opts.device == DeviceMode::Auto
            {
                sink.push(&cn.id, "no GPU adapter; ran the CPU path".into());
            }
            let device = if gpu.is_some() { "gpu" } else { "cpu" };
            observer.node_started(&cn.id, &cn.kind, device);
            let task = Task {
                idx: i,
                node: slot.node.clone(),
                prepared: slot.prepared.clone(),
                key: slot.key,
                inputs,
                ctx: NodeContext {
                    node: cn.id.clone(),
                    base_dir: opts.base_dir.clone(),
                    cancel: opts.cancel.clone(),
                    gpu,
                    sink: sink.clone(),
                },
                expected: slot.expected.as_ref().map(|(o, _)| o.clone()),
                memory: opts.use_cache.then(|| engine.memory.clone()),
                disk: if opts.use_cache && slot.node.spec().disk_cache {
                    engine.disk.clone()
                } else {
                    None
                },
                device,
                tx: tx.clone(),
            };
            running += 1;
            if running == 1 && ready.is_empty() && device == "cpu" {
                // Nothing else is runnable: a hand-off to the pool would only add a thread
                // wake-up per node (it dominates long chains of small nodes). The node's own
                // parallel loops still use the pool.
                task.run();
            } else if device == "gpu" {
                // The GPU lane: GPU nodes submit to the one device one at a time, off the rayon
                // pool so CPU nodes keep running beside them.
                let lane = gpu_lane.clone();
                std::thread::spawn(move || {
                    let _guard = lane.lock().unwrap_or_else(|e| e.into_inner());
                    task.run();
                });
            } else {
                rayon::spawn(move || task.run());
            }
        }
        if running == 0 {
            break;
        }
        let Ok(done) = rx.recv() else { break };
        running -= 1;
        let i = done.idx;
        let cn = &graph.nodes[i];
        let Some(slot) = slots[i].as_mut() else {
            continue;
        };
        let key = slot.key;
        let report = match done.result {
            Ok(outputs) => {
                let status = match (&slot.expected, done.verified) {
                    (Some((_, s)), true) => *s,
                    _ => NodeStatus::Computed,
                };
                let r = NodeReport {
                    id: cn.id.clone(),
                    kind: cn.kind.clone(),
                    device: done.device.into(),
                    status,
                    seconds: done.seconds,
                    bytes: outputs.byte_size() as u64,
                    key: key.map(|k| k.hex()).unwrap_or_default(),
                    metrics: metrics(&outputs),
                    error: None,
                    verified: done.verified,
                };
                write_artifacts(&cn.id, &outputs, &out_dir, &sink, &mut files);
                slot.outputs = Some(outputs);
                for &j in &downstream[i] {
                    if compute[j] {
                        waiting[j] -= 1;
                        if waiting[j] == 0 {
                            ready.insert(j);
                        }
                    }
                }
                r
            }
            Err(e) => {
                let status = if e == NodeError::Cancelled {
                    NodeStatus::Cancelled
                } else {
                    NodeStatus::Failed
                };
                let mut r = failure(cn, &slot.node, status, e.to_string(), key);
                r.seconds = done.seconds;
                r.device = done.device.into();
                cancel_dependants(i, graph, &upstream, &compute, &mut slots, &observer);
                r
            }
        };
        observer.node_finished(&report);
        if let Some(slot) = slots[i].as_mut() {
            slot.report = Some(report);
        }
    }

    let cancelled = opts.cancel.load(Ordering::Relaxed);
    let mut nodes = Vec::new();
    let mut skipped = Vec::new();
    for (i, cn) in graph.nodes.iter().enumerate() {
        let Some(slot) = slots[i].as_mut() else {
            continue;
        };
        match slot.report.take() {
            Some(r) => nodes.push(r),
            None if compute[i] => nodes.push(failure(
                cn,
                &slot.node,
                NodeStatus::Cancelled,
                "cancelled".into(),
                slot.key,
            )),
            None => skipped.push(cn.id.clone()),
        }
    }
    let ok = nodes.iter().all(|r| {
        matches!(
            r.status,
            NodeStatus::Computed | NodeStatus::Memory | NodeStatus::Disk
        )
    });
    let warnings = std::mem::take(&mut *sink.warnings.lock().unwrap_or_else(|e| e.into_inner()));
    RunReport {
        mesoflow: 1,
        graph: opts.graph_name.clone(),
        ok,
        seconds: t0.elapsed().as_secs_f64(),
        nodes,
        warnings,
        skipped,
        files,
        cancelled,
        read: read_files.into_iter().collect(),
    }
}

fn planned_device(pref: DevicePreference, mode: DeviceMode) -> DevicePreference {
    if mode == DeviceMode::Cpu {
        DevicePreference::Cpu
    } else {
        pref
    }
}

/// `Ok(Some(gpu))` to run on the GPU lane, `Ok(None)` for the CPU path, `Err` when a GPU was
/// required and none can be had.
fn choose_device(
    engine: &Engine,
    pref: DevicePreference,
    opts: &RunOptions,
) -> Result<Option<Arc<crate::gpu::Gpu>>, String> {
    if planned_device(pref, opts.device) == DevicePreference::Cpu {
        return Ok(None);
    }
    match engine.gpu.get() {
        Ok(gpu) => Ok(Some(gpu)),
        Err(e) if opts.device == DeviceMode::Gpu => Err(format!("{e} (--device gpu)")),
        Err(e) if opts.require_gpu => Err(format!(
            "{e} (MESOFLOW_REQUIRE_GPU=1 forbids the CPU fallback)"
        )),
        Err(_) => Ok(None),
    }
}

fn prepare_and_key(
    node: &Arc<dyn DynNode>,
    cn: &mesoflow_graph::CheckedNode,
    slots: &[Option<Slot>],
    index: &BTreeMap<&str, usize>,
    base: &Path,
    read_files: &mut BTreeSet<String>,
) -> Result<(Prepared, Key), NodeError> {
    let prepared = node.prepare(&cn.params)?;
    let mut files = Vec::new();
    for path in node.files(&prepared, base)? {
        files.push(key::hash_file(&path).map_err(|e| NodeError::file(&path, e))?);
        let shown = std::fs::canonicalize(&path).unwrap_or(path);
        read_files.insert(shown.display().to_string());
    }
    let mut inputs = Vec::new();
    for e in &cn.inputs {
        let k = index
            .get(e.from.node.as_str())
            .and_then(|&u| slots[u].as_ref())
            .and_then(|s| s.key)
            .ok_or_else(|| NodeError::input(&e.port, format!("`{}` has no key", e.from)))?;
        inputs.push((e.port.as_str(), k, e.from.port.as_str()));
    }
    let spec = node.spec();
    let key = key::compute(&KeyParts {
        kind: spec.kind,
        version: spec.version,
        params: &prepared.canonical,
        inputs,
        files,
    });
    Ok((prepared, key))
}

fn lookup(
    engine: &Engine,
    key: &Key,
    node: &str,
    sink: &Sink,
) -> Option<(Outputs, NodeStatus, f64)> {
    if let Some(out) = engine.memory.get(key) {
        return Some((out, NodeStatus::Memory, 0.0));
    }
    let disk = engine.disk.as_ref()?;
    let t = Instant::now();
    match disk.get(key, &engine.registry) {
        Ok(Some((outputs, compute_seconds))) => {
            engine.memory.insert(*key, outputs.clone(), compute_seconds);
            Some((outputs, NodeStatus::Disk, t.elapsed().as_secs_f64()))
        }
        Ok(None) => None,
        Err(e) => {
            sink.push(node, format!("{e}; recomputing"));
            disk.remove(key);
            None
        }
    }
}

fn failure(
    cn: &mesoflow_graph::CheckedNode,
    node: &Arc<dyn DynNode>,
    status: NodeStatus,
    error: String,
    key: Option<Key>,
) -> NodeReport {
    NodeReport {
        id: cn.id.clone(),
        kind: cn.kind.clone(),
        device: device_name(node.spec().device).into(),
        status,
        seconds: 0.0,
        bytes: 0,
        key: key.map(|k| k.hex()).unwrap_or_default(),
        metrics: BTreeMap::new(),
        error: Some(format!("node `{}`: {error}", cn.id)),
        verified: false,
    }
}

/// Marks every not-yet-run descendant of `failed` as cancelled.
fn cancel_dependants(
    failed: usize,
    graph: &CheckedGraph,
    upstream: &[Vec<usize>],
    compute: &[bool],
    slots: &mut [Option<Slot>],
    observer: &Arc<dyn RunObserver>,
) {
    let mut dead = BTreeSet::from([failed]);
    for j in failed + 1..graph.nodes.len() {
        if compute[j] && upstream[j].iter().any(|u| dead.contains(u)) {
            dead.insert(j);
            if let Some(slot) = slots[j].as_mut() {
                if slot.report.is_none() {
                    let message =
                        format!("not run: input node `{}` failed", graph.nodes[failed].id);
                    let r = failure(
                        &graph.nodes[j],
                        &slot.node,
                        NodeStatus::Cancelled,
                        message,
                        slot.key,
                    );
                    observer.node_finished(&r);
                    slot.report = Some(r);
                }
            }
        }
    }
}

/// Writes a node's `File` outputs under the output folder, atomically (temporary file + rename).
fn write_artifacts(
    node: &str,
    outputs: &Outputs,
    out_dir: &Path,
    sink: &Sink,
    files: &mut Vec<String>,
) {
    let all = outputs.values.values().flat_map(|v| {
        let one = v.as_any().downcast_ref::<Artifact>().into_iter();
        let many = v
            .as_any()
            .downcast_ref::<Artifacts>()
            .into_iter()
            .flat_map(|s| s.files.iter());
        one.chain(many)
    });
    for a in all {
        let path = out_dir.join(&a.path);
        // Re-running into the same folder is the common case while tuning; a file that already
        // holds these bytes is left alone (a read is cheaper than a write and a rename).
        let unchanged = std::fs::metadata(&path).is_ok_and(|m| m.len() == a.bytes.len() as u64)
            && std::fs::read(&path).is_ok_and(|b| b == a.bytes);
        if unchanged {
            files.push(path.display().to_string());
            continue;
        }
        let write = || -> std::io::Result<()> {
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)?;
            }
            let tmp = path.with_extension(format!("tmp{}", std::process::id()));
            std::fs::write(&tmp, &a.bytes)?;
            std::fs::rename(&tmp, &path)
        };
        match write() {
            Ok(()) => files.push(path.display().to_string()),
            Err(e) => sink.push(node, format!("cannot write {}: {e}", path.display())),
        }
    }
}

struct Task {
    idx: usize,
    node: Arc<dyn DynNode>,
    prepared: Option<Arc<Prepared>>,
    key: Option<Key>,
    inputs: Inputs,
    ctx: NodeContext,
    expected: Option<Outputs>,
    memory: Option<Arc<crate::cache::MemoryCache>>,
    disk: Option<crate::cache::DiskCache>,
    device: &'static str,
    tx: mpsc::Sender<Done>,
}

impl Task {
    fn run(self) {
        let t = Instant::now();
        let result = match &self.prepared {
            Some(p) => std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                self.node.run(&self.ctx, p, &self.inputs)
            }))
            .unwrap_or_else(|panic| {
                let msg = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                Err(NodeError::Failed(format!("internal error (panic): {msg}")))
            }),
            None => Err(NodeError::Failed("internal: no prepared parameters".into())),
        };
        let seconds = t.elapsed().as_secs_f64();
        let result = result.and_then(|out| check_outputs(self.node.as_ref(), out));
        let mut verified = false;
        let result = match (result, &self.expected) {
            (Ok(out), Some(expected)) => match compare(expected, &out) {
                Ok(()) => {
                    verified = true;
                    Ok(out)
                }
                Err(port) => Err(NodeError::Failed(format!(
                    "--verify-cache: the cached output `{port}` differs from the recomputed one; \
                     the kind `{}` (version {}) changed its results without a version bump",
                    self.node.spec().kind,
                    self.node.spec().version
                ))),
            },
            (r, _) => r,
        };
        // A cancelled run may still store a node that completed: the entry is whole.
        if let (Ok(out), Some(key)) = (&result, self.key) {
            if let Some(memory) = &self.memory {
                memory.insert(key, out.clone(), seconds);
            }
            if let Some(disk) = &self.disk {
                if !verified {
                    if let Err(e) = disk.put(&key, self.node.spec().kind, out, seconds) {
                        self.ctx.warn(format!("disk cache not written: {e}"));
                    }
                }
            }
        }
        let _ = self.tx.send(Done {
            idx: self.idx,
            result,
            seconds,
            device: self.device,
            verified,
        });
    }
}

/// Every declared output must be present with its declared type: downstream nodes rely on it.
fn check_outputs(node: &dyn DynNode, out: Outputs) -> Result<Outputs, NodeError> {
    for port in &node.spec().outputs {
        match out.get(port.name) {
            None => {
                return Err(NodeError::Failed(format!(
                    "internal: output `{}` was not produced",
                    port.name
                )))
            }
            Some(v) if !port.ty.accepts(v.type_name()) => {
                return Err(NodeError::Failed(format!(
                    "internal: output `{}` is a {}, declared {}",
                    port.name,
                    v.type_name(),
                    port.ty
                )))
            }
            Some(_) => {}
        }
    }
    Ok(out)
}

/// Compares two output sets by their encodings; returns the first differing port.
fn compare(a: &Outputs, b: &Outputs) -> Result<(), String> {
    let encode = |v: &crate::value::ValueRef| {
        let mut e = crate::codec::Encoder::default();
        v.encode(&mut e);
        e.bytes
    };
    for (port, va) in &a.values {
        match b.get(port) {
            Some(vb) if va.type_name() == vb.type_name() && encode(va) == encode(vb) => {}
            _ => return Err(port.clone()),
        }
    }
    match b.values.keys().find(|k| !a.values.contains_key(*k)) {
        Some(k) => Err(k.clone()),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use crate::engine::{Engine, EngineConfig, RunOptions, SilentObserver};
    use crate::node::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
    use crate::registry::Registry;
    use crate::report::NodeStatus;
    use crate::value::Scalar;
    use mesoflow_graph::{check, DevicePreference, GraphFile};
    use schemars::JsonSchema;
    use serde::{Deserialize, Serialize};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    use std::time::{Duration, Instant};

    #[derive(Default, Serialize, Deserialize, JsonSchema)]
    #[serde(default)]
    struct NoParams {}

    /// Outputs how many times it has run: a kind whose results change without a version bump.
    struct Drifting(Arc<AtomicUsize>);
    impl Node for Drifting {
        type Params = NoParams;
        fn spec(&self) -> NodeSpec {
            NodeSpec {
                kind: "test.drifting",
                version: 1,
                doc: "",
                device: DevicePreference::Cpu,
                inputs: vec![],
                outputs: vec![Port::output("y", "Scalar", "")],
                disk_cache: true,
            }
        }
        fn run(&self, _: &NodeContext, _: &NoParams, _: &Inputs) -> Result<Outputs, NodeError> {
            Ok(Outputs::new().with("y", Scalar(self.0.fetch_add(1, Ordering::SeqCst) as f64)))
        }
    }

    /// Waits (up to 10 s) until `expected` instances are inside `run` at once; reports whether
    /// they met. Run one at a time, they never meet.
    struct Rendezvous(Arc<AtomicUsize>, usize);
    impl Node for Rendezvous {
        type Params = NoParams;
        fn spec(&self) -> NodeSpec {
            NodeSpec {
                kind: "test.rendezvous",
                version: 1,
                doc: "",
                device: DevicePreference::Cpu,
                inputs: vec![],
                outputs: vec![Port::output("met", "Scalar", "")],
                disk_cache: false,
            }
        }
        fn run(&self, _: &NodeContext, _: &NoParams, _: &Inputs) -> Result<Outputs, NodeError> {
            self.0.fetch_add(1, Ordering::SeqCst);
            let start = Instant::now();
            while self.0.load(Ordering::SeqCst) < self.1
                && start.elapsed() < Duration::from_secs(10)
            {
                std::thread::sleep(Duration::from_millis(1));
            }
            let met = self.0.load(Ordering::SeqCst) >= self.1;
            Ok(Outputs::new().with("met", Scalar(if met { 1.0 } else { 0.0 })))
        }
    }

    struct Panics;
    impl Node for Panics {
        type Params = NoParams;
        fn spec(&self) -> NodeSpec {
            NodeSpec {
                kind: "test.panics",
                version: 1,
                doc: "",
                device: DevicePreference::Cpu,
                inputs: vec![Port::optional("x", "Scalar", "")],
                outputs: vec![Port::output("y", "Scalar", "")],
                disk_cache: false,
            }
        }
        fn run(&self, _: &NodeContext, _: &NoParams, _: &Inputs) -> Result<Outputs, NodeError> {
            panic!("index out of bounds")
        }
    }

    fn run(
        engine: &Engine,
        text: &str,
        verify: bool,
        dir: &std::path::Path,
    ) -> crate::report::RunReport {
        let file = GraphFile::parse(text).unwrap();
        let graph = check("t.json", &file, engine.registry()).unwrap();
        let mut opts = RunOptions::new("t.json", dir.into(), dir.join("out"));
        opts.verify_cache = verify;
        engine.run(&graph, &opts, Arc::new(SilentObserver)).unwrap()
    }

    #[test]
    fn verify_cache_catches_a_kind_changed_without_a_version_bump() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = Registry::new();
        r.register(Drifting(Arc::new(AtomicUsize::new(0))));
        let config = || EngineConfig {
            memory_budget: 1 << 20,
            disk: Some(crate::cache::DiskCache::new(dir.path().join("c"))),
        };
        let g = r#"{"mesoflow": 1, "nodes": {"d": {"kind": "test.drifting"}}}"#;
        let first = run(&Engine::new(r.clone(), config()), g, false, dir.path());
        assert_eq!(first.nodes[0].status, NodeStatus::Computed);
        let plain = run(&Engine::new(r.clone(), config()), g, false, dir.path());
        assert_eq!(
            plain.nodes[0].status,
            NodeStatus::Disk,
            "without verification the stale hit is used"
        );
        let verified = run(&Engine::new(r, config()), g, true, dir.path());
        assert!(!verified.ok);
        assert_eq!(verified.nodes[0].status, NodeStatus::Failed);
        let err = verified.nodes[0].error.as_deref().unwrap();
        assert!(
            err.contains("node `d`") && err.contains("without a version bump"),
            "{err}"
        );
    }

    #[test]
    fn independent_nodes_run_at_the_same_time() {
        if rayon::current_num_threads() < 2 {
            return; // one worker cannot overlap anything; the CLI tests cover RAYON_NUM_THREADS=1
        }
        let dir = tempfile::tempdir().unwrap();
        let mut r = Registry::new();
        r.register(Rendezvous(Arc::new(AtomicUsize::new(0)), 2));
        let engine = Engine::new(
            r,
            EngineConfig {
                memory_budget: 1 << 20,
                disk: None,
            },
        );
        let rep = run(
            &engine,
            r#"{"mesoflow": 1, "nodes": {"a": {"kind": "test.rendezvous"}, "b": {"kind": "test.rendezvous"}}}"#,
            false,
            dir.path(),
        );
        assert!(rep.ok);
        assert!(
            rep.nodes.iter().all(|n| n.metrics["met"] == 1.0),
            "{:?}",
            rep.nodes
        );
    }

    #[test]
    fn memory_cache_serves_a_second_run_and_a_panic_is_a_node_failure() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = Registry::new();
        r.register(Drifting(Arc::new(AtomicUsize::new(0))));
        r.register(Panics);
        let engine = Engine::new(
            r,
            EngineConfig {
                memory_budget: 1 << 20,
                disk: None,
            },
        );
        let g = r#"{"mesoflow": 1, "nodes": {"d": {"kind": "test.drifting"}, "p": {"kind": "test.panics", "inputs": {"x": "d.y"}}}}"#;
        let first = run(&engine, g, false, dir.path());
        assert!(!first.ok);
        assert_eq!(first.nodes[0].status, NodeStatus::Computed);
        assert_eq!(first.nodes[1].status, NodeStatus::Failed);
        assert!(
            first.nodes[1].error.as_deref().unwrap().contains("panic"),
            "{:?}",
            first.nodes[1].error
        );
        let second = run(&engine, g, false, dir.path());
        assert_eq!(second.nodes[0].status, NodeStatus::Memory);
        assert_eq!(
            second.nodes[0].metrics["y"], 0.0,
            "the cached value, not a recomputation"
        );
    }
}
