//! `--verify-cache`: a cache hit is recomputed and compared with the cached value by encoding, so
//! a kind whose results changed without a version bump (or that is not a pure function) fails.

use crate::node::{DynNode, NodeError, Outputs};

/// Compares two output sets by their encodings; returns the first differing port.
pub(crate) fn compare(a: &Outputs, b: &Outputs) -> Result<(), String> {
    let encode = |v: &crate::value::ValueRef| {
        let mut e = crate::codec::Encoder::default();
        v.encode(&mut e);
        e.bytes
    };
    for (port, va) in &a.values {
        match b.get(port) {
            Some(vb) if va.type_name() == vb.type_name() && encode(va) == encode(vb) => {}
            _ => return Err(port.clone()),
        }
    }
    match b.values.keys().find(|k| !a.values.contains_key(*k)) {
        Some(k) => Err(k.clone()),
        None => Ok(()),
    }
}

/// The failure a mismatch becomes.
pub(crate) fn mismatch(node: &dyn DynNode, port: &str) -> NodeError {
    NodeError::Failed(format!(
        "--verify-cache: the cached output `{port}` differs from the recomputed one; the kind \
         `{}` (version {}) changed its results without a version bump",
        node.spec().kind,
        node.spec().version
    ))
}

/// Every declared output must be present with its declared type: downstream nodes rely on it.
pub(crate) fn check_outputs(node: &dyn DynNode, out: Outputs) -> Result<Outputs, NodeError> {
    for port in &node.spec().outputs {
        match out.get(port.name) {
            None if !port.required => {}
            None => {
                return Err(NodeError::Failed(format!(
                    "internal: output `{}` was not produced",
                    port.name
                )))
            }
            Some(v) if !port.ty.accepts(v.type_name()) => {
                return Err(NodeError::Failed(format!(
                    "internal: output `{}` is a {}, declared {}",
                    port.name,
                    v.type_name(),
                    port.ty
                )))
            }
            Some(_) => {}
        }
    }
    Ok(out)
}
