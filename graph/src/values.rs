//! Shared values: a graph file's top-level `values` (a name → any JSON value), referred to from
//! any node's parameters as `{"$value": "name"}`, or `{"$value": "name", "field": …}` for the
//! value (an object) with those fields replaced. Written once, a camera, a light or a tiling
//! is the same in the model, its truth and its exports.
//!
//! References are resolved when the file is read, so validation, cache keys, `explain` and
//! every command see the values themselves. The file keeps where each value was used
//! ([`Use`]), so an override of the value (`--set values.camera.fov=30`) reaches every use.
//! A graph mesoflow writes (a plan, a sweep's points) writes each value where it is used.

use crate::error::GraphError;
use serde_json::{Map, Value};

/// The key of a reference.
pub const KEY: &str = "$value";

/// The node id an override names to change a shared value (`--set values.NAME=…`).
pub const OVERRIDE_NODE: &str = "values";

/// One step into a parameter: an object's key or an array's index.
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    Key(String),
    Index(usize),
}

/// Where a value was used: node `node`'s parameters at `path`, with the fields the reference
/// replaced.
#[derive(Clone, Debug, PartialEq)]
pub struct Use {
    pub node: String,
    pub path: Vec<Step>,
    pub name: String,
    pub fields: Map<String, Value>,
}

fn error(node: Option<&str>, field: &str, message: String) -> GraphError {
    let message = match node {
        Some(n) => format!("node `{n}`, parameter `{field}`: {message}"),
        None => message,
    };
    GraphError::Structure {
        node: node.map(str::to_string),
        field: Some(field.to_string()),
        message,
    }
}

/// The path as written in messages: `light.direction[1]`.
pub(crate) fn shown(path: &[Step]) -> String {
    let mut out = String::new();
    for s in path {
        match s {
            Step::Key(k) if out.is_empty() => out.push_str(k),
            Step::Key(k) => {
                out.push('.');
                out.push_str(k);
            }
            Step::Index(i) => out.push_str(&format!("[{i}]")),
        }
    }
    out
}

/// Checks the file's `values`: an object whose values hold no reference (a value is written
/// out, not built from another).
pub fn parse(v: Value) -> Result<Map<String, Value>, GraphError> {
    let Value::Object(map) = v else {
        return Err(error(
            None,
            "values",
            "`values` must be an object of named values".into(),
        ));
    };
    for (name, value) in &map {
        if holds_reference(value) {
            return Err(error(
                None,
                "values",
                format!("value `{name}` refers to another value: write it out"),
            ));
        }
    }
    Ok(map)
}

fn holds_reference(v: &Value) -> bool {
    match v {
        Value::Object(m) => m.contains_key(KEY) || m.values().any(holds_reference),
        Value::Array(a) => a.iter().any(holds_reference),
        _ => false,
    }
}

/// Replaces every reference in node `node`'s `params` by its value, recording each use;
/// every unknown name is an error naming the node and the parameter.
pub fn resolve(
    values: &Map<String, Value>,
    node: &str,
    params: &mut Map<String, Value>,
    uses: &mut Vec<Use>,
) -> Vec<GraphError> {
    let mut errors = Vec::new();
    for (key, v) in params.iter_mut() {
        let mut path = vec![Step::Key(key.clone())];
        walk(values, node, v, &mut path, uses, &mut errors);
    }
    errors
}

fn walk(
    values: &Map<String, Value>,
    node: &str,
    v: &mut Value,
    path: &mut Vec<Step>,
    uses: &mut Vec<Use>,
    errors: &mut Vec<GraphError>,
) {
    match v {
        Value::Object(m) if m.contains_key(KEY) => {
            let mut fields = m.clone();
            let name = fields.remove(KEY);
            let Some(Value::String(name)) = name else {
                errors.push(error(
                    Some(node),
                    &shown(path),
                    format!(
                        "`{KEY}` must name a shared value, got {}",
                        name.unwrap_or_default()
                    ),
                ));
                return;
            };
            if holds_reference(&Value::Object(fields.clone())) {
                errors.push(error(
                    Some(node),
                    &shown(path),
                    "a reference's own fields cannot refer to a value again".into(),
                ));
                return;
            }
            match value_with(values, &name, &fields) {
                Ok(resolved) => {
                    *v = resolved;
                    uses.push(Use {
                        node: node.to_string(),
                        path: path.clone(),
                        name,
                        fields,
                    });
                }
                Err(message) => errors.push(error(Some(node), &shown(path), message)),
            }
        }
        Value::Object(m) => {
            for (k, child) in m.iter_mut() {
                path.push(Step::Key(k.clone()));
                walk(values, node, child, path, uses, errors);
                path.pop();
            }
        }
        Value::Array(a) => {
            for (i, child) in a.iter_mut().enumerate() {
                path.push(Step::Index(i));
                walk(values, node, child, path, uses, errors);
                path.pop();
            }
        }
        _ => {}
    }
}

