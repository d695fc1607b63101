//! Subgraphs: a graph file used as a node, `{"kind": "graph", "params": {"path": "f.json", "set":
//! {"pca.rank": 8}, "rank": 4}, "inputs": {"surface": "scan.height"}}`. The included file declares
//! what it exposes in its `interface` (format version 2): `inputs` (each a name for one or more
//! of its nodes' input ports, open or overridable), `outputs` (a name for one of its nodes'
//! outputs, read outside as `id.name`) and `params` (a name for one of its nodes' parameters).
//!
//! A graph is checked and run as if the subgraph were inlined: [`expand`] replaces each `graph`
//! node with the included file's nodes under the path `id/inner` (nested to any depth,
//! `a/b/inner`), its exposed inputs wired to what the outer graph gives them (a node inside
//! whose every consumer is replaced that way is dropped), its outputs' readers rewired to the
//! inner outputs. Ids do not enter cache keys, so an inner node has exactly the key it has when
//! the included file runs on its own, and shares its cache. A parameter inside is set from
//! outside through an exposed name (`--set pipeline.rank=4`) or explicitly by its path
//! (`--set pipeline/pca.rank=4`, kept in the graph node's `set`).

use crate::error::GraphError;
use crate::file::{GraphFile, NodeDecl};
use crate::interface::problem;
pub use crate::interface::{Interface, KIND, MAX_DEPTH, SEP};
use crate::port_ref::PortRef;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Whether `file` uses a graph file as a node.
pub fn uses_subgraphs(file: &GraphFile) -> bool {
    file.nodes.iter().any(|(_, d)| d.kind == KIND)
}

/// A subgraph read from its file, its `set` and exposed parameters applied, its own subgraphs
/// read in turn.
struct Loaded {
    file: GraphFile,
    interface: Interface,
    subs: BTreeMap<String, Loaded>,
}

