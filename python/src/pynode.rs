//! Node kinds written in Python (`@mesoflow.node`): a Python callable behind the engine's
//! `DynNode` face. Its cache key holds the kind's version and a hash of the function's source
//! (in the canonical parameters), so editing the function recomputes it; it runs on the CPU lane,
//! holding the GIL only while the function runs; an exception becomes the node's error.
//! Cancellation reaches the function: when the run is cancelled (Ctrl-C) while it runs, a
//! `KeyboardInterrupt` is raised in its thread (`PyThreadState_SetAsyncExc`), which stops Python
//! code at its next bytecode (a call blocked inside C returns first), and the node reports
//! `cancelled`.

use crate::convert::{from_python, to_python};
use mesoflow_graph::{DevicePreference, InputSpec, KindSignature, OutputSpec, TypeSet};
use mesoflow_runtime::{
    DynNode, Inputs, NodeContext, NodeError, NodeSpec, Outputs, Port, Prepared,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

pub struct PyNode {
    spec: NodeSpec,
    signature: KindSignature,
    /// Called as `func(inputs: dict, params: dict)`; returns `(outputs: dict, warnings: list)`.
    func: Py<PyAny>,
    defaults: Map<String, Value>,
    source_hash: String,
}

/// Strings of a kind's spec live as long as the process: a notebook that redefines a node a few
/// times keeps a few short strings more.
fn leak(s: &str) -> &'static str {
    Box::leak(s.to_string().into_boxed_str())
}

impl PyNode {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        kind: &str,
        version: u32,
        doc: &str,
        inputs: Vec<(String, String, bool)>,
        outputs: Vec<(String, String)>,
        schema: Value,
        defaults: Map<String, Value>,
        source_hash: String,
        func: Py<PyAny>,
        disk_cache: bool,
    ) -> PyNode {
        let port = |name: &str, ty: &str, required: bool| Port {
            name: leak(name),
            ty: TypeSet::one(ty),
            required,
            doc: "",
        };
        let spec = NodeSpec {
            kind: leak(kind),
            version,
            doc: leak(doc),
            device: DevicePreference::Cpu,
            inputs: inputs.iter().map(|(n, t, r)| port(n, t, *r)).collect(),
            outputs: outputs.iter().map(|(n, t)| port(n, t, true)).collect(),
            disk_cache,
        };
        let signature = KindSignature {
            kind: kind.into(),
            version,
            device: DevicePreference::Cpu,
            doc: doc.into(),
            inputs: inputs
                .iter()
                .map(|(n, t, r)| InputSpec {
                    name: n.clone(),
                    ty: TypeSet::one(t),
                    required: *r,
                    doc: String::new(),
                })
                .collect(),
            outputs: outputs
                .iter()
                .map(|(n, t)| OutputSpec {
                    name: n.clone(),
                    ty: t.clone(),
                    doc: String::new(),
                })
                .collect(),
            params: schema,
            timings: Vec::new(),
        };
        PyNode {
            spec,
            signature,
            func,
            defaults,
            source_hash,
        }
    }
}

/// The last frame of a Python traceback and the exception, for a node error that says where.
fn describe(py: Python<'_>, e: &PyErr) -> String {
    let kind = e
        .get_type(py)
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "exception".into());
    let mut text = format!("{kind}: {}", e.value(py));
    if let Some(tb) = e.traceback(py) {
        if let Ok(formatted) = tb.format() {
            let frames: Vec<&str> = formatted
                .lines()
                .filter(|l| l.trim_start().starts_with("File "))
                .collect();
            if let Some(last) = frames.last() {
                text.push_str(&format!(" ({})", last.trim()));
            }
        }
    }
    text
}

