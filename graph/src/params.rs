//! Checks a node's parameter object against its kind's JSON Schema. Only the subset of JSON Schema
//! that `schemars` emits for parameter structs is understood: `type`, `enum`, `const`, `oneOf`,
//! `anyOf`, `$ref` into `$defs`, numeric bounds, `items`, `properties`, `required` and
//! `additionalProperties`. Anything else in a schema is ignored (accepted).

use crate::error::GraphError;
use crate::file::describe;
use serde_json::{Map, Value};

/// Checks `params` of node `node` (kind `kind`) against `schema`; returns every problem found.
pub fn check_params(
    node: &str,
    kind: &str,
    schema: &Value,
    params: &Map<String, Value>,
) -> Vec<GraphError> {
    let mut errors = Vec::new();
    let root = schema;
    let props = schema.get("properties").and_then(Value::as_object);
    for (name, value) in params {
        match props.and_then(|p| p.get(name)) {
            None => errors.push(GraphError::UnknownParam {
                node: node.into(),
                kind: kind.into(),
                param: name.clone(),
                suggestion: crate::nearest(
                    name,
                    props.into_iter().flat_map(|p| p.keys().map(String::as_str)),
                ),
            }),
            Some(sub) => {
                if let Err(problem) = check_value(root, sub, value) {
                    errors.push(problem.into_error(node, name, value));
                }
            }
        }
    }
    if let Some(required) = schema.get("required").and_then(Value::as_array) {
        for r in required.iter().filter_map(Value::as_str) {
            if !params.contains_key(r) {
                errors.push(GraphError::MissingParam {
                    node: node.into(),
                    param: r.into(),
                });
            }
        }
    }
    errors
}

/// Why a value does not match a schema.
#[derive(Debug)]
pub enum Problem {
    Type {
        expected: String,
        suggestion: Option<String>,
    },
    Range(String),
}

impl Problem {
    fn into_error(self, node: &str, param: &str, value: &Value) -> GraphError {
        match self {
            Problem::Type {
                expected,
                suggestion,
            } => GraphError::ParamType {
                node: node.into(),
                param: param.into(),
                expected,
                found: describe(value),
                suggestion,
            },
            Problem::Range(message) => GraphError::ParamRange {
                node: node.into(),
                param: param.into(),
                message,
            },
        }
    }
}

/// The schema `schema` stands for, following `$ref`s into `root`'s definitions.
pub fn resolve<'a>(root: &'a Value, schema: &'a Value) -> &'a Value {
    let mut s = schema;
    for _ in 0..16 {
        match s.get("$ref").and_then(Value::as_str) {
            Some(r) => {
                let name = r.rsplit('/').next().unwrap_or_default();
                let found = root
                    .get("$defs")
                    .or_else(|| root.get("definitions"))
                    .and_then(|d| d.get(name));
                match found {
                    Some(f) => s = f,
                    None => return s,
                }
            }
            None => return s,
        }
    }
    s
}

/// A human description of what a schema accepts.
pub fn expected_text(root: &Value, schema: &Value) -> String {
    let s = resolve(root, schema);
    if let Some(values) = enum_values(root, s) {
        let list: Vec<String> = values.iter().map(|v| v.to_string()).collect();
        return format!("one of {}", list.join(", "));
    }
    for key in ["oneOf", "anyOf"] {
        if let Some(branches) = s.get(key).and_then(Value::as_array) {
            let texts: Vec<String> = branches.iter().map(|b| expected_text(root, b)).collect();
            return texts.join(" or ");
        }
    }
    match s.get("type") {
        Some(Value::String(t)) => type_text(t, s),
        Some(Value::Array(ts)) => ts
            .iter()
            .filter_map(Value::as_str)
            .map(|t| type_text(t, s))
            .collect::<Vec<_>>()
            .join(" or "),
        _ => "any value".into(),
    }
}

