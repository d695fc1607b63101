//! Demand-driven execution of one checked graph, one module per phase:
//!
//! 1. [`plan`]: the requested outputs (by default the sinks) and their ancestors.
//! 2. [`keying`]: parameter defaults, declared files hashed, Merkle keys.
//! 3. [`demand`]: cache lookups from the requested nodes upwards; a hit ends its branch.
//! 4. [`dispatch`]: the misses run as their inputs become ready (rayon lane, GPU lane, chosen in
//!    [`device`]); [`write`] puts their files under the output folder; [`verify`] holds
//!    `--verify-cache` hits to their recomputation.
//!
//! then the report is assembled here, with each computed node's reason ([`crate::explain`]).
//! [`dry_run`] repeats phases 1–3 without running anything (`mesoflow explain`).

mod demand;
mod device;
mod dispatch;
pub mod dry_run;
mod keying;
mod plan;
mod verify;
mod write;

use crate::cache::Record;
use crate::key::Key;
use crate::node::{DynNode, Outputs, Prepared, ProgressSink};
use crate::report::{NodeReport, NodeStatus, RunReport, Warning};
use crate::resources::Resources;
use crate::run::{RunObserver, RunOptions, RunOutcome};
use mesoflow_graph::{CheckedGraph, DevicePreference};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Collects warnings and forwards progress to the observer.
pub(crate) struct Sink {
    observer: Arc<dyn RunObserver>,
    warnings: Mutex<Vec<Warning>>,
}