impl DynNode for PyNode {
    fn spec(&self) -> &NodeSpec {
        &self.spec
    }
    fn signature(&self) -> &KindSignature {
        &self.signature
    }
    fn prepare(&self, params: &Map<String, Value>) -> Result<Prepared, NodeError> {
        let problems = mesoflow_graph::params::check_params(
            "",
            self.spec.kind,
            &self.signature.params,
            params,
        );
        if let Some(p) = problems.first() {
            let param = p.field().unwrap_or("params").to_string();
            return Err(NodeError::Param {
                param,
                message: p.to_string(),
            });
        }
        let mut merged = self.defaults.clone();
        for (k, v) in params {
            merged.insert(k.clone(), v.clone());
        }
        let canonical = serde_json::json!({ "params": merged, "source": self.source_hash });
        Ok(Prepared::new(Box::new(merged), canonical))
    }
    fn files(&self, _: &Prepared, _: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(Vec::new())
    }
    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[]
    }
    fn run(&self, ctx: &NodeContext, p: &Prepared, inputs: &Inputs) -> Result<Outputs, NodeError> {
        ctx.check_cancel()?;
        let params = p
            .params()
            .downcast_ref::<Map<String, Value>>()
            .ok_or_else(|| NodeError::Failed("internal: parameters of another kind".into()))?;
        let params_text = serde_json::to_string(params)
            .map_err(|e| NodeError::Failed(format!("parameters: {e}")))?;
        Python::attach(|py| -> Result<Outputs, NodeError> {
            let py_err = |e: PyErr| NodeError::Failed(describe(py, &e));
            let args = PyDict::new(py);
            for port in &self.spec.inputs {
                if let Ok(v) = inputs.value(port.name) {
                    let value = to_python(py, v)
                        .map_err(|e| NodeError::input(port.name, describe(py, &e)))?;
                    args.set_item(port.name, value).map_err(py_err)?;
                }
            }
            let json = py.import("json").map_err(py_err)?;
            let params = json.call_method1("loads", (params_text,)).map_err(py_err)?;
            let result = call_cancellable(py, ctx, self.func.bind(py), (args, params));
            let result = match result {
                Err(_) if ctx.is_cancelled() => return Err(NodeError::Cancelled),
                r => r.map_err(py_err)?,
            };
            let (values, warnings) = result
                .cast::<PyTuple>()
                .ok()
                .filter(|t| t.len() == 2)
                .and_then(|t| Some((t.get_item(0).ok()?, t.get_item(1).ok()?)))
                .ok_or_else(|| {
                    NodeError::Failed("internal: the wrapper returned no pair".into())
                })?;
            if let Ok(list) = warnings.extract::<Vec<String>>() {
                for w in list {
                    ctx.warn(w);
                }
            }
            let values = values.cast::<PyDict>().map_err(|_| {
                NodeError::Failed("internal: the wrapper returned no dict of outputs".into())
            })?;
            let mut out = Outputs::new();
            for port in &self.spec.outputs {
                let item = values.get_item(port.name).map_err(py_err)?.ok_or_else(|| {
                    NodeError::Failed(format!("the function returned no output `{}`", port.name))
                })?;
                let v = from_python(&item, &port.ty.to_string())
                    .map_err(|m| NodeError::Failed(format!("output `{}`: {m}", port.name)))?;
                out.values.insert(port.name.to_string(), v);
            }
            Ok(out)
        })
    }
}

/// Calls `func(args)` on this thread, watching the run's cancel flag from another: once it is
/// set, a `KeyboardInterrupt` is raised in this thread asynchronously. An interrupt that was
/// raised but not yet delivered when the call returned is withdrawn, so it never lands in
/// Python code run later on this thread.
fn call_cancellable<'py>(
    py: Python<'py>,
    ctx: &NodeContext,
    func: &Bound<'py, PyAny>,
    args: (Bound<'py, PyDict>, Bound<'py, PyAny>),
) -> PyResult<Bound<'py, PyAny>> {
    use std::sync::atomic::{AtomicBool, Ordering};
    // SAFETY: reads this thread's identifier; the GIL is held (`py`).
    let ident = unsafe { pyo3::ffi::PyThread_get_thread_ident() } as std::os::raw::c_long;
    let (done, fired) = (AtomicBool::new(false), AtomicBool::new(false));
    std::thread::scope(|scope| {
        let watcher = scope.spawn(|| {
            while !done.load(Ordering::Acquire) {
                if ctx.is_cancelled() {
                    Python::attach(|_| {
                        if !done.load(Ordering::Acquire) {
                            // SAFETY: the GIL is held; the exception object is a static type.
                            unsafe {
                                pyo3::ffi::PyThreadState_SetAsyncExc(
                                    ident,
                                    pyo3::ffi::PyExc_KeyboardInterrupt,
                                );
                            }
                            fired.store(true, Ordering::Release);
                        }
                    });
                    return;
                }
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        });
        let result = func.call1(args);
        done.store(true, Ordering::Release);
        // The watcher may be waiting for the GIL: wait for it without holding it.
        let _ = py.detach(|| watcher.join());
        if fired.load(Ordering::Acquire) {
            // SAFETY: the GIL is held; a null exception withdraws a pending one.
            unsafe {
                pyo3::ffi::PyThreadState_SetAsyncExc(ident, std::ptr::null_mut());
            }
        }
        result
    })
}
