//! Why a node ran: every run records what each node's key was made of (a [`KeyRecord`]: kind,
//! version, parameters, inputs' keys, files' hashes, device) in its output folder
//! ([`RECORD_FILE`]), and the next run into that folder compares its own records with them. A
//! computed node's `reason` in the report names the difference: the first run, `--no-cache`,
//! an evicted value, a parameter (from what to what), an input (and the upstream node whose own
//! change reached it), a file it reads, its kind's version. Only the key's ingredients are
//! recorded (parameters and hashes), never values, so nothing is stored twice.

use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// The records' file in the output folder.
pub const RECORD_FILE: &str = ".mesoflow-keys.json";

/// One input of a node: where it comes from and the key it had.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputRecord {
    /// `node.port` upstream.
    pub from: String,
    pub key: String,
}

/// One file a node reads: its path as resolved and the hash of its contents.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileRecord {
    pub path: String,
    pub hash: String,
}

/// What one node's key was made of.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyRecord {
    pub key: String,
    pub kind: String,
    pub version: u32,
    /// The parameters as the node took them (defaults applied).
    pub params: Value,
    /// By input port.
    pub inputs: BTreeMap<String, InputRecord>,
    pub files: Vec<FileRecord>,
    /// `cpu` or `gpu` for a GPU-capable kind.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
}

#[derive(Serialize, Deserialize)]
struct RecordFile {
    mesoflow: u32,
    nodes: BTreeMap<String, KeyRecord>,
}

/// The records of the last runs into `out_dir`, by node id; `None` when there are none (or
/// they cannot be read, which is the same as none: the reason then says "first run").
pub fn load(out_dir: &Path) -> Option<BTreeMap<String, KeyRecord>> {
    let text = std::fs::read_to_string(out_dir.join(RECORD_FILE)).ok()?;
    serde_json::from_str::<RecordFile>(&text)
        .ok()
        .map(|f| f.nodes)
}

/// Writes `records` over those of earlier runs (a node this run did not key keeps its record).
pub fn save(out_dir: &Path, records: &BTreeMap<String, KeyRecord>) -> std::io::Result<()> {
    let mut nodes = load(out_dir).unwrap_or_default();
    nodes.extend(records.iter().map(|(k, v)| (k.clone(), v.clone())));
    let text = serde_json::to_string_pretty(&RecordFile { mesoflow: 1, nodes })
        .map_err(std::io::Error::other)?;
    crate::write_atomic(&out_dir.join(RECORD_FILE), text + "\n")
}

/// A JSON value as a short text for a reason.
fn shown(v: Option<&Value>) -> String {
    match v {
        None => "unset".into(),
        Some(v) => {
            let t = v.to_string();
            if t.chars().count() > 40 {
                format!("{}…", t.chars().take(39).collect::<String>())
            } else {
                t
            }
        }
    }
}

fn file_name(path: &str) -> &str {
    Path::new(path)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or(path)
}

/// The differences in a node's own ingredients (not its inputs): version, parameters, files,
/// device; empty when none.
///
/// A changed parameter is shown at the leaves that changed (`camera.eye[1] 1.5 → 1.6`), not
/// as the whole object cut off before the part that differs.
pub fn own_changes(prev: &KeyRecord, now: &KeyRecord) -> Vec<String> {
    let mut out = Vec::new();
    if prev.kind != now.kind {
        out.push(format!("kind {} → {}", prev.kind, now.kind));
    } else if prev.version != now.version {
        out.push(format!(
            "{} version {} → {}",
            now.kind, prev.version, now.version
        ));
    }
    let empty = serde_json::Map::new();
    let (p, n) = (
        prev.params.as_object().unwrap_or(&empty),
        now.params.as_object().unwrap_or(&empty),
    );
    let mut names: Vec<&String> = p.keys().chain(n.keys()).collect();
    names.sort();
    names.dedup();
    for name in names {
        let mut leaves = Vec::new();
        changed_leaves(name.clone(), p.get(name), n.get(name), &mut leaves);
        let more = leaves.len().saturating_sub(MAX_LEAVES);
        for (path, a, b) in leaves.into_iter().take(MAX_LEAVES) {
            out.push(format!("parameter `{path}` {} → {}", shown(a), shown(b)));
        }
        if more > 0 {
            out.push(format!("and {more} more values of parameter `{name}`"));
        }
    }
    if prev.files.len() != now.files.len() {
        out.push(format!(
            "reads {} files, was {}",
            now.files.len(),
            prev.files.len()
        ));
    } else {
        for (a, b) in prev.files.iter().zip(&now.files) {
            if a.path != b.path {
                out.push(format!(
                    "reads `{}` instead of `{}`",
                    file_name(&b.path),
                    file_name(&a.path)
                ));
            } else if a.hash != b.hash {
                out.push(format!("file `{}` changed", b.path));
            }
        }
    }
    if prev.device != now.device {
        out.push(format!(
            "device {} → {}",
            prev.device.as_deref().unwrap_or("cpu"),
            now.device.as_deref().unwrap_or("cpu")
        ));
    }
    out
}