fn type_text(t: &str, s: &Value) -> String {
    match t {
        "integer" => "an integer".into(),
        "number" => "a number".into(),
        "string" => "a string".into(),
        "boolean" => "a boolean".into(),
        "null" => "null".into(),
        "array" => match s.get("items") {
            Some(items) => format!("an array of {}", expected_text(s, items)),
            None => "an array".into(),
        },
        "object" => "an object".into(),
        other => other.into(),
    }
}

/// The values of an `enum` or of a `oneOf` made only of `const`s.
fn enum_values(root: &Value, s: &Value) -> Option<Vec<Value>> {
    if let Some(vals) = s.get("enum").and_then(Value::as_array) {
        return Some(vals.clone());
    }
    let branches = s.get("oneOf").or_else(|| s.get("anyOf"))?.as_array()?;
    let mut out = Vec::new();
    for b in branches {
        let b = resolve(root, b);
        if let Some(c) = b.get("const") {
            out.push(c.clone());
        } else if let Some(vals) = b.get("enum").and_then(Value::as_array) {
            out.extend(vals.iter().cloned());
        } else {
            return None;
        }
    }
    Some(out)
}

fn type_matches(t: &str, v: &Value) -> bool {
    match t {
        // Written as an integer: `3.0` and `-0.0` are floats, and the typed parameters refuse them.
        "integer" => v.is_i64() || v.is_u64(),
        "number" => v.is_number(),
        "string" => v.is_string(),
        "boolean" => v.is_boolean(),
        "null" => v.is_null(),
        "array" => v.is_array(),
        "object" => v.is_object(),
        _ => true,
    }
}

/// The bounds that an integer `format` (as schemars writes for Rust integer types) implies, and
/// output paths (`x-output-path`) that must stay inside the output folder.
fn format_problem(s: &Value, v: &Value) -> Option<Problem> {
    if s.get("x-output-path") == Some(&Value::Bool(true)) {
        let path = v.as_str()?;
        return output_path_problem(path).map(Problem::Range);
    }
    let (lo, hi): (i128, i128) = match s.get("format").and_then(Value::as_str)? {
        "uint8" => (0, u8::MAX.into()),
        "uint16" => (0, u16::MAX.into()),
        "uint32" => (0, u32::MAX.into()),
        "uint64" | "uint" => (0, u64::MAX.into()),
        "int8" => (i8::MIN.into(), i8::MAX.into()),
        "int16" => (i16::MIN.into(), i16::MAX.into()),
        "int32" => (i32::MIN.into(), i32::MAX.into()),
        "int64" | "int" => (i64::MIN.into(), i64::MAX.into()),
        _ => return None,
    };
    let x: i128 = match (v.as_i64(), v.as_u64()) {
        (Some(i), _) => i.into(),
        (_, Some(u)) => u.into(),
        // Beyond 64 bits serde_json keeps a float: out of every integer range.
        _ if v.is_number() => {
            return Some(Problem::Range(format!(
                "{v} does not fit an integer from {lo} to {hi}"
            )))
        }
        _ => return None,
    };
    (x < lo || x > hi).then(|| Problem::Range(format!("{x} is outside {lo}..={hi}")))
}

/// Why `path` may not be written under the output folder: empty, absolute, or climbing out.
pub fn output_path_problem(path: &str) -> Option<String> {
    let p = std::path::Path::new(path);
    if path.trim().is_empty() {
        return Some("an output path must not be empty".into());
    }
    if p.is_absolute() || path.starts_with('/') || path.starts_with('\\') {
        return Some(format!(
            "`{path}` is absolute; output paths are relative to the output folder"
        ));
    }
    if p.components().any(|c| {
        !matches!(
            c,
            std::path::Component::Normal(_) | std::path::Component::CurDir
        )
    }) {
        return Some(format!(
            "`{path}` leaves the output folder (`..`); output paths stay inside it"
        ));
    }
    None
}

