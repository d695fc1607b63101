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
/// raw BTF, and the model the graph gives the renderer on the way.
pub fn btf_chain(file: &GraphFile, render: &str, port: &str) -> Option<BtfChain> {
    let input = file.node(render)?.inputs.get(port)?.clone();
    let mut from = input.clone();
    let mut level = 0.0;
    let mut pca: Option<Option<(u32, u32, bool)>> = None;
    loop {
        let (id, _) = from.split_once('.')?;
        let n = file.node(id)?;
        match n.kind.as_str() {
            "btf.lod" => {
                level += n.params.get("level").and_then(Value::as_f64).unwrap_or(0.0);
                from = n.inputs.get("basis")?.clone();
            }
            "btf.pca" => {
                pca = Some(pca_rank(&n.params));
                from = n.inputs.get("btf")?.clone();
            }
            _ => {
                let given = match pca {
                    None => Some(GivenBtf::Raw),
                    Some(None) => None,
                    Some(Some((rank, chroma_rank, ycbcr))) => Some(GivenBtf::Pca {
                        from: input,
                        rank,
                        chroma_rank,
                        ycbcr,
                        level,
                    }),
                };
                return Some(BtfChain { raw: from, given });
            }
        }
    }
}

/// A `btf.pca`'s rank, chroma rank and colour space as its parameters declare them (its
/// defaults: rank 8, rgb, chroma max(1, rank / 4)); `None` where the rank follows from the data
/// (`max_rmse` or `energy`).
fn pca_rank(p: &Map<String, Value>) -> Option<(u32, u32, bool)> {
    let set = |k: &str| p.get(k).is_some_and(|v| !v.is_null());
    if !set("rank") && (set("max_rmse") || set("energy")) {
        return None;
    }
    let rank = p.get("rank").and_then(Value::as_u64).unwrap_or(8) as u32;
    let ycbcr = p.get("color").and_then(Value::as_str) == Some("ycbcr");
    let chroma = p
        .get("chroma_rank")
        .and_then(Value::as_u64)
        .map_or((rank / 4).max(1), |c| c as u32);
    Some((rank, chroma, ycbcr))
}
