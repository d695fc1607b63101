//! The graph file, format version 2 (see the design brief): parsing, with every structural problem
//! collected rather than the first one only, and migration of older versions. Version 2 adds the
//! `interface` a file exposes when another graph uses it as a node (`crate::subgraph`); a
//! version-1 file is a version-2 file without one.

use crate::error::GraphError;
use serde::de::{Deserializer, MapAccess, Visitor};
use serde::Deserialize;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::fmt;

pub use crate::port_ref::PortRef;

/// The newest format version this crate reads and writes.
pub const FORMAT_VERSION: u64 = 2;

/// One node declaration as written in the file.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeDecl {
    pub kind: String,
    pub params: Map<String, Value>,
    /// Input port name → "node.port".
    pub inputs: BTreeMap<String, String>,
}

/// A parsed graph file. Nodes keep the order of the file.
#[derive(Clone, Debug)]
pub struct GraphFile {
    pub description: Option<String>,
    /// What the file exposes to a graph that uses it as a node (version 2).
    pub interface: Option<crate::interface::Interface>,
    pub nodes: Vec<(String, NodeDecl)>,
    /// The folder its relative paths (input files, subgraphs) resolve against, where known.
    pub base: Option<std::path::PathBuf>,
    /// The file it was read from, canonical, where known (a subgraph that includes it again is
    /// refused).
    pub source: Option<std::path::PathBuf>,
    /// The file's shared values (`crate::values`), already resolved into the nodes' parameters.
    pub values: Map<String, Value>,
    /// Where each shared value was used, so that an override of it reaches every use.
    pub uses: Vec<crate::values::Use>,
    /// Per node, warnings the graph expects of it (parts of their messages): what the graph is
    /// about, which a run keeps in its report without printing (`expected_warnings`).
    pub expected_warnings: BTreeMap<String, Vec<String>>,
}

/// A JSON object that keeps duplicate keys, so that a duplicated node id can be reported instead
/// of silently replaced (serde_json's maps keep the last one).
struct Entries(Vec<(String, Value)>);

impl<'de> Deserialize<'de> for Entries {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Entries;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Entries, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, Value>()? {
                    out.push((k, v));
                }
                Ok(Entries(out))
            }
        }
        d.deserialize_map(V)
    }
}

#[derive(Deserialize)]
struct RawFile {
    nodes: Option<Entries>,
    #[serde(flatten)]
    rest: Map<String, Value>,
}

fn structure(node: Option<&str>, field: Option<&str>, message: String) -> GraphError {
    GraphError::Structure {
        node: node.map(str::to_string),
        field: field.map(str::to_string),
        message,
    }
}

/// Upgrades a file of an older format version to the current one, one step at a time. Version 1
/// is the first; a later version adds `migrate_vN_to_vN+1(Map) -> Map` here and a line below.
fn migrate(version: u64, rest: Map<String, Value>) -> Result<Map<String, Value>, GraphError> {
    match version {
        1 => migrate(2, migrate_v1_to_v2(rest)?),
        FORMAT_VERSION => Ok(rest),
        found => Err(GraphError::Version {
            found,
            supported: FORMAT_VERSION,
        }),
    }
}

/// Two files are the same graph when what they say is the same: where each was read from
/// (`base`, `source`) is not part of it.
impl PartialEq for GraphFile {
    fn eq(&self, other: &Self) -> bool {
        self.description == other.description
            && self.interface == other.interface
            && self.nodes == other.nodes
    }
}

/// Version 2 adds `interface`, which a version-1 file cannot have (it is refused there, so a
/// version-1 reader never meets a file it would half understand).
fn migrate_v1_to_v2(rest: Map<String, Value>) -> Result<Map<String, Value>, GraphError> {
    if rest.contains_key("interface") {
        return Err(structure(
            None,
            Some("interface"),
            "`interface` needs `\"mesoflow\": 2`".into(),
        ));
    }
    Ok(rest)
}

impl GraphFile {
    /// The same graph, located: relative paths and subgraphs resolve against `path`'s folder,
    /// and `path` is the file it came from.
    pub fn located(mut self, path: &std::path::Path) -> GraphFile {
        let canonical = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        self.base = canonical.parent().map(std::path::Path::to_path_buf);
        self.source = Some(canonical);
        self
    }

    /// The same graph with relative paths resolving against `dir` (a graph given as text).
    pub fn in_folder(mut self, dir: &std::path::Path) -> GraphFile {
        self.base = Some(dir.to_path_buf());
        self
    }

