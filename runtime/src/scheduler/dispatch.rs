//! Phase 4, **execute**: the nodes to compute run as soon as their inputs are ready, CPU nodes on
//! rayon, GPU nodes one at a time on the GPU lane thread. Results go to the caches, their files
//! are written, and a failure stops its dependants while independent nodes finish. Cancellation
//! stops dispatching; running nodes see the flag.

use super::plan::Plan;
use super::verify::{check_outputs, compare, mismatch};
use super::write::write_artifacts;
use super::{cancel_dependants, failure, metrics, timings_of, Sink, Slot};
use crate::cache::Record;
use crate::key::Key;
use crate::node::{DynNode, Inputs, NodeContext, NodeError, Outputs, Prepared};
use crate::report::{NodeReport, NodeStatus};
use crate::resources::Resources;
use crate::run::{RunObserver, RunOptions, NOT_IN_CACHE};
use mesoflow_graph::CheckedGraph;
use std::collections::BTreeSet;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Instant;

struct Done {
    idx: usize,
    result: Result<Outputs, NodeError>,
    record: Record,
    device: &'static str,
    verified: bool,
}

/// What a run wrote, and on which adapter its GPU nodes ran.
pub(crate) struct Executed {
    pub files: Vec<String>,
    pub adapter: Option<String>,
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn run_all(
    shared: &Resources,
    graph: &CheckedGraph,
    plan: &Plan,
    slots: &mut [Option<Slot>],
    compute: &[bool],
    opts: &RunOptions,
    sink: &Arc<Sink>,
    observer: &Arc<dyn RunObserver>,
    mut files: Vec<String>,
) -> Executed {
    let n = graph.nodes.len();
    let mut adapter = None;
    let mut waiting: Vec<usize> = (0..n)
        .map(|i| {
            if compute[i] {
                plan.upstream[i].iter().filter(|&&u| compute[u]).count()
            } else {
                0
            }
        })
        .collect();
    let mut ready: BTreeSet<usize> = (0..n).filter(|&i| compute[i] && waiting[i] == 0).collect();
    let (tx, rx) = mpsc::channel::<Done>();
    let gpu_lane = Arc::new(Mutex::new(()));
    // Joined before the run returns: a GPU thread still dropping its task (and with it a handle
    // on the device) after the run has reported would race the process's exit and the driver's
    // exit handlers (CI once saw `mesoflow run` die of a signal after a complete report, on
    // lavapipe).
    let mut gpu_threads = Vec::new();
    let mut running = 0usize;
    loop {
        while !opts.policy.cancel.load(Ordering::Relaxed) {
            let Some(i) = ready.pop_first() else { break };
            if slots[i].as_ref().is_none_or(|s| s.report.is_some()) {
                continue; // failed while preparing
            }
            let cn = &graph.nodes[i];
            if opts
                .compute_only
                .as_ref()
                .is_some_and(|only| !only.contains(&cn.id))
            {
                if let Some(slot) = slots[i].as_mut() {
                    let message = format!(
                        "{NOT_IN_CACHE} (this run computes only {})",
                        opts.compute_only
                            .as_ref()
                            .map(|o| o.iter().cloned().collect::<Vec<_>>().join(", "))
                            .filter(|t| !t.is_empty())
                            .unwrap_or_else(|| "nothing: every value must be cached".into())
                    );
                    let r = failure(cn, &slot.node, NodeStatus::Failed, message, slot.key);
                    observer.node_finished(&r);
                    slot.report = Some(r);
                }
                cancel_dependants(i, graph, &plan.upstream, compute, slots, observer);
                continue;
            }
            let mut inputs = Inputs::new();
            for e in &cn.inputs {
                let value = plan
                    .index
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
            // Chosen while keying (the path is part of the key).
            let choice = slot.device.take();
            if let Some(why) = choice.as_ref().and_then(|c| c.fallback.clone()) {
                sink.push(&cn.id, why);
            }
            let device = choice.as_ref().map_or("cpu", |c| c.path());
            // The device itself is created here, at the first GPU node that computes: a run
            // whose GPU nodes are all cached never loads a driver. The path came from this same
            // device or from a remembered probe confirmed before dispatch, so it is there.
            let gpu = (device == "gpu").then(|| shared.gpu.get().ok()).flatten();
            if let Some(g) = &gpu {
                adapter.get_or_insert_with(|| g.describe());
            }
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
                    cancel: opts.policy.cancel.clone(),
                    gpu,
                    sink: sink.clone(),
                    timings: Default::default(),
                    warnings: Default::default(),
                    confine: opts.policy.confine.clone(),
                    derived: opts.policy.use_cache.then(|| shared.disk.clone()).flatten(),
                },
                expected: slot.expected.as_ref().map(|(o, _)| o.clone()),
                memory: opts.policy.use_cache.then(|| shared.memory.clone()),
                disk: if opts.policy.use_cache
                    && (slot.node.spec().disk_cache || opts.cache_everything)
                {
                    shared.disk.clone()
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
                gpu_threads.push(std::thread::spawn(move || {
                    let _guard = lane.lock().unwrap_or_else(|e| e.into_inner());
                    task.run();
                }));
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
        // A file that cannot be written fails the node like an error inside it.
        let result = done.result.and_then(|outputs| {
            write_artifacts(&outputs, &opts.out_dir)
                .map(|paths| (outputs, paths))
                .map_err(NodeError::Failed)
        });
        let report = match result {
            Ok((outputs, paths)) => {
                files.extend(paths);
                let status = match (&slot.expected, done.verified) {
                    (Some((_, s)), true) => *s,
                    _ => NodeStatus::Computed,
                };
                let r = NodeReport {
                    reason: None,
                    id: cn.id.clone(),
                    kind: cn.kind.clone(),
                    device: done.device.into(),
                    status,
                    seconds: done.record.seconds,
                    bytes: outputs.byte_size() as u64,
                    key: key.map(|k| k.hex()).unwrap_or_default(),
                    metrics: metrics(&outputs),
                    timings: timings_of(&done.record),
                    kind_version: slot.node.spec().version,
                    error: None,
                    verified: done.verified,
                };
                slot.outputs = Some(outputs);
                for &j in &plan.downstream[i] {
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
                r.seconds = done.record.seconds;
                r.device = done.device.into();
                cancel_dependants(i, graph, &plan.upstream, compute, slots, observer);
                r
            }
        };
        observer.node_finished(&report);
        if let Some(slot) = slots[i].as_mut() {
            slot.report = Some(report);
        }
    }
    for t in gpu_threads {
        // A panic inside a node was caught and reported by `Task::run`; one in the thread's own
        // tear-down has nothing left to report.
        let _ = t.join();
    }
    Executed { files, adapter }
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
            Some(p) => crate::node_panic::catching(|| self.node.run(&self.ctx, p, &self.inputs))
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
        let record = Record {
            seconds: t.elapsed().as_secs_f64(),
            timings: self.ctx.timings(),
            warnings: self.ctx.warnings(),
        };
        let result = result.and_then(|out| check_outputs(self.node.as_ref(), out));
        let mut verified = false;
        let result = match (result, &self.expected) {
            (Ok(out), Some(expected)) => match compare(expected, &out) {
                Ok(()) => {
                    verified = true;
                    Ok(out)
                }
                Err(port) => Err(mismatch(self.node.as_ref(), &port)),
            },
            (r, _) => r,
        };
        // A cancelled run may still store a node that completed: the entry is whole.
        if let (Ok(out), Some(key)) = (&result, self.key) {
            if let Some(memory) = &self.memory {
                memory.insert(key, out.clone(), record.clone());
            }
            if let Some(disk) = &self.disk {
                if !verified {
                    if let Err(e) = disk.put(&key, self.node.spec().kind, out, &record) {
                        self.ctx.warn(format!("disk cache not written: {e}"));
                    }
                }
            }
        }
        let _ = self.tx.send(Done {
            idx: self.idx,
            result,
            record,
            device: self.device,
            verified,
        });
    }
}