/// Why each node's key differs from its record, in the graph's topological `order`: for a node
/// whose own ingredients changed, those changes; for one that changed only through an input,
/// that input and the upstream node whose own change reached it. Nodes whose key is unchanged
/// have no entry; a node without an earlier record gets "first run".
pub fn changes(
    order: &[String],
    now: &BTreeMap<String, KeyRecord>,
    prev: Option<&BTreeMap<String, KeyRecord>>,
) -> BTreeMap<String, String> {
    // Per node: its reason, and the origin an input change points back to.
    let mut reason: BTreeMap<String, String> = BTreeMap::new();
    let mut origin: BTreeMap<String, String> = BTreeMap::new();
    for id in order {
        let Some(n) = now.get(id) else { continue };
        let Some(p) = prev.and_then(|p| p.get(id)) else {
            reason.insert(
                id.clone(),
                "first run: no earlier run of this node in this output folder".into(),
            );
            origin.insert(id.clone(), format!("`{id}` runs for the first time"));
            continue;
        };
        if p.key == n.key {
            continue;
        }
        let own = own_changes(p, n);
        let mut parts = own.clone();
        let mut first_origin = (!own.is_empty()).then(|| format!("`{id}`: {}", own[0]));
        for (port, input) in &n.inputs {
            match p.inputs.get(port) {
                Some(was) if was.key == input.key => {}
                Some(was) if was.from != input.from => {
                    parts.push(format!(
                        "input `{port}` now from `{}` (was `{}`)",
                        input.from, was.from
                    ));
                    first_origin.get_or_insert_with(|| format!("`{id}`: input `{port}` rewired"));
                }
                None => {
                    parts.push(format!("input `{port}` connected to `{}`", input.from));
                    first_origin.get_or_insert_with(|| format!("`{id}`: input `{port}` connected"));
                }
                Some(_) => {
                    let up = input.from.split('.').next().unwrap_or("");
                    let cause = origin
                        .get(up)
                        .cloned()
                        .unwrap_or_else(|| format!("`{up}`'s value changed"));
                    parts.push(format!(
                        "input `{port}` from `{}` changed ({cause})",
                        input.from
                    ));
                    first_origin.get_or_insert(cause);
                }
            }
        }
        for port in p.inputs.keys().filter(|k| !n.inputs.contains_key(*k)) {
            parts.push(format!("input `{port}` disconnected"));
        }
        if parts.is_empty() {
            // The key moved with nothing recorded to show for it: a new key scheme.
            parts.push("the key scheme changed".into());
        }
        origin.insert(
            id.clone(),
            first_origin.unwrap_or_else(|| format!("`{id}`: {}", parts[0])),
        );
        reason.insert(id.clone(), parts.join("; "));
    }
    reason
}

/// The reason a computed node with key `key` ran, given its change (if any) since the last
/// record: `--no-cache`, its change, or, with the same key as before, why no cache held it.
/// `on_disk`: whether a value of this kind would have been kept in the disk cache.
pub fn reason(use_cache: bool, change: Option<&String>, on_disk: bool) -> String {
    if !use_cache {
        return "--no-cache: no cache was read".into();
    }
    match change {
        Some(c) => c.clone(),
        None if !on_disk => {
            "the same key as before, not in this process's memory cache (its kind is kept in memory only, cheaper to recompute than to read)".into()
        }
        None => "evicted: the same key as before, but its value was in no cache (cleared, collected by `cache gc`, or another cache folder)".into(),
    }
}