impl Sink {
    pub(crate) fn push(&self, node: &str, message: String) {
        tracing::warn!(node, "{message}");
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(Warning {
                expected: false,
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
pub(crate) struct Slot {
    pub node: Arc<dyn DynNode>,
    pub prepared: Option<Arc<Prepared>>,
    pub key: Option<Key>,
    pub outputs: Option<Outputs>,
    pub report: Option<NodeReport>,
    /// A cached value to compare against (`--verify-cache`).
    pub expected: Option<(Outputs, NodeStatus)>,
    /// Where the node runs, chosen before its key (the path is part of it).
    pub device: Option<device::Choice>,
    /// What the key was made of, for the next run's reasons.
    pub record: Option<crate::explain::KeyRecord>,
}

impl Slot {
    fn new(node: Arc<dyn DynNode>) -> Slot {
        Slot {
            node,
            prepared: None,
            key: None,
            outputs: None,
            report: None,
            expected: None,
            device: None,
            record: None,
        }
    }
}

pub(crate) fn device_name(d: DevicePreference) -> &'static str {
    match d {
        DevicePreference::Cpu => "cpu",
        DevicePreference::Gpu => "gpu",
    }
}

/// Every scalar output, for the report.
pub(crate) fn metrics(outputs: &Outputs) -> BTreeMap<String, f64> {
    outputs
        .values
        .iter()
        .filter_map(|(name, v)| v.as_scalar().map(|x| (name.clone(), x)))
        .collect()
}

/// The report's `timings`: the compute wall time as `seconds`, then the kind's own.
pub(crate) fn timings_of(record: &Record) -> BTreeMap<String, f64> {
    let mut t = record.timings.clone();
    t.insert("seconds".into(), record.seconds);
    t
}

pub(crate) fn keys(
    shared: &Resources,
    graph: &CheckedGraph,
    opts: &RunOptions,
) -> BTreeMap<String, Result<Key, String>> {
    let plan = plan::Plan::new(graph, opts);
    let keyed = keying::key_all(shared, graph, &plan, opts);
    graph
        .nodes
        .iter()
        .zip(keyed.slots)
        .filter_map(|(cn, slot)| {
            let slot = slot?;
            let key = match (slot.key, slot.report) {
                (Some(k), _) => Ok(k),
                (None, Some(r)) => Err(r.error.unwrap_or_default()),
                (None, None) => Err("no key".into()),
            };
            Some((cn.id.clone(), key))
        })
        .collect()
}

pub(crate) fn execute(
    shared: &Resources,
    graph: &CheckedGraph,
    opts: &RunOptions,
    observer: Arc<dyn RunObserver>,
) -> RunOutcome {
    let t0 = Instant::now();
    let sink = Arc::new(Sink {
        observer: observer.clone(),
        warnings: Mutex::new(Vec::new()),
    });
    let plan = plan::Plan::new(graph, opts);
    let keying::Keyed {
        mut slots,
        mut read_files,
    } = keying::key_all(shared, graph, &plan, opts);
    let mut compute = demand::demand(shared, graph, &plan, &mut slots, opts, &sink);
    // A GPU node keyed from the probe remembered in the disk cache and about to be computed:
    // the live probe must agree first, or the graph is keyed again from the live device.
    let remembered = (0..slots.len()).find_map(|i| {
        let choice = slots[i].as_ref()?.device.as_ref()?;
        compute[i]
            .then(|| choice.remembered.clone().map(|f| (i, f)))
            .flatten()
    });
    if let Some((i, found)) = remembered {
        if !device::confirm(shared, opts, &found) {
            sink.push(
                &graph.nodes[i].id,
                format!(
                    "the GPU probe remembered in the cache ({found:?}) no longer holds: keyed \
                     again from the live one"
                ),
            );
            keying::Keyed { slots, read_files } = keying::key_all(shared, graph, &plan, opts);
            compute = demand::demand(shared, graph, &plan, &mut slots, opts, &sink);
        }
    }

    // Cache hits write their files now; a hit whose files cannot be written fails like a node.
    let mut files = Vec::new();
    for (i, cn) in graph.nodes.iter().enumerate() {
        let Some(slot) = slots[i].as_mut() else {
            continue;
        };
        if let Some(out) = &slot.outputs {
            match write::write_artifacts(out, &opts.out_dir) {
                Ok(paths) => files.extend(paths),
                Err(e) => {
                    slot.report = Some(failure(cn, &slot.node, NodeStatus::Failed, e, slot.key));
                    slot.outputs = None;
                    cancel_dependants(i, graph, &plan.upstream, &compute, &mut slots, &observer);
                    continue;
                }
            }
        }
        if let Some(r) = &slot.report {
            observer.node_finished(r);
        }
    }

    let executed = dispatch::run_all(
        shared, graph, &plan, &mut slots, &compute, opts, &sink, &observer, files,
    );

    let cancelled = opts
        .policy
        .cancel
        .load(std::sync::atomic::Ordering::Relaxed);
    explain_and_record(shared, graph, &mut slots, &compute, opts, &sink);
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
    let values = plan
        .requested
        .iter()
        .filter_map(|&i| {
            let out = slots[i].as_ref()?.outputs.clone()?;
            Some((graph.nodes[i].id.clone(), out))
        })
        .collect();
    let mut report = RunReport {
        mesoflow: 1,
        version: env!("CARGO_PKG_VERSION").into(),
        graph: opts.graph_name.clone(),
        adapter: executed.adapter,
        ok,
        seconds: t0.elapsed().as_secs_f64(),
        nodes,
        warnings,
        skipped,
        files: executed.files,
        cancelled,
        read: read_files.into_iter().collect(),
        earlier: Vec::new(),
    };
    report.mark_expected(&graph.expected_warnings);
    RunOutcome { report, values }
}

/// Gives each computed node its reason (what changed since the records of the last run into
/// this output folder) and records what every node that ran or was read had its key made of.
fn explain_and_record(
    shared: &Resources,
    graph: &CheckedGraph,
    slots: &mut [Option<Slot>],
    compute: &[bool],
    opts: &RunOptions,
    sink: &Sink,
) {
    let order: Vec<String> = graph.nodes.iter().map(|n| n.id.clone()).collect();
    let now: BTreeMap<String, crate::explain::KeyRecord> = graph
        .nodes
        .iter()
        .zip(slots.iter())
        .filter_map(|(cn, s)| Some((cn.id.clone(), s.as_ref()?.record.clone()?)))
        .collect();
    let prev = crate::explain::load(&opts.out_dir);
    let changes = crate::explain::changes(&order, &now, prev.as_ref());
    let mut done = BTreeMap::new();
    for ((cn, slot), &computing) in graph.nodes.iter().zip(slots.iter_mut()).zip(compute) {
        let Some(slot) = slot.as_mut() else { continue };
        let Some(r) = slot.report.as_mut() else {
            // Keyed but not needed (every value depending on it was cached): its key stands.
            // One that was to run and has no report was cancelled: its record stays as it was.
            if let (Some(rec), false) = (&slot.record, computing) {
                done.insert(cn.id.clone(), rec.clone());
            }
            continue;
        };
        if r.status == NodeStatus::Computed {
            let on_disk =
                shared.disk.is_some() && (slot.node.spec().disk_cache || opts.cache_everything);
            r.reason = Some(crate::explain::reason(
                opts.policy.use_cache,
                changes.get(&cn.id),
                on_disk,
            ));
        }
        if matches!(
            r.status,
            NodeStatus::Computed | NodeStatus::Memory | NodeStatus::Disk
        ) {
            if let Some(rec) = &slot.record {
                done.insert(cn.id.clone(), rec.clone());
            }
        }
    }
    if !done.is_empty() {
        if let Err(e) = crate::explain::save(&opts.out_dir, &done) {
            sink.push(
                "",
                format!(
                    "could not record the keys' ingredients in {} ({e}): the next run cannot say why a node re-ran",
                    opts.out_dir.join(crate::explain::RECORD_FILE).display()
                ),
            );
        }
    }
}

pub(crate) fn failure(
    cn: &mesoflow_graph::CheckedNode,
    node: &Arc<dyn DynNode>,
    status: NodeStatus,
    error: String,
    key: Option<Key>,
) -> NodeReport {
    NodeReport {
        reason: None,
        id: cn.id.clone(),
        kind: cn.kind.clone(),
        device: device_name(node.spec().device).into(),
        status,
        seconds: 0.0,
        bytes: 0,
        key: key.map(|k| k.hex()).unwrap_or_default(),
        metrics: BTreeMap::new(),
        timings: BTreeMap::new(),
        kind_version: node.spec().version,
        error: Some(format!("node `{}`: {error}", cn.id)),
        verified: false,
    }
}

/// Marks every not-yet-run descendant of `failed` as cancelled.
pub(crate) fn cancel_dependants(
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