    /// Parses a graph file, collecting every structural error (node-level problems of several
    /// nodes are reported together).
    pub fn parse(text: &str) -> Result<GraphFile, Vec<GraphError>> {
        let raw: RawFile = serde_json::from_str(text).map_err(|e| {
            let err = if e.is_syntax() || e.is_eof() {
                GraphError::Syntax {
                    line: e.line(),
                    column: e.column(),
                    message: strip_position(&e.to_string()),
                }
            } else {
                structure(None, None, format!("the file must be a JSON object: {e}"))
            };
            vec![err]
        })?;
        let mut errors = Vec::new();
        let mut rest = raw.rest;
        let version = match rest.remove("mesoflow") {
            Some(Value::Number(n)) if n.as_u64().is_some() => n.as_u64().unwrap_or_default(),
            Some(other) => {
                errors.push(structure(
                    None,
                    Some("mesoflow"),
                    format!("`mesoflow` must be the format version number, got {other}"),
                ));
                FORMAT_VERSION
            }
            None => {
                errors.push(structure(
                    None,
                    Some("mesoflow"),
                    "missing `\"mesoflow\": 1` (the format version)".into(),
                ));
                FORMAT_VERSION
            }
        };
        let mut rest = match migrate(version, rest) {
            Ok(r) => r,
            Err(e) => return Err(vec![e]),
        };
        let description = match rest.remove("description") {
            None => None,
            Some(Value::String(s)) => Some(s),
            Some(other) => {
                errors.push(structure(
                    None,
                    Some("description"),
                    format!("`description` must be a string, got {}", describe(&other)),
                ));
                None
            }
        };
        let interface = match rest.remove("interface") {
            None => None,
            Some(v) => match crate::interface::Interface::parse(&v) {
                Ok(i) => Some(i),
                Err(mut es) => {
                    errors.append(&mut es);
                    None
                }
            },
        };
        let values = match rest.remove("values") {
            None => Map::new(),
            Some(v) => crate::values::parse(v).unwrap_or_else(|e| {
                errors.push(e);
                Map::new()
            }),
        };
        let expected_warnings = match rest.remove("expected_warnings") {
            None => BTreeMap::new(),
            Some(v) => parse_expected(v).unwrap_or_else(|e| {
                errors.push(e);
                BTreeMap::new()
            }),
        };
        for key in rest.keys() {
            let hint = crate::nearest(
                key,
                [
                    "mesoflow",
                    "description",
                    "interface",
                    "values",
                    "expected_warnings",
                    "nodes",
                ],
            )
            .map(|s| format!(" (did you mean `{s}`?)"))
            .unwrap_or_default();
            errors.push(structure(
                None,
                Some(key),
                format!("unknown top-level field `{key}`{hint}"),
            ));
        }
        let Some(Entries(entries)) = raw.nodes else {
            errors.push(structure(
                None,
                Some("nodes"),
                "missing `nodes` object".into(),
            ));
            return Err(errors);
        };
        let mut nodes = Vec::new();
        let mut uses = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for (id, value) in entries {
            if !seen.insert(id.clone()) {
                errors.push(GraphError::DuplicateId { node: id });
                continue;
            }
            if !valid_path_id(&id) {
                errors.push(GraphError::BadNodeId { node: id.clone() });
            }
            match parse_node(&id, value) {
                Ok(mut decl) => {
                    errors.extend(crate::values::resolve(
                        &values,
                        &id,
                        &mut decl.params,
                        &mut uses,
                    ));
                    nodes.push((id, decl));
                }
                Err(mut es) => errors.append(&mut es),
            }
        }
        for id in expected_warnings.keys() {
            if !nodes.iter().any(|(n, _)| n == id) {
                let hint = crate::nearest(id, nodes.iter().map(|(n, _)| n.as_str()))
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                errors.push(structure(
                    Some(id),
                    Some("expected_warnings"),
                    format!("`expected_warnings` names no node `{id}`{hint}"),
                ));
            }
        }
        if errors.is_empty() {
            Ok(GraphFile {
                description,
                interface,
                nodes,
                base: None,
                source: None,
                values,
                uses,
                expected_warnings,
            })
        } else {
            Err(errors)
        }
    }

    pub fn node(&self, id: &str) -> Option<&NodeDecl> {
        self.nodes.iter().find(|(n, _)| n == id).map(|(_, d)| d)
    }

    pub fn node_mut(&mut self, id: &str) -> Option<&mut NodeDecl> {
        self.nodes.iter_mut().find(|(n, _)| n == id).map(|(_, d)| d)
    }