/// The most changed leaves of one parameter shown; the rest are counted.
const MAX_LEAVES: usize = 4;

/// The leaves where `a` and `b` differ, under `path`: objects compared key by key, arrays of
/// the same length index by index, anything else as a whole.
fn changed_leaves<'a>(
    path: String,
    a: Option<&'a Value>,
    b: Option<&'a Value>,
    out: &mut Vec<(String, Option<&'a Value>, Option<&'a Value>)>,
) {
    let same = |x: Option<&Value>, y: Option<&Value>| {
        crate::key::canonical(x.unwrap_or(&Value::Null))
            == crate::key::canonical(y.unwrap_or(&Value::Null))
    };
    if same(a, b) {
        return;
    }
    match (a, b) {
        (Some(Value::Object(x)), Some(Value::Object(y))) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                changed_leaves(format!("{path}.{k}"), x.get(k), y.get(k), out);
            }
        }
        (Some(Value::Array(x)), Some(Value::Array(y))) if x.len() == y.len() => {
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                changed_leaves(format!("{path}[{i}]"), Some(u), Some(v), out);
            }
        }
        _ => out.push((path, a, b)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn rec(key: &str, params: Value, inputs: &[(&str, &str, &str)]) -> KeyRecord {
        KeyRecord {
            key: key.into(),
            kind: "k".into(),
            version: 1,
            params,
            inputs: inputs
                .iter()
                .map(|(p, f, k)| {
                    (
                        p.to_string(),
                        InputRecord {
                            from: f.to_string(),
                            key: k.to_string(),
                        },
                    )
                })
                .collect(),
            files: vec![],
            device: None,
        }
    }

    #[test]
    fn a_parameter_change_is_named_and_followed_downstream() {
        let order = vec!["a".to_string(), "b".to_string(), "c".to_string()];
        let prev: BTreeMap<_, _> = [
            ("a".into(), rec("1", json!({"size": 64}), &[])),
            ("b".into(), rec("2", json!({}), &[("x", "a.out", "1")])),
            ("c".into(), rec("3", json!({}), &[("y", "b.out", "2")])),
        ]
        .into();
        let now: BTreeMap<_, _> = [
            ("a".into(), rec("1b", json!({"size": 32}), &[])),
            ("b".into(), rec("2b", json!({}), &[("x", "a.out", "1b")])),
            ("c".into(), rec("3b", json!({}), &[("y", "b.out", "2b")])),
        ]
        .into();
        let c = changes(&order, &now, Some(&prev));
        assert_eq!(c["a"], "parameter `size` 64 → 32");
        assert!(
            c["c"].contains("input `y` from `b.out` changed"),
            "{}",
            c["c"]
        );
        // Two levels down, the cause is still the node whose own parameter changed.
        assert!(
            c["c"].contains("`a`: parameter `size` 64 → 32"),
            "{}",
            c["c"]
        );
        let first = changes(&order, &now, None);
        assert!(first["b"].starts_with("first run"));
        assert!(changes(&order, &now, Some(&now)).is_empty());
    }

    #[test]
    fn a_nested_change_is_shown_at_its_leaf() {
        let (a, b) = (
            serde_json::json!({ "eye": [0.0, 1.5, 2.7], "fov": 42 }),
            serde_json::json!({ "eye": [0.0, 1.6, 2.7], "fov": 42 }),
        );
        let mut leaves = Vec::new();
        super::changed_leaves("camera".into(), Some(&a), Some(&b), &mut leaves);
        let shown: Vec<String> = leaves
            .iter()
            .map(|(p, x, y)| format!("{p} {} → {}", super::shown(*x), super::shown(*y)))
            .collect();
        assert_eq!(shown, ["camera.eye[1] 1.5 → 1.6"]);
    }
}
