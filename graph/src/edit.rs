//! Parameter overrides (`--set id.param=value`, `--set id.param.field=value` inside an object
//! parameter, sweeps): parsing them and applying them to a file.

use crate::file::GraphFile;
use serde_json::Value;

#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    pub node: String,
    pub param: String,
    pub value: Value,
}

/// Parses `id.param=value`. The value is read as JSON when it parses as JSON (numbers, booleans,
/// arrays, quoted strings) and as a plain string otherwise, so `--set surface.pattern=weave` works.
pub fn parse_override(text: &str) -> Result<Override, String> {
    let (target, value) = text
        .split_once('=')
        .ok_or_else(|| format!("`{text}`: expected id.param=value"))?;
    let (node, param) = target
        .split_once('.')
        .filter(|(n, p)| !n.is_empty() && !p.is_empty())
        .ok_or_else(|| format!("`{text}`: expected id.param=value"))?;
    Ok(Override {
        node: node.into(),
        param: param.into(),
        value: parse_value(value),
    })
}

/// A command-line value: JSON if it parses as JSON, a string otherwise.
pub fn parse_value(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|_| Value::String(text.to_string()))
}

impl GraphFile {
    /// Applies an override; the static check then validates the new value like any other.
    pub fn apply(&mut self, o: &Override) -> Result<(), String> {
        let ids: Vec<String> = self.nodes.iter().map(|(id, _)| id.clone()).collect();
        match self.node_mut(&o.node) {
            Some(decl) => {
                // `camera.resolution` sets a field inside an object parameter, creating the
                // object if the file left it to its defaults.
                let mut keys = o.param.split('.');
                let first = keys.next().unwrap_or_default();
                let mut slot = decl
                    .params
                    .entry(first.to_string())
                    .or_insert_with(|| Value::Object(Default::default()));
                let mut path = first.to_string();
                for key in keys {
                    let Value::Object(map) = slot else {
                        return Err(format!(
                            "--set {}.{}: `{path}` is not an object",
                            o.node, o.param
                        ));
                    };
                    slot = map
                        .entry(key.to_string())
                        .or_insert_with(|| Value::Object(Default::default()));
                    path = format!("{path}.{key}");
                }
                *slot = o.value.clone();
                Ok(())
            }
            None => {
                let hint = crate::nearest(&o.node, ids.iter().map(String::as_str))
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                Err(format!(
                    "--set {}.{}: no node `{}` in the graph{hint}",
                    o.node, o.param, o.node
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dotted_params_set_fields_inside_objects() {
        let mut f = GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {"r": {"kind": "k", "params": {"camera": {"fov": 40}, "n": 1}}}}"#,
        )
        .unwrap();
        f.apply(&parse_override("r.camera.resolution=[8,6]").unwrap())
            .unwrap();
        f.apply(&parse_override("r.light.intensity=2").unwrap())
            .unwrap();
        let p = &f.node_mut("r").unwrap().params;
        assert_eq!(
            p["camera"],
            serde_json::json!({"fov": 40, "resolution": [8, 6]})
        );
        assert_eq!(p["light"], serde_json::json!({"intensity": 2}));
        let e = f.apply(&parse_override("r.n.x=1").unwrap()).unwrap_err();
        assert!(e.contains("`n` is not an object"), "{e}");
    }

    #[test]
    fn values_are_json_or_strings() {
        let o = parse_override("surface.size=64").unwrap();
        assert_eq!(
            (o.node.as_str(), o.param.as_str(), o.value),
            ("surface", "size", Value::from(64))
        );
        assert_eq!(
            parse_override("s.pattern=weave").unwrap().value,
            Value::from("weave")
        );
        assert_eq!(
            parse_override("s.v=[1,2]").unwrap().value,
            serde_json::json!([1, 2])
        );
        assert!(parse_override("nodot=1").is_err());
        assert!(parse_override("a.b").is_err());
    }
}
