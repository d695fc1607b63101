//! Phase 1, **plan**: the graph's edges as indices, the requested nodes (by default the sinks) and
//! every ancestor they need.

use crate::run::RunOptions;
use crate::value::{Artifact, Artifacts};
use mesoflow_graph::CheckedGraph;
use std::collections::{BTreeMap, BTreeSet};

pub(crate) struct Plan<'g> {
    pub index: BTreeMap<&'g str, usize>,
    pub upstream: Vec<Vec<usize>>,
    pub downstream: Vec<Vec<usize>>,
    pub requested: BTreeSet<usize>,
    /// The requested nodes and their ancestors.
    pub needed: Vec<bool>,
}

impl<'g> Plan<'g> {
    pub fn new(graph: &'g CheckedGraph, opts: &RunOptions) -> Plan<'g> {
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
        // Topological order: every node comes after its inputs, so one backward pass suffices.
        for i in (0..n).rev() {
            if needed[i] {
                for &u in &upstream[i] {
                    needed[u] = true;
                }
            }
        }
        Plan {
            index,
            upstream,
            downstream,
            requested,
            needed,
        }
    }
}

/// Whether a kind writes files: one of its outputs is a `File` or `Files`. Such a node's files are
/// part of what a run produces, so it is demanded whenever it is needed, even when the nodes it
/// feeds were cache hits.
pub(crate) fn writes_files(sig: &mesoflow_graph::KindSignature) -> bool {
    sig.outputs
        .iter()
        .any(|o| o.ty == Artifact::TYPE || o.ty == Artifacts::TYPE)
}
