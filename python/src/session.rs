//! The process's engines and the functions the Python layer calls: the catalog of kinds,
//! validation, registering Python kinds, and runs.
//!
//! One engine per cache folder lives as long as the process, so runs from a notebook share the
//! memory cache as `watch` and `sweep` do. Registering a Python kind makes the next run use a
//! registry that has it; the new engine shares the old one's caches and GPU.

use crate::convert::to_python;
use crate::observe::PyObserver;
use crate::pynode::PyNode;
use mesoflow_graph::{check, parse_override, GraphFile, PortRef};
use mesoflow_runtime::cache::{default_memory_budget, DiskCache};
use mesoflow_runtime::{
    DeviceMode, DynNode, Engine, EngineConfig, Registry, RunObserver, RunOptions, RunOutcome,
    SilentObserver,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

struct State {
    python_kinds: BTreeMap<String, Arc<dyn DynNode>>,
    /// Bumped whenever a Python kind is (re)registered.
    generation: u64,
    /// By cache folder ("" without a disk cache): the engine and the generation it was built at.
    engines: BTreeMap<String, (u64, Arc<Engine>)>,
    /// The registry of the current generation (building one derives every kind's schema).
    registry: Option<(u64, Arc<Registry>)>,
}

fn state() -> MutexGuard<'static, State> {
    static STATE: Mutex<State> = Mutex::new(State {
        python_kinds: BTreeMap::new(),
        generation: 0,
        engines: BTreeMap::new(),
        registry: None,
    });
    // The state is a few maps replaced whole; a panic elsewhere cannot leave it half-updated.
    STATE.lock().unwrap_or_else(|e| e.into_inner())
}

fn registry(s: &mut State) -> Arc<Registry> {
    if let Some((g, r)) = &s.registry {
        if *g == s.generation {
            return r.clone();
        }
    }
    let mut r = mesoflow_nodes::registry::builtin();
    for node in s.python_kinds.values() {
        r.register_dyn(node.clone());
    }
    let r = Arc::new(r);
    s.registry = Some((s.generation, r.clone()));
    r
}

pub(crate) fn engine(cache_dir: Option<&str>) -> Arc<Engine> {
    let mut s = state();
    let name = cache_dir.unwrap_or("").to_string();
    let generation = s.generation;
    if let Some((g, e)) = s.engines.get(&name) {
        if *g == generation {
            return e.clone();
        }
    }
    let reg = Registry::clone(&registry(&mut s));
    let engine = match s.engines.get(&name) {
        Some((_, old)) => Arc::new(old.with_registry(reg)),
        None => Arc::new(Engine::new(
            reg,
            EngineConfig {
                memory_budget: default_memory_budget(),
                disk: cache_dir.map(DiskCache::new),
            },
        )),
    };
    s.engines.insert(name, (generation, engine.clone()));
    engine
}

/// One problem of a graph: (node, field, message).
type Problem = (Option<String>, Option<String>, String);

