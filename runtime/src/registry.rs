//! The set of node kinds and value types an engine knows. `mesoflow-nodes` fills one.

use crate::codec::{DecodeError, Decoder};
use crate::node::{DynNode, Erased, Node};
use crate::value::{Artifact, Artifacts, DecodeFn, Scalar, ValueRef};
use mesoflow_graph::{Catalog, KindSignature};
use std::collections::BTreeMap;
use std::sync::Arc;

#[derive(Clone, Default)]
pub struct Registry {
    nodes: BTreeMap<String, Arc<dyn DynNode>>,
    codecs: BTreeMap<&'static str, DecodeFn>,
}

impl Registry {
    /// A registry with the runtime's own value types (Scalar, File) and no kinds.
    pub fn new() -> Self {
        let mut r = Registry::default();
        r.register_type(Scalar::TYPE, Scalar::decode);
        r.register_type(Artifact::TYPE, Artifact::decode);
        r.register_type(Artifacts::TYPE, Artifacts::decode);
        r
    }

    pub fn register<N: Node>(&mut self, node: N) -> &mut Self {
        let erased = Erased::new(node);
        self.nodes
            .insert(erased.spec.kind.to_string(), Arc::new(erased));
        self
    }

    /// A kind implemented outside Rust's type system (the Python package's `@mesoflow.node`):
    /// it describes itself through [`DynNode`] directly. It replaces a kind of the same name.
    pub fn register_dyn(&mut self, node: Arc<dyn DynNode>) -> &mut Self {
        self.nodes.insert(node.spec().kind.to_string(), node);
        self
    }

    pub fn register_type(&mut self, name: &'static str, decode: DecodeFn) -> &mut Self {
        self.codecs.insert(name, decode);
        self
    }

    pub fn node(&self, kind: &str) -> Option<&Arc<dyn DynNode>> {
        self.nodes.get(kind)
    }

    pub fn signatures(&self) -> impl Iterator<Item = &KindSignature> {
        self.nodes.values().map(|n| n.signature())
    }

    pub fn decode(&self, type_name: &str, bytes: &[u8]) -> Result<ValueRef, DecodeError> {
        let f = self
            .codecs
            .get(type_name)
            .ok_or_else(|| DecodeError::new(type_name, "no decoder registered for this type"))?;
        let mut d = Decoder::new("cache entry", bytes);
        let v = f(&mut d)?;
        d.finish()?;
        Ok(v)
    }
}

impl Catalog for Registry {
    fn signature(&self, kind: &str) -> Option<&KindSignature> {
        self.nodes.get(kind).map(|n| n.signature())
    }
    fn kinds(&self) -> Vec<&str> {
        self.nodes.keys().map(String::as_str).collect()
    }
    fn check_typed(
        &self,
        kind: &str,
        params: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<(), mesoflow_graph::TypedProblem> {
        use mesoflow_graph::TypedProblem;
        match self.nodes.get(kind) {
            Some(node) => node.prepare(params).map(|_| ()).map_err(|e| match e {
                // serde's refusal of the whole object: the checker finds the parameter.
                crate::NodeError::Param { param, message } if param == "params" => TypedProblem {
                    param: None,
                    message,
                },
                // `Node::check` named it.
                crate::NodeError::Param { param, message } => TypedProblem {
                    param: Some(param),
                    message,
                },
                other => TypedProblem {
                    param: None,
                    message: other.to_string(),
                },
            }),
            None => Ok(()),
        }
    }
}