/// Value `name` with `fields` replacing its own (an object's).
pub(crate) fn value_with(
    values: &Map<String, Value>,
    name: &str,
    fields: &Map<String, Value>,
) -> Result<Value, String> {
    let Some(value) = values.get(name) else {
        let hint = crate::nearest(name, values.keys().map(String::as_str))
            .map(|s| format!(" (did you mean `{s}`?)"))
            .unwrap_or_default();
        return Err(if values.is_empty() {
            format!("refers to the shared value `{name}`, but the file has no `values`")
        } else {
            format!("no shared value `{name}`{hint}")
        });
    };
    if fields.is_empty() {
        return Ok(value.clone());
    }
    match value {
        Value::Object(base) => {
            let mut out = base.clone();
            for (k, v) in fields {
                out.insert(k.clone(), v.clone());
            }
            Ok(Value::Object(out))
        }
        _ => Err(format!(
            "shared value `{name}` is not an object, so the reference cannot replace its fields ({})",
            fields.keys().cloned().collect::<Vec<_>>().join(", ")
        )),
    }
}

#[cfg(test)]
mod tests {
    use crate::file::GraphFile;
    use serde_json::json;

    const FILE: &str = r#"{"mesoflow": 1,
        "values": { "camera": { "eye": [0, 1, 2], "fov": 40 }, "tiling": [12, 5] },
        "nodes": {
            "a": { "kind": "k", "params": { "camera": { "$value": "camera" }, "tiling": { "$value": "tiling" } } },
            "b": { "kind": "k", "params": { "camera": { "$value": "camera", "fov": 30 }, "list": [1, { "$value": "tiling" }] } }
        }}"#;

    #[test]
    fn references_read_as_the_values_and_a_reference_s_fields_replace_the_value_s() {
        let f = GraphFile::parse(FILE).unwrap();
        let a = &f.node("a").unwrap().params;
        assert_eq!(a["camera"], json!({ "eye": [0, 1, 2], "fov": 40 }));
        assert_eq!(a["tiling"], json!([12, 5]));
        let b = &f.node("b").unwrap().params;
        assert_eq!(b["camera"], json!({ "eye": [0, 1, 2], "fov": 30 }));
        assert_eq!(b["list"], json!([1, [12, 5]]));
        // Written out, each value stands where it is used.
        let again = GraphFile::parse(&f.to_json()).unwrap();
        assert_eq!(again, f);
    }

    #[test]
    fn an_override_of_a_value_reaches_every_use_but_a_reference_s_own_fields() {
        let mut f = GraphFile::parse(FILE).unwrap();
        f.apply(&crate::parse_override("values.camera.fov=25").unwrap())
            .unwrap();
        assert_eq!(f.node("a").unwrap().params["camera"]["fov"], json!(25));
        assert_eq!(f.node("b").unwrap().params["camera"]["fov"], json!(30));
        f.apply(&crate::parse_override("values.tiling=[2,2]").unwrap())
            .unwrap();
        assert_eq!(f.node("a").unwrap().params["tiling"], json!([2, 2]));
        assert_eq!(f.node("b").unwrap().params["list"], json!([1, [2, 2]]));
        let err = f
            .apply(&crate::parse_override("values.camra=1").unwrap())
            .unwrap_err();
        assert!(err.contains("did you mean `camera`"), "{err}");
    }

    #[test]
    fn unknown_names_and_values_that_refer_are_refused_naming_node_and_parameter() {
        let text = FILE.replace(r#""$value": "tiling" } }"#, r#""$value": "tilling" } }"#);
        let errs = GraphFile::parse(&text).unwrap_err();
        let msg = errs
            .iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join("\n");
        assert!(msg.contains("`a`") && msg.contains("tiling"), "{msg}");
        assert!(msg.contains("did you mean `tiling`"), "{msg}");
        let text = FILE.replace(
            r#""tiling": [12, 5] }"#,
            r#""tiling": { "$value": "camera" } }"#,
        );
        let msg = GraphFile::parse(&text).unwrap_err()[0].to_string();
        assert!(msg.contains("refers to another value"), "{msg}");
        let text = r#"{"mesoflow": 1, "nodes": { "a": { "kind": "k", "params": { "c": { "$value": "x" } } } } }"#;
        let msg = GraphFile::parse(text).unwrap_err()[0].to_string();
        assert!(msg.contains("has no `values`"), "{msg}");
    }
}