    /// Serializes back (pretty-printed): version 2 with an interface, else version 1, which every
    /// earlier mesoflow reads.
    pub fn to_json(&self) -> String {
        let mut nodes = Map::new();
        for (id, d) in &self.nodes {
            let mut obj = Map::new();
            obj.insert("kind".into(), Value::String(d.kind.clone()));
            if !d.inputs.is_empty() {
                let inputs = d
                    .inputs
                    .iter()
                    .map(|(k, v)| (k.clone(), Value::String(v.clone())));
                obj.insert("inputs".into(), Value::Object(inputs.collect()));
            }
            if !d.params.is_empty() {
                obj.insert("params".into(), Value::Object(d.params.clone()));
            }
            nodes.insert(id.clone(), Value::Object(obj));
        }
        let mut top = Map::new();
        let version = if self.interface.is_some() { 2 } else { 1 };
        top.insert("mesoflow".into(), Value::from(version));
        if let Some(d) = &self.description {
            top.insert("description".into(), Value::String(d.clone()));
        }
        if let Some(i) = &self.interface {
            top.insert("interface".into(), i.to_value());
        }
        if !self.expected_warnings.is_empty() {
            let expected = self
                .expected_warnings
                .iter()
                .map(|(id, parts)| (id.clone(), Value::from(parts.clone())));
            top.insert(
                "expected_warnings".into(),
                Value::Object(expected.collect()),
            );
        }
        top.insert("nodes".into(), Value::Object(nodes));
        serde_json::to_string_pretty(&Value::Object(top)).unwrap_or_default()
    }
}

/// `expected_warnings`: an object of node id → array of strings.
fn parse_expected(v: Value) -> Result<BTreeMap<String, Vec<String>>, GraphError> {
    let bad = |what: String| structure(None, Some("expected_warnings"), what);
    let Value::Object(m) = v else {
        return Err(bad(format!(
            "`expected_warnings` must be an object of node id → [parts of messages], got {}",
            describe(&v)
        )));
    };
    let mut out = BTreeMap::new();
    for (id, parts) in m {
        let list = match parts {
            Value::Array(a) => a
                .into_iter()
                .map(|p| match p {
                    Value::String(s) if !s.trim().is_empty() => Ok(s),
                    other => Err(bad(format!(
                        "`expected_warnings.{id}`: each entry must be a non-empty string, got {}",
                        describe(&other)
                    ))),
                })
                .collect::<Result<Vec<String>, GraphError>>()?,
            other => {
                return Err(bad(format!(
                    "`expected_warnings.{id}` must be an array of strings, got {}",
                    describe(&other)
                )))
            }
        };
        out.insert(id, list);
    }
    Ok(out)
}

fn strip_position(message: &str) -> String {
    match message.rfind(" at line ") {
        Some(i) => message[..i].to_string(),
        None => message.to_string(),
    }
}

/// A node id as a graph file may write it: `[a-z][a-z0-9_]*`, or a path of them, `a/b`, the id
/// of node `b` inside the subgraph `a` (what a graph with subgraphs expands to, and a planned
/// graph of one is written with).
pub fn valid_path_id(id: &str) -> bool {
    id.split(crate::interface::SEP).all(valid_id)
}