/// Checks one value against one schema.
pub fn check_value(root: &Value, schema: &Value, v: &Value) -> Result<(), Problem> {
    let s = resolve(root, schema);
    let type_error = |suggestion| Problem::Type {
        expected: expected_text(root, s),
        suggestion,
    };
    if let Some(values) = enum_values(root, s) {
        if values.contains(v) {
            return Ok(());
        }
        let suggestion = v
            .as_str()
            .and_then(|word| crate::nearest(word, values.iter().filter_map(Value::as_str)));
        return Err(type_error(suggestion));
    }
    if let Some(c) = s.get("const") {
        return if c == v {
            Ok(())
        } else {
            Err(type_error(None))
        };
    }
    for key in ["oneOf", "anyOf"] {
        if let Some(branches) = s.get(key).and_then(Value::as_array) {
            let mut range_problem = None;
            for b in branches {
                match check_value(root, b, v) {
                    Ok(()) => return Ok(()),
                    Err(p @ Problem::Range(_)) => range_problem = Some(p),
                    Err(_) => {}
                }
            }
            return Err(range_problem.unwrap_or_else(|| type_error(None)));
        }
    }
    let type_ok = match s.get("type") {
        Some(Value::String(t)) => type_matches(t, v),
        Some(Value::Array(ts)) => ts
            .iter()
            .filter_map(Value::as_str)
            .any(|t| type_matches(t, v)),
        _ => true,
    };
    if !type_ok {
        return Err(type_error(None));
    }
    // The documented bounds first, then the storage type's: `-5` for a size in [4, 8192] is
    // "below the minimum 4", not "outside 0..=4294967295" (issue 58).
    if let Some(x) = v.as_f64() {
        let bound = |k: &str| s.get(k).and_then(Value::as_f64);
        if let Some(m) = bound("minimum").filter(|m| x < *m) {
            return Err(Problem::Range(format!("{x} is below the minimum {m}")));
        }
        if let Some(m) = bound("maximum").filter(|m| x > *m) {
            return Err(Problem::Range(format!("{x} is above the maximum {m}")));
        }
        if let Some(m) = bound("exclusiveMinimum").filter(|m| x <= *m) {
            return Err(Problem::Range(format!("{x} must be greater than {m}")));
        }
        if let Some(m) = bound("exclusiveMaximum").filter(|m| x >= *m) {
            return Err(Problem::Range(format!("{x} must be less than {m}")));
        }
    }
    if let Some(problem) = format_problem(s, v) {
        return Err(problem);
    }
    if let (Some(Value::Array(prefix)), Some(arr)) = (s.get("prefixItems"), v.as_array()) {
        for (i, (item, sub)) in arr.iter().zip(prefix).enumerate() {
            check_value(root, sub, item).map_err(|p| match p {
                Problem::Range(m) => Problem::Range(format!("element {i}: {m}")),
                Problem::Type { .. } => type_error(None),
            })?;
        }
    }
    if let (Some(items), Some(arr)) = (s.get("items"), v.as_array()) {
        for (i, item) in arr.iter().enumerate() {
            check_value(root, items, item).map_err(|p| match p {
                Problem::Range(m) => Problem::Range(format!("element {i}: {m}")),
                Problem::Type { .. } => type_error(None),
            })?;
        }
        let len = arr.len() as u64;
        if let Some(m) = s
            .get("minItems")
            .and_then(Value::as_u64)
            .filter(|m| len < *m)
        {
            return Err(Problem::Range(format!(
                "{len} elements, at least {m} expected"
            )));
        }
        if let Some(m) = s
            .get("maxItems")
            .and_then(Value::as_u64)
            .filter(|m| len > *m)
        {
            return Err(Problem::Range(format!(
                "{len} elements, at most {m} expected"
            )));
        }
    }
    if let (Some(required), Some(obj)) =
        (s.get("required").and_then(Value::as_array), v.as_object())
    {
        if let Some(missing) = required
            .iter()
            .filter_map(Value::as_str)
            .find(|r| !obj.contains_key(*r))
        {
            return Err(Problem::Type {
                expected: format!("{} (`{missing}` is missing)", expected_text(root, s)),
                suggestion: None,
            });
        }
    }
    if let (Some(props), Some(obj)) = (
        s.get("properties").and_then(Value::as_object),
        v.as_object(),
    ) {
        for (k, sub) in obj {
            match props.get(k) {
                Some(ps) => check_value(root, ps, sub).map_err(|p| match p {
                    Problem::Range(m) => Problem::Range(format!("`{k}`: {m}")),
                    other => other,
                })?,
                None if s.get("additionalProperties") == Some(&Value::Bool(false)) => {
                    return Err(Problem::Type {
                        expected: format!(
                            "an object with fields {}",
                            props.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                        suggestion: crate::nearest(k, props.keys().map(String::as_str)),
                    })
                }
                None => {}
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn schema() -> Value {
        json!({
            "type": "object",
            "properties": {
                "size": {"type": "integer", "minimum": 1, "maximum": 8192, "default": 128},
                "depth": {"type": "number", "default": 4.0},
                "pattern": {"$ref": "#/$defs/Pattern", "default": "weave"},
                "path": {"type": ["string", "null"]},
                "mode": {"oneOf": [{"const": "a"}, {"const": "b"}]}
            },
            "required": ["depth"],
            "$defs": {"Pattern": {"type": "string", "enum": ["bumps", "weave", "cells"]}}
        })
    }

    fn errs(params: Value) -> Vec<GraphError> {
        check_params("n", "k", &schema(), params.as_object().unwrap())
    }

    #[test]
    fn accepts_valid_params() {
        assert!(errs(
            json!({"size": 64, "depth": 2, "pattern": "cells", "path": null, "mode": "b"})
        )
        .is_empty());
    }

    #[test]
    fn reports_every_kind_of_problem_at_once() {
        let e = errs(json!({"sise": 3, "size": 0, "pattern": "waeve", "mode": 3}));
        assert_eq!(e.len(), 5, "{e:#?}");
        // Parameters are visited in file order: sise, size, pattern, mode; then required ones.
        assert!(
            matches!(&e[0], GraphError::UnknownParam { suggestion: Some(s), .. } if s == "size")
        );
        assert!(matches!(&e[1], GraphError::ParamRange { param, .. } if param == "size"));
        assert!(matches!(&e[2], GraphError::ParamType { suggestion: Some(s), .. } if s == "weave"));
        assert!(matches!(&e[3], GraphError::ParamType { param, .. } if param == "mode"));
        assert!(matches!(&e[4], GraphError::MissingParam { param, .. } if param == "depth"));
    }

    #[test]
    fn integer_formats_bound_values_and_floats_are_not_integers() {
        let schema = json!({"type": "object", "properties": {
            "n": {"type": "integer", "format": "uint32", "minimum": 0},
            "out": {"type": "string", "x-output-path": true}}});
        let check = |v: Value| check_params("n", "k", &schema, v.as_object().unwrap());
        assert!(check(json!({"n": 4294967295u64})).is_empty());
        assert!(matches!(
            &check(json!({"n": 4294967296u64}))[0],
            GraphError::ParamRange { .. }
        ));
        assert!(matches!(
            &check(json!({"n": 18446744073709551616.0}))[0],
            GraphError::ParamType { .. }
        ));
        assert!(matches!(
            &check(json!({"n": -0.0}))[0],
            GraphError::ParamType { .. }
        ));
        assert!(matches!(
            &check(json!({"n": 3.0}))[0],
            GraphError::ParamType { .. }
        ));
        for bad in ["/etc/passwd", "../up.png", "a/../../b.png", ""] {
            let e = check(json!({ "out": bad }));
            assert!(
                matches!(&e[0], GraphError::ParamRange { param, .. } if param == "out"),
                "{bad}: {e:?}"
            );
        }
        assert!(check(json!({"out": "frames/a.png"})).is_empty());
        assert!(check(json!({"out": "./a.png"})).is_empty());
    }

    #[test]
    fn integer_rejects_fractions() {
        let e = errs(json!({"size": 2.5, "depth": 1}));
        assert!(
            matches!(&e[0], GraphError::ParamType { expected, .. } if expected == "an integer")
        );
    }
}
