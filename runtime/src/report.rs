//! The run report, `<out-dir>/report.json`: the contract scripts and tests read (design brief).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NodeStatus {
    Computed,
    Memory,
    Disk,
    Failed,
    Cancelled,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct NodeReport {
    pub id: String,
    pub kind: String,
    pub device: String,
    pub status: NodeStatus,
    pub seconds: f64,
    pub bytes: u64,
    pub key: String,
    pub metrics: BTreeMap<String, f64>,
    /// The cost of the value: `seconds` (its compute wall time) and the kind's own timings
    /// (`gpu_ms`, `frame_ms`, …). For a cache hit, those measured when it was computed.
    /// Absent where nothing was measured; never cached as outputs.
    #[serde(skip_serializing_if = "BTreeMap::is_empty", default)]
    pub timings: BTreeMap<String, f64>,
    /// The kind's version (part of the key): which implementation produced the value.
    #[serde(default)]
    pub kind_version: u32,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub error: Option<String>,
    /// With `--verify-cache`: the cached value was recomputed and matched.
    #[serde(skip_serializing_if = "std::ops::Not::not", default)]
    pub verified: bool,
    /// Why a computed node ran (`crate::explain`): the first run, `--no-cache`, an evicted
    /// value, or what changed since the last run into the same output folder. Absent on cache
    /// hits and on nodes that did not run.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub reason: Option<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Warning {
    pub node: String,
    pub message: String,
    /// The graph expects it of the node (its file's `expected_warnings`, marked by the run):
    /// kept here, not printed.
    #[serde(skip_serializing_if = "std::ops::Not::not", default)]
    pub expected: bool,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunReport {
    pub mesoflow: u32,
    /// The mesoflow release that ran the graph.
    #[serde(default)]
    pub version: String,
    pub graph: String,
    /// The GPU adapter GPU nodes ran on, e.g. "llvmpipe (LLVM 15.0.6), Vulkan, software";
    /// absent when no node ran on a GPU.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub adapter: Option<String>,
    pub ok: bool,
    pub seconds: f64,
    /// Nodes that ran or were read from a cache, in topological order.
    pub nodes: Vec<NodeReport>,
    pub warnings: Vec<Warning>,
    /// Ancestors of the requested outputs that were not needed because every value depending on
    /// them came from a cache.
    #[serde(default)]
    pub skipped: Vec<String>,
    /// Files written under the output folder.
    #[serde(default)]
    pub files: Vec<String>,
    #[serde(default)]
    pub cancelled: bool,
    /// Absolute paths of the files that nodes declared they read (what `watch` watches).
    #[serde(default)]
    pub read: Vec<String>,
    /// After a run that asked for some outputs only (`--output`): the nodes of earlier runs
    /// into the same folder that this one did not need, as those runs reported them, so the
    /// folder's report stays whole ([`RunReport::keeping_earlier`]).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub earlier: Vec<NodeReport>,
}

impl RunReport {
    pub fn node(&self, id: &str) -> Option<&NodeReport> {
        self.nodes.iter().find(|n| n.id == id)
    }

    /// Marks the warnings a graph expects (per node id, parts of their messages) as expected.
    pub fn mark_expected(&mut self, expected: &std::collections::BTreeMap<String, Vec<String>>) {
        for w in &mut self.warnings {
            if let Some(parts) = expected.get(&w.node) {
                w.expected = parts.iter().any(|p| w.message.contains(p.as_str()));
            }
        }
    }

    /// This report with the nodes of `previous` (the folder's report before this run, of the
    /// same graph) that it does not hold kept in [`earlier`](Self::earlier): what a run of
    /// some outputs only writes, so it does not cut the folder's report down to them.
    pub fn keeping_earlier(mut self, previous: &RunReport) -> RunReport {
        if previous.graph != self.graph {
            return self;
        }
        let kept: Vec<NodeReport> = previous
            .nodes
            .iter()
            .chain(&previous.earlier)
            .filter(|n| self.node(&n.id).is_none())
            .cloned()
            .collect();
        let mut seen = std::collections::BTreeSet::new();
        self.earlier = kept
            .into_iter()
            .filter(|n| seen.insert(n.id.clone()))
            .collect();
        self
    }

    /// Writes `<out_dir>/report.json` whole or not at all (through [`crate::write_atomic`]),
    /// creating the folder; returns the file's path.
    pub fn write_into(&self, out_dir: &std::path::Path) -> std::io::Result<std::path::PathBuf> {
        let path = out_dir.join("report.json");
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        crate::write_atomic(&path, text + "\n")?;
        Ok(path)
    }
}
