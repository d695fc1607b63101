//! The JSON Schema of graph files (draft 2020-12), with every kind's parameters and ports, for
//! editors: `mesoflow schema > mesoflow.schema.json`.

use crate::catalog::Catalog;
use serde_json::{json, Map, Value};

/// Replaces every `$ref` into the kind's own `$defs` by the definition itself, so that kinds'
/// definitions (several are called `Params` or `Format`) cannot collide in one document.
fn inline_refs(schema: &Value, defs: &Map<String, Value>, depth: usize) -> Value {
    match schema {
        Value::Object(obj) => {
            if let Some(target) = obj.get("$ref").and_then(Value::as_str) {
                let name = target.rsplit('/').next().unwrap_or_default();
                if let Some(def) = defs.get(name).filter(|_| depth < 32) {
                    let mut resolved = inline_refs(def, defs, depth + 1);
                    // The field's own keywords (its doc, its default) beside the `$ref` win over
                    // the definition's: "views" says what views are, not what a DirectionSet is.
                    if let Value::Object(r) = &mut resolved {
                        for (k, v) in obj.iter().filter(|(k, _)| k.as_str() != "$ref") {
                            r.insert(k.clone(), inline_refs(v, defs, depth + 1));
                        }
                    }
                    return resolved;
                }
            }
            let out = obj
                .iter()
                .filter(|(k, _)| k.as_str() != "$defs" && k.as_str() != "$schema")
                .map(|(k, v)| (k.clone(), inline_refs(v, defs, depth)))
                .collect();
            Value::Object(out)
        }
        Value::Array(a) => Value::Array(a.iter().map(|v| inline_refs(v, defs, depth)).collect()),
        other => other.clone(),
    }
}

pub fn graph_schema(catalog: &dyn Catalog) -> Value {
    let mut kinds = catalog.kinds();
    kinds.sort();
    let mut rules = Vec::new();
    for kind in &kinds {
        let Some(sig) = catalog.signature(kind) else {
            continue;
        };
        let defs = sig
            .params
            .get("$defs")
            .and_then(Value::as_object)
            .cloned()
            .unwrap_or_default();
        let mut params = inline_refs(&sig.params, &defs, 0);
        if let Value::Object(p) = &mut params {
            p.remove("title");
        }
        let inputs: Map<String, Value> = sig
            .inputs
            .iter()
            .map(|i| {
                let desc = format!("{} ({}): output of another node, \"node.port\"", i.doc, i.ty);
                (i.name.clone(), json!({ "type": "string", "pattern": "^[a-z][a-z0-9_]*\\.[a-z0-9_]+$", "description": desc }))
            })
            .collect();
        let required: Vec<&str> = sig
            .inputs
            .iter()
            .filter(|i| i.required)
            .map(|i| i.name.as_str())
            .collect();
        rules.push(json!({
            "if": { "properties": { "kind": { "const": kind } }, "required": ["kind"] },
            "then": {
                "description": sig.doc,
                "properties": {
                    "params": params,
                    "inputs": { "type": "object", "properties": inputs, "required": required, "additionalProperties": false }
                }
            }
        }));
    }
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "mesoflow graph file, version 1",
        "type": "object",
        "required": ["mesoflow", "nodes"],
        "additionalProperties": false,
        "properties": {
            "mesoflow": { "const": 1, "description": "format version" },
            "description": { "type": "string" },
            "values": { "type": "object", "description": "shared values, written once and referred to from any node's parameters as {\"$value\": \"name\"} (with fields beside it replacing an object value's own)" },
            "expected_warnings": { "type": "object", "description": "per node id, parts of the warnings the graph expects of it (what the graph is about): a run keeps them in its report and does not print them", "additionalProperties": { "type": "array", "items": { "type": "string", "minLength": 1 } } },
            "nodes": {
                "type": "object",
                "propertyNames": { "pattern": "^[a-z][a-z0-9_]*$" },
                "additionalProperties": {
                    "type": "object",
                    "required": ["kind"],
                    "additionalProperties": false,
                    "properties": {
                        "kind": { "enum": kinds },
                        "params": { "type": "object" },
                        "inputs": { "type": "object" }
                    },
                    "allOf": rules
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::{DevicePreference, KindSignature};

    #[test]
    fn refs_are_inlined_per_kind() {
        let sig = KindSignature {
            kind: "a.b".into(),
            version: 1,
            device: DevicePreference::Cpu,
            doc: "d".into(),
            inputs: vec![],
            outputs: vec![],
            params: json!({"type": "object", "properties": {"p": {"$ref": "#/$defs/P", "default": "x"}},
                           "$defs": {"P": {"type": "string", "enum": ["x", "y"]}}}),
            timings: vec![],
        };
        let s = graph_schema(&vec![sig]);
        let text = s.to_string();
        assert!(!text.contains("$ref"), "{text}");
        let p = &s["properties"]["nodes"]["additionalProperties"]["allOf"][0]["then"]["properties"]
            ["params"]["properties"]["p"];
        assert_eq!(
            p,
            &json!({"type": "string", "enum": ["x", "y"], "default": "x"})
        );
    }
}