/// `[a-z][a-z0-9_]*`
pub fn valid_id(id: &str) -> bool {
    let mut chars = id.chars();
    matches!(chars.next(), Some('a'..='z'))
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

/// A short description of a JSON value's type, for error messages.
pub fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("boolean {b}"),
        Value::Number(n) => format!("number {n}"),
        Value::String(s) => format!("string \"{s}\""),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

fn parse_node(id: &str, value: Value) -> Result<NodeDecl, Vec<GraphError>> {
    let Value::Object(mut obj) = value else {
        return Err(vec![structure(
            Some(id),
            None,
            format!(
                "node `{id}` must be an object with `kind`, got {}",
                describe(&value)
            ),
        )]);
    };
    let mut errors = Vec::new();
    let kind = match obj.remove("kind") {
        Some(Value::String(k)) => k,
        Some(other) => {
            errors.push(structure(
                Some(id),
                Some("kind"),
                format!(
                    "node `{id}`: `kind` must be a string, got {}",
                    describe(&other)
                ),
            ));
            String::new()
        }
        None => {
            errors.push(structure(
                Some(id),
                Some("kind"),
                format!("node `{id}`: missing `kind`"),
            ));
            String::new()
        }
    };
    let params = match obj.remove("params") {
        None => Map::new(),
        Some(Value::Object(m)) => m,
        Some(other) => {
            errors.push(structure(
                Some(id),
                Some("params"),
                format!(
                    "node `{id}`: `params` must be an object, got {}",
                    describe(&other)
                ),
            ));
            Map::new()
        }
    };
    let mut inputs = BTreeMap::new();
    match obj.remove("inputs") {
        None => {}
        Some(Value::Object(m)) => {
            for (port, v) in m {
                match v {
                    Value::String(s) => {
                        inputs.insert(port, s);
                    }
                    other => errors.push(structure(
                        Some(id),
                        Some(&port),
                        format!(
                            "node `{id}`: input `{port}` must be a string \"node.port\", got {}",
                            describe(&other)
                        ),
                    )),
                }
            }
        }
        Some(other) => errors.push(structure(
            Some(id),
            Some("inputs"),
            format!(
                "node `{id}`: `inputs` must be an object, got {}",
                describe(&other)
            ),
        )),
    }
    for key in obj.keys() {
        let hint = crate::nearest(key, ["kind", "params", "inputs"])
            .map(|s| format!(" (did you mean `{s}`?)"))
            .unwrap_or_default();
        errors.push(structure(
            Some(id),
            Some(key),
            format!("node `{id}`: unknown field `{key}`{hint}"),
        ));
    }
    if errors.is_empty() {
        Ok(NodeDecl {
            kind,
            params,
            inputs,
        })
    } else {
        Err(errors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn syntax_error_has_line_and_column() {
        let errs = GraphFile::parse("{\n  \"mesoflow\": 1,\n  \"nodes\": { ,}\n}").unwrap_err();
        match &errs[0] {
            GraphError::Syntax { line, column, .. } => {
                assert_eq!(*line, 3);
                assert_eq!(*column, 14);
            }
            e => panic!("expected a syntax error, got {e:?}"),
        }
    }

    #[test]
    fn duplicate_ids_are_reported_not_replaced() {
        let text = r#"{"mesoflow":1,"nodes":{"a":{"kind":"x"},"a":{"kind":"y"}}}"#;
        let errs = GraphFile::parse(text).unwrap_err();
        assert_eq!(errs, vec![GraphError::DuplicateId { node: "a".into() }]);
    }

    #[test]
    fn ids_follow_the_pattern() {
        assert!(valid_id("surface_2"));
        for bad in ["", "2a", "Surface", "a-b", "a.b", "_a"] {
            assert!(!valid_id(bad), "{bad}");
        }
        assert!(valid_path_id("weave/capture") && valid_path_id("a/b/c"));
        for bad in ["a/", "/a", "a//b", "a/B", "a/b.c"] {
            assert!(!valid_path_id(bad), "{bad}");
        }
    }

    #[test]
    fn version_1_migrates_and_an_interface_needs_version_2() {
        let v1 = GraphFile::parse(r#"{"mesoflow":1,"nodes":{"a":{"kind":"k"}}}"#).unwrap();
        assert!(v1.interface.is_none());
        assert!(v1.to_json().contains("\"mesoflow\": 1"));
        let text = r#"{"mesoflow":2,"interface":{"outputs":{"y":"a.y"},"params":{"s":"a.scale"},
            "inputs":{"x":["a.x","a.z"]}},"nodes":{"a":{"kind":"k"}}}"#;
        let v2 = GraphFile::parse(text).unwrap();
        let i = v2.interface.clone().unwrap();
        assert_eq!(i.inputs["x"].len(), 2);
        assert_eq!(i.params["s"], ("a".to_string(), "scale".to_string()));
        // Written back as version 2, the same graph.
        assert!(v2.to_json().contains("\"mesoflow\": 2"));
        assert_eq!(GraphFile::parse(&v2.to_json()).unwrap(), v2);
        let errs = GraphFile::parse(r#"{"mesoflow":1,"interface":{},"nodes":{}}"#).unwrap_err();
        assert!(
            errs[0].to_string().contains("needs `\"mesoflow\": 2`"),
            "{errs:?}"
        );
    }

    #[test]
    fn future_versions_are_refused() {
        let errs = GraphFile::parse(r#"{"mesoflow":7,"nodes":{}}"#).unwrap_err();
        assert_eq!(
            errs,
            vec![GraphError::Version {
                found: 7,
                supported: 2
            }]
        );
    }

    #[test]
    fn round_trips_through_json() {
        let text = r#"{"mesoflow":1,"description":"d","nodes":{"b":{"kind":"k","params":{"x":1.5}},
            "a":{"kind":"k2","inputs":{"i":"b.o"}}}}"#;
        let g = GraphFile::parse(text).unwrap();
        assert_eq!(g.nodes[0].0, "b", "file order is kept");
        assert_eq!(GraphFile::parse(&g.to_json()).unwrap(), g);
    }
}
