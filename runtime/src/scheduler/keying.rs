//! Phase 2, **key**: in topological order, apply parameter defaults, hash the files a node declares
//! it reads, and derive each node's Merkle key from its inputs' keys. A node whose key cannot be
//! made fails here; its dependants are cancelled.

use super::{failure, Slot};
use crate::explain::{FileRecord, InputRecord, KeyRecord};
use crate::key::{self, Key, KeyParts};
use crate::node::{DynNode, NodeError, Prepared};
use crate::report::NodeStatus;
use crate::resources::Resources;
use crate::run::RunOptions;
use mesoflow_graph::{CheckedNode, DevicePreference};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::Arc;

pub(crate) struct Keyed {
    pub slots: Vec<Option<Slot>>,
    /// Files nodes declared they read (what `watch` watches).
    pub read_files: BTreeSet<String>,
}

pub(crate) fn key_all(
    shared: &Resources,
    graph: &mesoflow_graph::CheckedGraph,
    plan: &super::plan::Plan,
    opts: &RunOptions,
) -> Keyed {
    let mut slots: Vec<Option<Slot>> = Vec::with_capacity(graph.nodes.len());
    let mut read_files = BTreeSet::new();
    for (i, cn) in graph.nodes.iter().enumerate() {
        if !plan.needed[i] {
            slots.push(None);
            continue;
        }
        let Some(node) = shared.registry.node(&cn.kind).cloned() else {
            slots.push(None);
            continue;
        };
        let mut slot = Slot::new(node);
        let failed_input = plan.upstream[i]
            .iter()
            .find(|&&u| slots[u].as_ref().is_none_or(|s| s.key.is_none()));
        let keyed = match failed_input {
            Some(&u) => Err((
                NodeStatus::Cancelled,
                format!("not run: input node `{}` failed", graph.nodes[u].id),
            )),
            None => super::device::choose(shared, slot.node.spec().device, opts)
                .map_err(|e| (NodeStatus::Failed, e))
                .and_then(|choice| {
                    let path =
                        (slot.node.spec().device == DevicePreference::Gpu).then(|| choice.path());
                    prepare_and_key(
                        &slot.node,
                        cn,
                        &slots,
                        &plan.index,
                        opts,
                        path,
                        &mut read_files,
                    )
                    .map(|(prepared, key, record)| (prepared, key, record, choice))
                    .map_err(|e| (NodeStatus::Failed, e.to_string()))
                }),
        };
        match keyed {
            Ok((prepared, key, record, choice)) => {
                slot.prepared = Some(Arc::new(prepared));
                slot.key = Some(key);
                slot.record = Some(record);
                slot.device = Some(choice);
            }
            Err((status, error)) => {
                slot.report = Some(failure(cn, &slot.node, status, error, None))
            }
        }
        slots.push(Some(slot));
    }
    Keyed { slots, read_files }
}

fn prepare_and_key(
    node: &Arc<dyn DynNode>,
    cn: &CheckedNode,
    slots: &[Option<Slot>],
    index: &BTreeMap<&str, usize>,
    opts: &RunOptions,
    device: Option<&str>,
    read_files: &mut BTreeSet<String>,
) -> Result<(Prepared, Key, KeyRecord), NodeError> {
    let (base, confine) = (opts.base_dir.as_path(), opts.policy.confine.as_ref());
    let prepared = node.prepare(&cn.params)?;
    let declared = node.files(&prepared, base)?;
    let mut files = Vec::new();
    let mut file_records = Vec::new();
    for path in declared.iter().cloned() {
        if !path.exists() {
            return Err(NodeError::file(
                &path,
                format!(
                    "no such file (a relative path resolves against the graph's folder, {})",
                    base.display()
                ),
            ));
        }
        crate::confine::admit(confine, &path).map_err(|m| NodeError::file(&path, m))?;
        let hash = key::hash_file(&path).map_err(|e| NodeError::file(&path, e))?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        files.push((name, hash));
        let shown = std::fs::canonicalize(&path).unwrap_or(path);
        file_records.push(FileRecord {
            path: shown.display().to_string(),
            hash: Key(hash).hex(),
        });
        read_files.insert(shown.display().to_string());
    }
    let mut inputs = Vec::new();
    let mut input_records = BTreeMap::new();
    for e in &cn.inputs {
        let k = index
            .get(e.from.node.as_str())
            .and_then(|&u| slots[u].as_ref())
            .and_then(|s| s.key)
            .ok_or_else(|| NodeError::input(&e.port, format!("`{}` has no key", e.from)))?;
        inputs.push((e.port.as_str(), k, e.from.port.as_str()));
        input_records.insert(
            e.port.clone(),
            InputRecord {
                from: e.from.to_string(),
                key: k.hex(),
            },
        );
    }
    let spec = node.spec();
    let params = paths_as_files(&prepared.canonical, base, &declared);
    let key = key::compute(&KeyParts {
        kind: spec.kind,
        version: spec.version,
        params: &params,
        inputs,
        files,
        device,
    });
    let record = KeyRecord {
        key: key.hex(),
        kind: spec.kind.into(),
        version: spec.version,
        params: prepared.canonical.clone(),
        inputs: input_records,
        files: file_records,
        device: device.map(String::from),
    };
    Ok((prepared, key, record))
}

/// A parameter that names a declared file enters the key as its place in the list of files
/// (`<file 0>`), not as written: the file's name and contents are in the key already, and a path
/// that is absolute on one machine and relative on another must not make their keys differ.
fn paths_as_files(
    v: &serde_json::Value,
    base: &Path,
    files: &[std::path::PathBuf],
) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::String(s) => match files.iter().position(|f| *f == base.join(s)) {
            Some(i) => Value::String(format!("<file {i}>")),
            None => v.clone(),
        },
        Value::Array(a) => Value::Array(a.iter().map(|x| paths_as_files(x, base, files)).collect()),
        Value::Object(o) => Value::Object(
            o.iter()
                .map(|(k, x)| (k.clone(), paths_as_files(x, base, files)))
                .collect(),
        ),
        other => other.clone(),
    }
}
