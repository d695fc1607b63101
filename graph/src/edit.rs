//! Parameter overrides (`--set id.param=value`, sweeps): parsing them and applying them to a file.

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
                decl.params.insert(o.param.clone(), o.value.clone());
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
