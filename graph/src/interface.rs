//! What a graph file exposes when another graph uses it as a node (format version 2's
//! `interface`), and the names subgraphs are written with; `crate::subgraph` expands them.

use crate::error::GraphError;
use crate::port_ref::PortRef;
use serde_json::{Map, Value};
use std::collections::BTreeMap;

/// The kind of a node that is a graph file.
pub const KIND: &str = "graph";
/// Separates a subgraph's id from its nodes' ids in the expanded graph.
pub const SEP: char = '/';
/// How deep subgraphs may nest.
pub const MAX_DEPTH: usize = 32;

/// What a graph file exposes to a graph that uses it as a node.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Interface {
    /// Exposed input → the inner input ports (`node.port`) it feeds.
    pub inputs: BTreeMap<String, Vec<PortRef>>,
    /// Exposed output → the inner output (`node.port`).
    pub outputs: BTreeMap<String, PortRef>,
    /// Exposed parameter → (inner node, parameter path).
    pub params: BTreeMap<String, (String, String)>,
}

impl Interface {
    /// Reads an `interface` object; problems name the field (`interface.outputs.basis`).
    pub fn parse(v: &Value) -> Result<Interface, Vec<GraphError>> {
        let mut errors = Vec::new();
        let mut out = Interface::default();
        let Some(obj) = v.as_object() else {
            return Err(vec![problem(None, "interface", "must be an object")]);
        };
        let port = |field: &str, text: &Value, errors: &mut Vec<GraphError>| -> Option<PortRef> {
            let parsed = text.as_str().and_then(PortRef::parse);
            if parsed.is_none() {
                errors.push(problem(
                    None,
                    field,
                    &format!("expected \"node.port\", got {text}"),
                ));
            }
            parsed
        };
        for (key, value) in obj {
            let Some(map) = value.as_object() else {
                errors.push(problem(
                    None,
                    &format!("interface.{key}"),
                    "must be an object",
                ));
                continue;
            };
            for (name, target) in map {
                let field = format!("interface.{key}.{name}");
                match key.as_str() {
                    "inputs" => {
                        let list: Vec<&Value> = match target {
                            Value::Array(a) => a.iter().collect(),
                            one => vec![one],
                        };
                        let ports: Vec<PortRef> = list
                            .into_iter()
                            .filter_map(|t| port(&field, t, &mut errors))
                            .collect();
                        out.inputs.insert(name.clone(), ports);
                    }
                    "outputs" => {
                        if let Some(p) = port(&field, target, &mut errors) {
                            out.outputs.insert(name.clone(), p);
                        }
                    }
                    "params" => match target.as_str().and_then(|t| t.split_once('.')) {
                        Some((n, p)) if !n.is_empty() && !p.is_empty() => {
                            out.params.insert(name.clone(), (n.into(), p.into()));
                        }
                        _ => errors.push(problem(
                            None,
                            &field,
                            &format!("expected \"node.param\", got {target}"),
                        )),
                    },
                    other => errors.push(problem(
                        None,
                        &format!("interface.{other}"),
                        "unknown field: an interface has `inputs`, `outputs` and `params`",
                    )),
                }
            }
        }
        if errors.is_empty() {
            Ok(out)
        } else {
            Err(errors)
        }
    }

    /// As written in a file.
    pub fn to_value(&self) -> Value {
        let mut top = Map::new();
        let inputs: Map<String, Value> = self
            .inputs
            .iter()
            .map(|(k, v)| {
                let list: Vec<Value> = v.iter().map(|p| Value::String(p.to_string())).collect();
                let v = if list.len() == 1 {
                    list[0].clone()
                } else {
                    Value::Array(list)
                };
                (k.clone(), v)
            })
            .collect();
        let outputs: Map<String, Value> = self
            .outputs
            .iter()
            .map(|(k, v)| (k.clone(), Value::String(v.to_string())))
            .collect();
        let params: Map<String, Value> = self
            .params
            .iter()
            .map(|(k, (n, p))| (k.clone(), Value::String(format!("{n}.{p}"))))
            .collect();
        for (k, m) in [("inputs", inputs), ("outputs", outputs), ("params", params)] {
            if !m.is_empty() {
                top.insert(k.into(), Value::Object(m));
            }
        }
        Value::Object(top)
    }
}

pub(crate) fn problem(node: Option<&str>, field: &str, message: &str) -> GraphError {
    GraphError::Structure {
        node: node.map(String::from),
        field: Some(field.into()),
        message: match node {
            Some(n) => format!("{n}/{field}: {message}"),
            None => format!("{field}: {message}"),
        },
    }
}
