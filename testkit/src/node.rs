//! One node run in a test as the engine runs it: its parameter checks, then its run on a
//! detached context (no cache, no progress sink), and its outputs read by port and type. A
//! missing port or a value of another type fails the test naming both, instead of the
//! `get(..).unwrap().as_any().downcast_ref::<T>().unwrap()` chain every node test used to write.

use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, Outputs, Value};

/// `node` with `params` on `inputs`: `check`, then `run`, as the engine does before a run.
pub fn run<N: Node>(node: &N, params: &N::Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
    run_in(&NodeContext::detached(None), node, params, inputs)
}

/// As [`run`], in the caller's context (a GPU, a base folder for relative paths, or to read
/// its warnings and timings afterwards).
pub fn run_in<N: Node>(
    ctx: &NodeContext,
    node: &N,
    params: &N::Params,
    inputs: &Inputs,
) -> Result<Outputs, NodeError> {
    node.check(params)?;
    node.run(ctx, params, inputs)
}

/// As [`run`], with the parameters as JSON (they must parse) and relative file paths resolved
/// against `dir`, no inputs: a node that reads files.
pub fn run_json_in<N: Node>(
    node: &N,
    params: serde_json::Value,
    dir: &std::path::Path,
) -> Result<Outputs, NodeError> {
    let p: N::Params = serde_json::from_value(params).expect("the parameters parse");
    let ctx = NodeContext::detached(None).with_base(dir.to_path_buf());
    run_in(&ctx, node, &p, &Inputs::new())
}

/// Typed reads of a node's outputs.
pub trait OutputsExt {
    /// The value at `port`, if there is one of type `T`.
    fn try_value<T: Value>(&self, port: &str) -> Option<&T>;
    /// The value at `port`; fails the test naming the port when it is missing or not a `T`.
    fn value<T: Value>(&self, port: &str) -> &T;
    /// An owned copy of the value at `port`.
    fn take<T: Value + Clone>(&self, port: &str) -> T {
        self.value::<T>(port).clone()
    }
    /// The number at a `Scalar` port.
    fn scalar(&self, port: &str) -> f64;
}

impl OutputsExt for Outputs {
    fn try_value<T: Value>(&self, port: &str) -> Option<&T> {
        self.get(port).and_then(|v| v.as_any().downcast_ref::<T>())
    }

    fn value<T: Value>(&self, port: &str) -> &T {
        let Some(v) = self.get(port) else {
            let ports: Vec<&String> = self.values.keys().collect();
            panic!("no output `{port}` (the node gave {ports:?})");
        };
        v.as_any().downcast_ref::<T>().unwrap_or_else(|| {
            panic!(
                "output `{port}` is a {}, not a {}",
                v.type_name(),
                std::any::type_name::<T>()
            )
        })
    }

    fn scalar(&self, port: &str) -> f64 {
        self.value::<mesoflow_runtime::Scalar>(port).0
    }
}
