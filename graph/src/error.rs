//! Errors of the static check. Every variant names the node and the field (parameter or port) it
//! concerns, says what was expected and what was found.

use std::fmt;
use thiserror::Error;

/// A kind nobody mistyped may be a Python node (`@mesoflow.node`): it exists only in the Python
/// process that defined it, so the command line cannot run it, and says so.
fn kind_hint(s: &Option<String>) -> String {
    match s {
        Some(_) => hint(s),
        None => " (no built-in kind has this name; a kind defined in Python with @mesoflow.node \
                  exists only in the Python session that defines it: run this graph from there)"
            .into(),
    }
}

fn hint(s: &Option<String>) -> String {
    s.as_ref()
        .map(|s| format!(" (did you mean `{s}`?)"))
        .unwrap_or_default()
}

#[derive(Clone, Debug, Error, PartialEq)]
pub enum GraphError {
    #[error("JSON syntax error at line {line}, column {column}: {message}")]
    Syntax {
        line: usize,
        column: usize,
        message: String,
    },
    #[error("{message}")]
    Structure {
        node: Option<String>,
        field: Option<String>,
        message: String,
    },
    #[error("unsupported format version {found}; this mesoflow reads versions 1 to {supported}")]
    Version { found: u64, supported: u64 },
    #[error("node id `{node}` is invalid: ids match [a-z][a-z0-9_]* (or a path of them, `sub/node`, for a node inside a subgraph)")]
    BadNodeId { node: String },
    #[error("node id `{node}` is defined more than once")]
    DuplicateId { node: String },
    #[error("node `{node}`: unknown kind `{kind}`{}", kind_hint(suggestion))]
    UnknownKind {
        node: String,
        kind: String,
        suggestion: Option<String>,
    },
    #[error(
        "node `{node}` ({kind}): unknown parameter `{param}`{}",
        hint(suggestion)
    )]
    UnknownParam {
        node: String,
        kind: String,
        param: String,
        suggestion: Option<String>,
    },
    #[error(
        "node `{node}`: parameter `{param}` expects {expected}, got {found}{}",
        hint(suggestion)
    )]
    ParamType {
        node: String,
        param: String,
        expected: String,
        found: String,
        suggestion: Option<String>,
    },
    #[error("node `{node}`: parameter `{param}` is out of range: {message}")]
    ParamRange {
        node: String,
        param: String,
        message: String,
    },
    /// A value the schema allows but the parameter cannot hold, or an output path that would
    /// leave the output folder.
    #[error("node `{node}`: parameter `{param}`: {message}")]
    ParamInvalid {
        node: String,
        param: String,
        message: String,
    },
    #[error("node `{node}`: required parameter `{param}` is missing")]
    MissingParam { node: String, param: String },
    #[error("node `{node}`: required input `{port}` ({ty}) is not connected")]
    MissingInput {
        node: String,
        port: String,
        ty: String,
    },
    #[error("node `{node}` ({kind}): unknown input `{port}`{}", hint(suggestion))]
    UnknownInput {
        node: String,
        kind: String,
        port: String,
        suggestion: Option<String>,
    },
    #[error("node `{node}`: input `{port}` is `{reference}`, expected the form \"node.port\"")]
    BadReference {
        node: String,
        port: String,
        reference: String,
    },
    #[error(
        "node `{node}`: input `{port}` names node `{target}`, which does not exist{}",
        hint(suggestion)
    )]
    NoSuchNode {
        node: String,
        port: String,
        target: String,
        suggestion: Option<String>,
    },
    #[error(
        "node `{node}`: input `{port}` names `{target}.{target_port}`, but `{target}` ({kind}) has no output `{target_port}`{}",
        hint(suggestion)
    )]
    NoSuchOutput {
        node: String,
        port: String,
        target: String,
        target_port: String,
        kind: String,
        suggestion: Option<String>,
    },
    #[error("`{node}` input `{port}` expects {expected}, got {found} from `{from}`")]
    TypeMismatch {
        node: String,
        port: String,
        expected: String,
        found: String,
        from: String,
    },
    #[error("cycle: {}", cycle_text(nodes))]
    Cycle { nodes: Vec<String> },
}

fn cycle_text(nodes: &[String]) -> String {
    let mut parts: Vec<&str> = nodes.iter().map(String::as_str).collect();
    if let Some(first) = nodes.first() {
        parts.push(first);
    }
    parts.join(" -> ")
}

impl GraphError {
    /// The node the error concerns, if any.
    pub fn node(&self) -> Option<&str> {
        use GraphError::*;
        match self {
            Syntax { .. } | Version { .. } => None,
            Structure { node, .. } => node.as_deref(),
            Cycle { nodes } => nodes.first().map(String::as_str),
            BadNodeId { node }
            | DuplicateId { node }
            | UnknownKind { node, .. }
            | UnknownParam { node, .. }
            | ParamType { node, .. }
            | ParamRange { node, .. }
            | ParamInvalid { node, .. }
            | MissingParam { node, .. }
            | MissingInput { node, .. }
            | UnknownInput { node, .. }
            | BadReference { node, .. }
            | NoSuchNode { node, .. }
            | NoSuchOutput { node, .. }
            | TypeMismatch { node, .. } => Some(node),
        }
    }

    /// The parameter or port the error concerns, if any.
    pub fn field(&self) -> Option<&str> {
        use GraphError::*;
        match self {
            Structure { field, .. } => field.as_deref(),
            UnknownKind { .. } => Some("kind"),
            UnknownParam { param, .. }
            | ParamType { param, .. }
            | ParamRange { param, .. }
            | ParamInvalid { param, .. }
            | MissingParam { param, .. } => Some(param),
            MissingInput { port, .. }
            | UnknownInput { port, .. }
            | BadReference { port, .. }
            | NoSuchNode { port, .. }
            | NoSuchOutput { port, .. }
            | TypeMismatch { port, .. } => Some(port),
            _ => None,
        }
    }
}

/// All the errors found in one graph file.
#[derive(Clone, Debug, Error, PartialEq)]
pub struct GraphErrors {
    pub file: String,
    pub errors: Vec<GraphError>,
}

impl fmt::Display for GraphErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.errors.len();
        writeln!(
            f,
            "{}: {n} error{}",
            self.file,
            if n == 1 { "" } else { "s" }
        )?;
        // A generated file can hold thousands of the same mistake: the first hundred say it.
        const SHOWN: usize = 100;
        for e in self.errors.iter().take(SHOWN) {
            writeln!(f, "  {}: {e}", self.file)?;
        }
        if n > SHOWN {
            writeln!(f, "  … and {} more", n - SHOWN)?;
        }
        Ok(())
    }
}
