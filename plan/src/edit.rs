//! The graph edits that carry the decisions out: added or replaced nodes, the nodes a plan
//! disconnects pruned, and the chain a BTF reaches the renderer through.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{Map, Value};
use std::collections::{BTreeMap, BTreeSet};

pub(crate) fn upsert(
    out: &mut GraphFile,
    id: &str,
    kind: &str,
    params: Map<String, Value>,
    inputs: BTreeMap<String, String>,
) {
    let decl = mesoflow_graph::NodeDecl {
        kind: kind.into(),
        params,
        inputs,
    };
    match out.node_mut(id) {
        Some(n) => *n = decl,
        None => out.nodes.push((id.to_string(), decl)),
    }
}

/// Removes the nodes the plan disconnected: those that fed something in `before` and feed
/// nothing now, unless they write files (a writer is a result in itself). Repeats until stable.
pub(crate) fn prune(out: &mut GraphFile, before: &GraphFile, render: &str) {
    let fed = |f: &GraphFile| -> BTreeSet<String> {
        f.nodes
            .iter()
            .flat_map(|(_, d)| d.inputs.values())
            .filter_map(|s| s.split_once('.').map(|(n, _)| n.to_string()))
            .collect()
    };
    let had_consumers = fed(before);
    loop {
        let now = fed(out);
        let orphan: Vec<String> = out
            .nodes
            .iter()
            .filter(|(id, d)| {
                id != render
                    && !now.contains(id)
                    && (had_consumers.contains(id) || id.starts_with(PREFIX))
                    && !d.kind.ends_with(".write")
                    && !d.kind.starts_with("btf.write")
            })
            .map(|(id, _)| id.clone())
            .collect();
        if orphan.is_empty() {
            break;
        }
        out.nodes.retain(|(id, _)| !orphan.contains(id));
    }
}

/// Where the BTF of `render`'s `port` comes from: through `btf.lod` and `btf.pca` back to the
/// raw BTF.
pub fn btf_chain(file: &GraphFile, render: &str, port: &str) -> Option<BtfChain> {
    let mut from = file.node(render)?.inputs.get(port)?.clone();
    loop {
        let (id, _) = from.split_once('.')?;
        let n = file.node(id)?;
        match n.kind.as_str() {
            "btf.lod" => from = n.inputs.get("basis")?.clone(),
            "btf.pca" => from = n.inputs.get("btf")?.clone(),
            _ => return Some(BtfChain { raw: from }),
        }
    }
}
