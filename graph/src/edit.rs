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
    check_target(node, param)?;
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

/// The most `.`-separated keys a parameter path may have: the deepest parameter object any kind
/// declares is two levels (`camera.resolution`); a path of 200 000 dots once built as many nested
/// objects and overflowed the stack (issue 43).
pub const MAX_PARAM_DEPTH: usize = 8;
/// The longest node id or parameter path, bytes.
pub const MAX_NAME_BYTES: usize = 256;

/// Refuses a node id or parameter path beyond [`MAX_NAME_BYTES`] or [`MAX_PARAM_DEPTH`], before
/// any work is done with it.
pub fn check_target(node: &str, param: &str) -> Result<(), String> {
    let short = |t: &str| t.chars().take(40).collect::<String>();
    if node.len() > MAX_NAME_BYTES || param.len() > MAX_NAME_BYTES {
        return Err(format!(
            "`{}….{}…`: a node id or parameter path is at most {MAX_NAME_BYTES} bytes",
            short(node),
            short(param)
        ));
    }
    let depth = param.split('.').count();
    if depth > MAX_PARAM_DEPTH {
        return Err(format!(
            "`{node}.{}…`: a parameter path has at most {MAX_PARAM_DEPTH} keys, this one {depth}",
            short(param)
        ));
    }
    Ok(())
}

impl GraphFile {
    /// `--set values.NAME[.field]=V`: the shared value changed, and written again at every use.
    fn apply_to_value(&mut self, o: &Override) -> Result<(), String> {
        let mut keys = o.param.split('.');
        let name = keys.next().unwrap_or_default().to_string();
        let Some(mut slot) = self.values.get_mut(&name) else {
            let hint = crate::nearest(&name, self.values.keys().map(String::as_str))
                .map(|s| format!(" (did you mean `{s}`?)"))
                .unwrap_or_default();
            return Err(format!(
                "--set values.{}: the graph has no shared value `{name}`{hint}",
                o.param
            ));
        };
        let mut path = name.clone();
        for key in keys {
            let Value::Object(map) = slot else {
                return Err(format!(
                    "--set values.{}: `{path}` is not an object",
                    o.param
                ));
            };
            slot = map
                .entry(key.to_string())
                .or_insert_with(|| Value::Object(Default::default()));
            path = format!("{path}.{key}");
        }
        *slot = o.value.clone();
        propagate(&self.values, &name, &self.uses, &mut self.nodes)
            .map_err(|e| format!("--set values.{}: {e}", o.param))
    }

    /// Applies an override; the static check then validates the new value like any other.
    pub fn apply(&mut self, o: &Override) -> Result<(), String> {
        check_target(&o.node, &o.param).map_err(|e| format!("--set {e}"))?;
        if o.node == crate::values::OVERRIDE_NODE && self.node(&o.node).is_none() {
            return self.apply_to_value(o);
        }
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
            // `sub/inner.param`: a parameter inside the subgraph `sub`, kept in its `set`.
            None if o.node.contains(crate::interface::SEP) => {
                let (head, rest) = o
                    .node
                    .split_once(crate::interface::SEP)
                    .unwrap_or((&o.node, ""));
                match self.node_mut(head) {
                    Some(decl) if decl.kind == crate::interface::KIND => {
                        let set = decl
                            .params
                            .entry("set".to_string())
                            .or_insert_with(|| Value::Object(Default::default()));
                        let Value::Object(set) = set else {
                            return Err(format!("--set {}.{}: `{head}.set` is not an object", o.node, o.param));
                        };
                        set.insert(format!("{rest}.{}", o.param), o.value.clone());
                        Ok(())
                    }
                    _ => Err(format!(
                        "--set {}.{}: no subgraph `{head}` in the graph (a path `a/b` names node `b` inside the graph node `a`)",
                        o.node, o.param
                    )),
                }
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

/// Writes value `name` (with each use's own fields) again at every use in `nodes`, after the
/// value changed.
fn propagate(
    values: &serde_json::Map<String, Value>,
    name: &str,
    uses: &[crate::values::Use],
    nodes: &mut [(String, crate::file::NodeDecl)],
) -> Result<(), String> {
    for u in uses.iter().filter(|u| u.name == name) {
        let v = crate::values::value_with(values, name, &u.fields)?;
        let Some((_, decl)) = nodes.iter_mut().find(|(id, _)| *id == u.node) else {
            continue;
        };
        let Some((crate::values::Step::Key(first), rest)) = u.path.split_first() else {
            continue;
        };
        let Some(mut slot) = decl.params.get_mut(first) else {
            continue;
        };
        for step in rest {
            let next = match (step, slot) {
                (crate::values::Step::Key(k), Value::Object(m)) => m.get_mut(k),
                (crate::values::Step::Index(i), Value::Array(a)) => a.get_mut(*i),
                _ => None,
            };
            let Some(next) = next else {
                return Err(format!(
                    "node `{}` no longer has `{}` where value `{name}` was used",
                    u.node,
                    crate::values::shown(&u.path)
                ));
            };
            slot = next;
        }
        *slot = v;
    }
    Ok(())
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
    fn a_path_too_deep_or_too_long_is_refused_before_any_work() {
        let mut f = GraphFile::parse(r#"{"mesoflow": 1, "nodes": {"r": {"kind": "k"}}}"#).unwrap();
        let deep = format!("r.{}=1", vec!["a"; 200_000].join("."));
        assert!(parse_override(&deep).unwrap_err().contains("at most"));
        let o = Override {
            node: "r".into(),
            param: vec!["a"; 100].join("."),
            value: Value::from(1),
        };
        let e = f.apply(&o).unwrap_err();
        assert!(e.contains("at most 8 keys"), "{e}");
        let long = Override {
            node: "r".repeat(300),
            param: "x".into(),
            value: Value::from(1),
        };
        assert!(f.apply(&long).unwrap_err().contains("256 bytes"));
        // Eight keys are still a path.
        let eight = parse_override(&format!("r.{}=1", ["a"; 8].join("."))).unwrap();
        f.apply(&eight).unwrap();
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
