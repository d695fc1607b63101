//! A reference to one output of one node, `node.port`, as graph files write inputs.

use std::fmt;

/// A reference to an output: `node.port`.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PortRef {
    pub node: String,
    pub port: String,
}

impl PortRef {
    /// Parses "node.port"; `None` if the text has not that shape.
    pub fn parse(text: &str) -> Option<PortRef> {
        let (node, port) = text.split_once('.')?;
        if node.is_empty() || port.is_empty() || port.contains('.') {
            return None;
        }
        Some(PortRef {
            node: node.to_string(),
            port: port.to_string(),
        })
    }
}

impl fmt::Display for PortRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.node, self.port)
    }
}