/// The graph with every `graph` node replaced by its file's nodes (see the module's doc).
/// Every problem names its path through the nesting (`pipeline/inner/pca`).
pub fn expand(file: &GraphFile) -> Result<GraphFile, Vec<GraphError>> {
    if !uses_subgraphs(file) {
        return Ok(file.clone());
    }
    let (_, nodes, mut errors) = load_and_flatten(file);
    // A node written under a path (`p/a`, as a planned graph is) must not meet one inside `p`.
    let mut seen = BTreeSet::new();
    for (id, _) in &nodes {
        if !seen.insert(id.as_str()) {
            errors.push(GraphError::DuplicateId { node: id.clone() });
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    Ok(GraphFile {
        description: file.description.clone(),
        interface: file.interface.clone(),
        nodes,
        base: file.base.clone(),
        source: file.source.clone(),
        values: file.values.clone(),
        uses: file.uses.clone(),
        expected_warnings: file.expected_warnings.clone(),
    })
}

/// Every subgraph of `file` read, and the graph's nodes with them inlined; flattened even after
/// a problem, so that every one is reported at once.
fn load_and_flatten(file: &GraphFile) -> (Loaded, Vec<(String, NodeDecl)>, Vec<GraphError>) {
    let mut errors = Vec::new();
    // The files being expanded, outermost first: one met again includes itself.
    let mut stack: Vec<PathBuf> = file.source.iter().cloned().collect();
    let loaded = load_subs(
        file.clone(),
        Interface::default(),
        "",
        &mut stack,
        &mut errors,
    );
    let mut nodes = Vec::new();
    flatten(&loaded, "", &BTreeMap::new(), &mut nodes, &mut errors);
    (loaded, nodes, errors)
}

/// Reads every subgraph of `file` (at `prefix`), applying each graph node's `set` and exposed
/// parameters to its file before reading that file's own subgraphs.
fn load_subs(
    file: GraphFile,
    interface: Interface,
    prefix: &str,
    stack: &mut Vec<PathBuf>,
    errors: &mut Vec<GraphError>,
) -> Loaded {
    let mut subs = BTreeMap::new();
    for (id, decl) in &file.nodes {
        if decl.kind != KIND {
            continue;
        }
        let path_id = format!("{prefix}{id}");
        let Some(sub) = read_sub(&file, &path_id, decl, stack, errors) else {
            continue;
        };
        let (sub_file, sub_interface, canonical) = sub;
        if stack.len() >= MAX_DEPTH {
            errors.push(problem(
                Some(&path_id),
                "path",
                &format!("subgraphs nest deeper than {MAX_DEPTH} levels"),
            ));
            continue;
        }
        stack.push(canonical);
        let loaded = load_subs(
            sub_file,
            sub_interface,
            &format!("{path_id}{SEP}"),
            stack,
            errors,
        );
        stack.pop();
        subs.insert(id.clone(), loaded);
    }
    Loaded {
        file,
        interface,
        subs,
    }
}

/// The file of graph node `decl` (at `path_id`), parsed, with its `set` and exposed parameters
/// applied and its interface checked against its nodes.
fn read_sub(
    outer: &GraphFile,
    path_id: &str,
    decl: &NodeDecl,
    stack: &[PathBuf],
    errors: &mut Vec<GraphError>,
) -> Option<(GraphFile, Interface, PathBuf)> {
    let at = |field: &str, message: String| problem(Some(path_id), field, &message);
    let Some(rel) = decl.params.get("path").and_then(Value::as_str) else {
        errors.push(at(
            "path",
            "a `graph` node needs `path`, the graph file it runs".into(),
        ));
        return None;
    };
    let Some(base) = &outer.base else {
        errors.push(at(
            "path",
            "a graph given as text has no folder to find its subgraph in (give the graph's folder)"
                .into(),
        ));
        return None;
    };
    let path = base.join(rel);
    let canonical = match std::fs::canonicalize(&path) {
        Ok(c) => c,
        Err(e) => {
            errors.push(at(
                "path",
                format!(
                    "{}: {e} (a relative path resolves against {})",
                    rel,
                    base.display()
                ),
            ));
            return None;
        }
    };
    if stack.contains(&canonical) {
        let chain: Vec<String> = stack
            .iter()
            .chain([&canonical])
            .map(|p| {
                p.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .collect();
        errors.push(at(
            "path",
            format!("{rel} includes itself ({})", chain.join(" → ")),
        ));
        return None;
    }
    let text = match std::fs::read_to_string(&canonical) {
        Ok(t) => t,
        Err(e) => {
            errors.push(at("path", format!("{rel}: cannot read: {e}")));
            return None;
        }
    };
    let mut file = match GraphFile::parse(&text) {
        Ok(f) => f,
        Err(es) => {
            for e in es {
                errors.push(at("path", format!("{rel}: {e}")));
            }
            return None;
        }
    };
    file.base = canonical.parent().map(Path::to_path_buf);
    file.source = Some(canonical.clone());
    let interface = file.interface.clone().unwrap_or_default();
    let before = errors.len();
    check_interface(&file, &interface, path_id, rel, errors);
    if errors.len() > before {
        return None;
    }
    // Explicit settings of inner parameters: `set` {"node.param": value}.
    match decl.params.get("set") {
        None => {}
        Some(Value::Object(sets)) => {
            for (target, value) in sets {
                let Some((node, param)) = target.split_once('.') else {
                    errors.push(at("set", format!("`{target}`: expected \"node.param\"")));
                    continue;
                };
                let o = crate::edit::Override {
                    node: node.into(),
                    param: param.into(),
                    value: value.clone(),
                };
                if let Err(e) = file.apply(&o) {
                    errors.push(at("set", e.replacen("--set ", "", 1)));
                }
            }
        }
        Some(other) => errors.push(at(
            "set",
            format!("must be an object {{\"node.param\": value}}, got {other}"),
        )),
    }
    // Exposed parameters.
    for (name, value) in &decl.params {
        if name == "path" || name == "set" {
            continue;
        }
        match interface.params.get(name) {
            Some((node, param)) => {
                let o = crate::edit::Override {
                    node: node.clone(),
                    param: param.clone(),
                    value: value.clone(),
                };
                if let Err(e) = file.apply(&o) {
                    errors.push(at(name, e.replacen("--set ", "", 1)));
                }
            }
            None => {
                let names = interface.params.keys().map(String::as_str);
                let hint = crate::nearest(name, names)
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                let exposed: Vec<&str> = interface.params.keys().map(String::as_str).collect();
                errors.push(at(
                    name,
                    format!(
                        "{rel} exposes no parameter `{name}`{hint}; it exposes {}, and any inner one is set as `set: {{\"node.param\": value}}`",
                        if exposed.is_empty() { "none".to_string() } else { exposed.join(", ") }
                    ),
                ));
            }
        }
    }
    for port in decl.inputs.keys() {
        if !interface.inputs.contains_key(port) {
            let hint = crate::nearest(port, interface.inputs.keys().map(String::as_str))
                .map(|s| format!(" (did you mean `{s}`?)"))
                .unwrap_or_default();
            errors.push(at(port, format!("{rel} exposes no input `{port}`{hint}")));
        }
    }
    // A mistake in what is given (a parameter, an input) is reported; the file is still read,
    // so the outer graph's use of its outputs is checked too. A broken interface stopped above.
    Some((file, interface, canonical))
}

/// Every name an interface gives must point at a node of its file.
fn check_interface(
    file: &GraphFile,
    interface: &Interface,
    path_id: &str,
    rel: &str,
    errors: &mut Vec<GraphError>,
) {
    let has = |n: &str| file.node(n).is_some();
    let mut bad = |field: String, node: &str| {
        if !has(node) {
            errors.push(problem(
                Some(path_id),
                &field,
                &format!("{rel}'s interface names `{node}`, which is no node of it"),
            ));
        }
    };
    for (name, ports) in &interface.inputs {
        for p in ports {
            bad(format!("interface.inputs.{name}"), &p.node);
        }
    }
    for (name, p) in &interface.outputs {
        bad(format!("interface.outputs.{name}"), &p.node);
    }
    for (name, (n, _)) in &interface.params {
        bad(format!("interface.params.{name}"), n);
    }
}

/// The expanded reference of `r` ("node.port") read in `loaded` at `prefix`: through a graph
/// node's exposed output into its file, else the node under the prefix.
fn resolve(loaded: &Loaded, prefix: &str, r: &str, errors: &mut Vec<GraphError>) -> String {
    let Some(p) = PortRef::parse(r) else {
        return format!("{prefix}{r}");
    };
    match loaded.subs.get(&p.node) {
        None => format!("{prefix}{r}"),
        Some(sub) => match sub.interface.outputs.get(&p.port) {
            Some(inner) => resolve(
                sub,
                &format!("{prefix}{}{SEP}", p.node),
                &inner.to_string(),
                errors,
            ),
            None => {
                let names: Vec<&str> = sub.interface.outputs.keys().map(String::as_str).collect();
                let hint = crate::nearest(&p.port, names.iter().copied())
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                errors.push(problem(
                    Some(&format!("{prefix}{}", p.node)),
                    &p.port,
                    &format!(
                        "the subgraph exposes no output `{}`{hint}; it exposes {}",
                        p.port,
                        if names.is_empty() {
                            "none".into()
                        } else {
                            names.join(", ")
                        }
                    ),
                ));
                format!("{prefix}{r}")
            }
        },
    }
}

/// Appends `loaded`'s nodes under `prefix` to `out`; `injected` gives, by (node, input port) of
/// this level, the expanded reference an exposed input brings from outside.
fn flatten(
    loaded: &Loaded,
    prefix: &str,
    injected: &BTreeMap<(String, String), String>,
    out: &mut Vec<(String, NodeDecl)>,
    errors: &mut Vec<GraphError>,
) {
    let dropped = dropped(&loaded.file, injected);
    for (id, decl) in &loaded.file.nodes {
        if dropped.contains(id) {
            continue;
        }
        let mut inputs: BTreeMap<String, String> = BTreeMap::new();
        for (port, r) in &decl.inputs {
            let v = match injected.get(&(id.clone(), port.clone())) {
                Some(x) => x.clone(),
                None => resolve(loaded, prefix, r, errors),
            };
            inputs.insert(port.clone(), v);
        }
        for ((n, port), x) in injected {
            if n == id {
                inputs.entry(port.clone()).or_insert_with(|| x.clone());
            }
        }
        match loaded.subs.get(id) {
            Some(sub) => {
                let mut inner = BTreeMap::new();
                for (name, r) in &inputs {
                    for target in sub.interface.inputs.get(name).into_iter().flatten() {
                        inner.insert((target.node.clone(), target.port.clone()), r.clone());
                    }
                }
                flatten(sub, &format!("{prefix}{id}{SEP}"), &inner, out, errors);
            }
            None => out.push((
                format!("{prefix}{id}"),
                NodeDecl {
                    kind: decl.kind.clone(),
                    params: decl.params.clone(),
                    inputs,
                },
            )),
        }
    }
}

/// Nodes of `file` that fed only inputs now given from outside: each had consumers, and every
/// one is replaced or itself dropped. A node that fed nothing (a sink: a writer, a measure)
/// stays.
fn dropped(file: &GraphFile, injected: &BTreeMap<(String, String), String>) -> BTreeSet<String> {
    let mut gone = BTreeSet::new();
    if injected.is_empty() {
        return gone;
    }
    loop {
        let mut changed = false;
        for (id, _) in &file.nodes {
            if gone.contains(id) {
                continue;
            }
            let consumers: Vec<(&String, &String)> = file
                .nodes
                .iter()
                .flat_map(|(n, d)| d.inputs.iter().map(move |(port, r)| (n, port, r)))
                .filter(|(_, _, r)| r.split('.').next() == Some(id.as_str()))
                .map(|(n, port, _)| (n, port))
                .collect();
            if !consumers.is_empty()
                && consumers.iter().all(|(n, port)| {
                    gone.contains(*n) || injected.contains_key(&((*n).clone(), (*port).clone()))
                })
            {
                gone.insert(id.clone());
                changed = true;
            }
        }
        if !changed {
            return gone;
        }
    }
}

/// What a front end shows of one graph node: its exposed inputs and parameters, its exposed
/// outputs with the expanded output each reads, and the expanded ids of the nodes inside it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Face {
    pub inputs: Vec<String>,
    pub params: Vec<String>,
    /// (exposed name, expanded `node.port`).
    pub outputs: Vec<(String, String)>,
    pub inner: Vec<String>,
    /// Each node inside, by expanded id, as expanded: its kind (what its outputs' types follow
    /// from), parameters and inputs (inner ones by expanded id), for front ends that open the
    /// box onto them.
    pub decls: BTreeMap<String, NodeDecl>,
}

/// The [`Face`] of every graph node of `file` (top level), as far as its files can be read;
/// problems are left to [`expand`], which reports them.
pub fn faces(file: &GraphFile) -> BTreeMap<String, Face> {
    let mut out = BTreeMap::new();
    if !uses_subgraphs(file) {
        return out;
    }
    let (loaded, nodes, _) = load_and_flatten(file);
    for (id, sub) in &loaded.subs {
        let prefix = format!("{id}{SEP}");
        let outputs = sub
            .interface
            .outputs
            .iter()
            .map(|(name, r)| {
                (
                    name.clone(),
                    resolve(sub, &prefix, &r.to_string(), &mut Vec::new()),
                )
            })
            .collect();
        let inside: Vec<&(String, NodeDecl)> = nodes
            .iter()
            .filter(|(n, _)| n.starts_with(&prefix))
            .collect();
        out.insert(
            id.clone(),
            Face {
                inputs: sub.interface.inputs.keys().cloned().collect(),
                params: sub.interface.params.keys().cloned().collect(),
                outputs,
                inner: inside.iter().map(|(n, _)| n.clone()).collect(),
                decls: inside.iter().map(|(n, d)| (n.clone(), d.clone())).collect(),
            },
        );
    }
    out
}

/// `id.name`, where `id` is a graph node and `name` one of its exposed outputs, as the inner
/// output it names (`p.y` is `p/b.y`); any other reference as given.
pub fn through(file: &GraphFile, r: PortRef) -> PortRef {
    through_all(file, vec![r]).remove(0)
}

/// [`through`] for several references, the subgraph files read once for all of them.
pub fn through_all(file: &GraphFile, refs: Vec<PortRef>) -> Vec<PortRef> {
    if refs.is_empty() {
        return refs;
    }
    let faces = faces(file);
    refs.into_iter()
        .map(|r| {
            faces
                .get(&r.node)
                .and_then(|f| f.outputs.iter().find(|(name, _)| *name == r.port))
                .and_then(|(_, inner)| PortRef::parse(inner))
                .unwrap_or(r)
        })
        .collect()
}
