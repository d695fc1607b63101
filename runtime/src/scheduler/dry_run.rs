//! `explain` without running: the plan and the keys as a run would make them, each key looked up
//! in the caches without reading a value, and the demand walk of [`super::demand`] repeated on
//! those lookups, so what would run is what a run would run; each with the reason a run would
//! give it ([`crate::explain`]).

use super::plan::{writes_files, Plan};
use super::{keying, Slot};
use crate::resources::Resources;
use crate::run::RunOptions;
use mesoflow_graph::CheckedGraph;
use serde::Serialize;
use std::collections::BTreeMap;

/// What a run would do with one node the requested outputs need.
#[derive(Clone, Debug, Serialize)]
pub struct Explained {
    pub id: String,
    pub kind: String,
    /// `run`, `memory` or `disk` (read from that cache), `not needed` (every value depending
    /// on it is cached) or `error` (no key could be made).
    pub action: String,
    /// Why it would run (see `NodeReport::reason`), or the error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

pub(crate) fn dry_run(
    shared: &Resources,
    graph: &CheckedGraph,
    opts: &RunOptions,
) -> Vec<Explained> {
    let plan = Plan::new(graph, opts);
    let keyed = keying::key_all(shared, graph, &plan, opts);
    let slots: Vec<Option<Slot>> = keyed.slots;
    let n = graph.nodes.len();
    let cached = |i: usize| -> Option<&'static str> {
        let key = slots[i].as_ref()?.key?;
        if !opts.policy.use_cache || opts.policy.verify_cache {
            None
        } else if shared.memory.get(&key).is_some() {
            Some("memory")
        } else if shared.disk.as_ref().is_some_and(|d| d.contains(&key)) {
            Some("disk")
        } else {
            None
        }
    };
    let mut demanded = vec![false; n];
    for &i in &plan.requested {
        demanded[i] = true;
    }
    for (i, s) in slots.iter().enumerate() {
        if s.as_ref().is_some_and(|s| writes_files(s.node.signature())) {
            demanded[i] = true;
        }
    }
    let mut run = vec![false; n];
    let mut hit: Vec<Option<&'static str>> = vec![None; n];
    for i in (0..n).rev() {
        if !demanded[i] || slots[i].as_ref().and_then(|s| s.key).is_none() {
            continue;
        }
        hit[i] = cached(i);
        if hit[i].is_none() {
            run[i] = true;
            for &u in &plan.upstream[i] {
                demanded[u] = true;
            }
        }
    }
    let order: Vec<String> = graph.nodes.iter().map(|c| c.id.clone()).collect();
    let now: BTreeMap<String, crate::explain::KeyRecord> = graph
        .nodes
        .iter()
        .zip(&slots)
        .filter_map(|(cn, s)| Some((cn.id.clone(), s.as_ref()?.record.clone()?)))
        .collect();
    let prev = crate::explain::load(&opts.out_dir);
    let changes = crate::explain::changes(&order, &now, prev.as_ref());
    let mut out = Vec::new();
    for (i, cn) in graph.nodes.iter().enumerate() {
        let Some(slot) = slots[i].as_ref() else {
            continue;
        };
        let (action, reason) = if let Some(r) = &slot.report {
            ("error".to_string(), r.error.clone())
        } else if run[i] {
            let on_disk =
                shared.disk.is_some() && (slot.node.spec().disk_cache || opts.cache_everything);
            (
                "run".to_string(),
                Some(crate::explain::reason(
                    opts.policy.use_cache,
                    changes.get(&cn.id),
                    on_disk,
                )),
            )
        } else if let Some(h) = hit[i] {
            (h.to_string(), None)
        } else {
            ("not needed".to_string(), None)
        };
        out.push(Explained {
            id: cn.id.clone(),
            kind: cn.kind.clone(),
            action,
            reason,
        });
    }
    out
}
