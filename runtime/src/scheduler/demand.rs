//! Phase 3, **demand**: from the requested nodes upwards, look each key up (memory, then disk). A
//! hit ends the walk on that branch: its ancestors are not needed and are reported as skipped,
//! except writers (nodes with `File` outputs), which are always demanded so that every run writes
//! every file. With `--verify-cache` a hit is still recomputed, so its inputs are demanded too.
//! A hit repeats the warnings its computation gave.

use super::plan::{writes_files, Plan};
use super::{metrics, Sink, Slot};
use crate::cache::Record;
use crate::key::Key;
use crate::node::Outputs;
use crate::report::{NodeReport, NodeStatus};
use crate::resources::Resources;
use crate::run::RunOptions;
use mesoflow_graph::CheckedGraph;
use std::time::Instant;

/// Marks the nodes to compute; fills the slots of cache hits with their outputs and reports.
pub(crate) fn demand(
    shared: &Resources,
    graph: &CheckedGraph,
    plan: &Plan,
    slots: &mut [Option<Slot>],
    opts: &RunOptions,
    sink: &Sink,
) -> Vec<bool> {
    let n = graph.nodes.len();
    let mut demanded = vec![false; n];
    for &i in &plan.requested {
        demanded[i] = true;
    }
    for (i, slot) in slots.iter().enumerate() {
        if let Some(slot) = slot {
            if writes_files(slot.node.signature()) {
                demanded[i] = true;
            }
        }
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
        let hit = if opts.policy.use_cache {
            lookup(shared, &key, slot.node.spec().kind, cn.id.as_str(), sink)
        } else {
            None
        };
        match hit {
            Some((outputs, status, seconds, record)) if !opts.policy.verify_cache => {
                // The warnings belong to the value: a cached render of a thin object is as thin.
                for w in &record.warnings {
                    sink.push(cn.id.as_str(), w.clone());
                }
                let spec = slot.node.spec();
                slot.report = Some(NodeReport {
                    reason: None,
                    id: cn.id.clone(),
                    kind: cn.kind.clone(),
                    // Every keyed node has its device chosen (the path is part of the key).
                    device: slot.device.as_ref().map_or("cpu", |c| c.path()).into(),
                    status,
                    seconds,
                    bytes: outputs.byte_size() as u64,
                    key: key.hex(),
                    metrics: metrics(&outputs),
                    timings: super::timings_of(&record),
                    kind_version: spec.version,
                    error: None,
                    verified: false,
                });
                slot.outputs = Some(outputs);
            }
            hit => {
                slot.expected = hit.map(|(o, s, _, _)| (o, s));
                compute[i] = true;
                for &u in &plan.upstream[i] {
                    demanded[u] = true;
                }
            }
        }
    }
    compute
}

/// A cached value: from memory, else from disk (then kept in memory too). A disk entry that cannot
/// be trusted is a warning, removed, and recomputed.
fn lookup(
    shared: &Resources,
    key: &Key,
    kind: &str,
    node: &str,
    sink: &Sink,
) -> Option<(Outputs, NodeStatus, f64, Record)> {
    if let Some((out, record)) = shared.memory.get(key) {
        return Some((out, NodeStatus::Memory, 0.0, record));
    }
    let disk = shared.disk.as_ref()?;
    let t = Instant::now();
    match disk.get(key, kind, &shared.registry) {
        Ok(Some((outputs, record))) => {
            shared.memory.insert(*key, outputs.clone(), record.clone());
            Some((outputs, NodeStatus::Disk, t.elapsed().as_secs_f64(), record))
        }
        Ok(None) => None,
        Err(e) => {
            sink.push(node, format!("{e}; recomputing"));
            disk.remove(key);
            None
        }
    }
}