/// Every kind's signature (built-in and Python) as JSON text.
#[pyfunction]
pub fn catalog() -> PyResult<String> {
    let reg = registry(&mut state());
    let sigs: Vec<_> = reg.signatures().collect();
    serde_json::to_string(&sigs).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// Checks a graph file's text as `mesoflow validate` does. Returns the errors as
/// `(node, field, message)`; an empty list means the graph is valid.
#[pyfunction]
#[pyo3(signature = (text, name, base_dir=None))]
pub fn validate(text: &str, name: &str, base_dir: Option<PathBuf>) -> PyResult<Vec<Problem>> {
    let errors = match GraphFile::parse(text) {
        Err(errors) => errors,
        Ok(file) => {
            let file = match &base_dir {
                Some(dir) => file.in_folder(dir),
                None => file,
            };
            let reg = registry(&mut state());
            match check(name, &file, &*reg) {
                Ok(_) => Vec::new(),
                Err(e) => e.errors,
            }
        }
    };
    Ok(errors
        .iter()
        .map(|e| {
            (
                e.node().map(String::from),
                e.field().map(String::from),
                e.to_string(),
            )
        })
        .collect())
}

/// Registers (or replaces) a Python kind. `inputs` are (name, type, required), `outputs`
/// (name, type); `schema` and `defaults` are JSON texts.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (kind, version, doc, inputs, outputs, schema, defaults, source_hash, func, disk_cache=true))]
pub fn register_node(
    kind: &str,
    version: u32,
    doc: &str,
    inputs: Vec<(String, String, bool)>,
    outputs: Vec<(String, String)>,
    schema: &str,
    defaults: &str,
    source_hash: String,
    func: Py<PyAny>,
    disk_cache: bool,
) -> PyResult<()> {
    let builtin = mesoflow_nodes::registry::builtin();
    if builtin.node(kind).is_some() {
        return Err(PyValueError::new_err(format!(
            "kind `{kind}` is a built-in kind; give the Python node another name (e.g. user.{})",
            kind.rsplit('.').next().unwrap_or(kind)
        )));
    }
    // The value types the built-in kinds produce: the types a port can have.
    let known: std::collections::BTreeSet<String> = builtin
        .signatures()
        .flat_map(|s| s.outputs.iter().map(|o| o.ty.clone()))
        .collect();
    for (port, ty) in inputs
        .iter()
        .map(|(n, t, _)| (n, t))
        .chain(outputs.iter().map(|(n, t)| (n, t)))
    {
        if !known.contains(ty.as_str()) {
            let names: Vec<&str> = known.iter().map(String::as_str).collect();
            return Err(PyValueError::new_err(format!(
                "{kind}: port `{port}` has type `{ty}`; port types are {}",
                names.join(", ")
            )));
        }
    }
    for (port, ty) in &outputs {
        if !crate::convert::RETURNABLE.iter().any(|(t, _)| t == ty) {
            return Err(PyValueError::new_err(format!(
                "{kind}: output `{port}` is a {ty}; a Python node can return {}",
                crate::convert::RETURNABLE
                    .iter()
                    .map(|(t, _)| *t)
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    let schema: Value = serde_json::from_str(schema)
        .map_err(|e| PyValueError::new_err(format!("{kind}: schema: {e}")))?;
    let defaults: Map<String, Value> = serde_json::from_str(defaults)
        .map_err(|e| PyValueError::new_err(format!("{kind}: defaults: {e}")))?;
    let node = PyNode::new(
        kind,
        version,
        doc,
        inputs,
        outputs,
        schema,
        defaults,
        source_hash,
        func,
        disk_cache,
    );
    let mut s = state();
    s.python_kinds.insert(kind.to_string(), Arc::new(node));
    s.generation += 1;
    Ok(())
}

pub(crate) fn device_mode(device: &str) -> PyResult<DeviceMode> {
    match device {
        "auto" => Ok(DeviceMode::Auto),
        "cpu" => Ok(DeviceMode::Cpu),
        "gpu" => Ok(DeviceMode::Gpu),
        other => Err(PyValueError::new_err(format!(
            "device={other:?}: expected \"auto\", \"cpu\" or \"gpu\""
        ))),
    }
}

/// Graph errors as one message, a line each.
pub(crate) fn errors_text(errors: &[mesoflow_graph::GraphError]) -> String {
    errors
        .iter()
        .map(|e| e.to_string())
        .collect::<Vec<_>>()
        .join("\n")
}

/// A graph file's text with `sets` ("id.param=value") applied; errors as `ValueError`.
/// Relative paths and subgraphs in it resolve against `base_dir`.
pub(crate) fn parse_with_sets(
    text: &str,
    sets: &[String],
    base_dir: &std::path::Path,
) -> PyResult<GraphFile> {
    let file = GraphFile::parse(text).map_err(|e| PyValueError::new_err(errors_text(&e)))?;
    let mut file = file.in_folder(base_dir);
    for s in sets {
        let o = parse_override(s).map_err(|e| PyValueError::new_err(format!("set {e}")))?;
        file.apply(&o).map_err(PyValueError::new_err)?;
    }
    Ok(file)
}

/// Runs a graph (its file text). Relative input paths resolve against `base_dir`, files are
/// written under `out_dir` with `report.json`, exactly as `mesoflow run` writes them. Returns
/// the report as JSON text and the requested values by "node.port" (every output of the sinks
/// when `outputs` is empty). The GIL is released while the engine runs; Ctrl-C cancels the run
/// and raises KeyboardInterrupt once the engine has stopped.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (text, name, base_dir, out_dir, outputs, sets, device="auto", cache_dir=None, use_cache=true, verify_cache=false, progress=None))]
pub fn run<'py>(
    py: Python<'py>,
    text: &str,
    name: &str,
    base_dir: PathBuf,
    out_dir: PathBuf,
    outputs: Vec<String>,
    sets: Vec<String>,
    device: &str,
    cache_dir: Option<String>,
    use_cache: bool,
    verify_cache: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<(String, Bound<'py, PyDict>)> {
    let file = parse_with_sets(text, &sets, &base_dir)?;
    let engine = engine(cache_dir.as_deref());
    let graph = check(name, &file, engine.registry())
        .map_err(|e| PyValueError::new_err(e.to_string().trim_end().to_string()))?;
    let cancel = Arc::new(AtomicBool::new(false));
    let policy = mesoflow_runtime::RunPolicy {
        device: device_mode(device)?,
        use_cache,
        verify_cache,
        cancel: cancel.clone(),
        ..Default::default()
    };
    let mut opts = RunOptions::new(name, base_dir, out_dir.clone(), policy);
    opts.outputs = outputs
        .iter()
        .map(|o| {
            PortRef::parse(o).ok_or_else(|| {
                PyValueError::new_err(format!("output {o:?}: expected \"node.port\""))
            })
        })
        .collect::<PyResult<_>>()?;
    let requested = opts.outputs.clone();

    let worker = engine.clone();
    let (result, interrupted) = crate::wait::run_interruptibly(
        py,
        "the run",
        move || {
            let observer: Arc<dyn RunObserver> = match progress {
                Some(callback) => Arc::new(PyObserver::new(callback)),
                None => Arc::new(SilentObserver),
            };
            worker.run_values(&graph, &opts, observer)
        },
        || cancel.store(true, Ordering::Relaxed),
    )?;
    let RunOutcome { report, values } = result.map_err(|e| PyValueError::new_err(e.to_string()))?;
    let report_text = serde_json::to_string_pretty(&report)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    std::fs::create_dir_all(&out_dir)
        .and_then(|()| std::fs::write(out_dir.join("report.json"), format!("{report_text}\n")))
        .map_err(|e| {
            PyRuntimeError::new_err(format!(
                "writing {}: {e}",
                out_dir.join("report.json").display()
            ))
        })?;
    if let Some(e) = interrupted {
        return Err(e);
    }
    let out = PyDict::new(py);
    for (node, outs) in &values {
        for (port, v) in &outs.values {
            let wanted = requested.is_empty()
                || requested.iter().any(|r| r.node == *node && r.port == *port);
            if wanted {
                out.set_item(format!("{node}.{port}"), to_python(py, v)?)?;
            }
        }
    }
    Ok((report_text, out))
}
