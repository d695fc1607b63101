//! `mesoflow.sweep` through the command line's own [`Sweep`]: the same grid, the same checks
//! before any run, the same runs on one engine and the same `sweep.csv` and charts. The GIL is
//! released while it runs; Ctrl-C stops it before the next run.

use crate::session::{device_mode, engine, parse_with_sets};
use mesoflow::sweep::{Refusal, Sweep, Vary};
use mesoflow_graph::{GraphFile, PortRef};
use mesoflow_runtime::{RunOptions, RunPolicy};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// One row: the values chosen (JSON text of a list), the measures, each measured node's
/// seconds, the run's seconds and whether it ran.
type PyRow = (String, Vec<Option<f64>>, Vec<Option<f64>>, f64, bool);

/// What the sweep hands back: the varied names, the measured nodes, the rows and the charts
/// that could not be drawn.
type Swept = (Vec<String>, Vec<String>, Vec<PyRow>, Vec<String>);

/// (node, field, message): how a refusal reaches Python's `GraphError`.
type Problem = (Option<String>, Option<String>, String);

fn port(text: &str, what: &str) -> PyResult<PortRef> {
    PortRef::parse(text)
        .ok_or_else(|| PyValueError::new_err(format!("{what} {text:?}: expected \"node.port\"")))
}

fn varies(varies: &[(String, String)]) -> PyResult<Vec<Vary>> {
    varies
        .iter()
        .map(|(name, values)| {
            let (node, param) = name.split_once('.').ok_or_else(|| {
                PyValueError::new_err(format!("vary {name:?}: expected \"node.param\""))
            })?;
            let values = match serde_json::from_str(values)
                .map_err(|e| PyValueError::new_err(format!("vary {name}: {e}")))?
            {
                Value::Array(v) => v,
                other => vec![other],
            };
            Ok(Vary {
                node: node.into(),
                param: param.into(),
                values,
            })
        })
        .collect()
}

/// Runs the sweep of the graph file `text` (named `name`, inputs relative to `base_dir`, `sets`
/// applied first) over `vary` (("node.param", JSON list of values)), measuring `measures`,
/// into `out_dir`. Returns the varied parameters' names, the measured nodes, the rows and the
/// charts that could not be drawn. A refused sweep raises `ValueError(message, problems)`:
/// `problems` is a list of (node, field, message) for a graph or measure at fault, empty for a
/// mistake in what was asked (a value list, the grid's size).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (text, name, base_dir, out_dir, vary, measures, versus, sets, max_runs, device="auto", cache_dir=None, use_cache=true, progress=true))]
pub fn sweep(
    py: Python<'_>,
    text: &str,
    name: &str,
    base_dir: PathBuf,
    out_dir: PathBuf,
    vary: Vec<(String, String)>,
    measures: Vec<String>,
    versus: Vec<String>,
    sets: Vec<String>,
    max_runs: usize,
    device: &str,
    cache_dir: Option<String>,
    use_cache: bool,
    progress: bool,
) -> PyResult<Swept> {
    let file: GraphFile = parse_with_sets(text, &sets, &base_dir)?;
    let engine = engine(cache_dir.as_deref());
    // A subgraph's exposed output (`p.y`) is measured as the inner output it names.
    let measures = measures
        .iter()
        .map(|m| port(m, "measure"))
        .collect::<PyResult<Vec<_>>>()?;
    let versus = versus
        .iter()
        .map(|m| port(m, "versus"))
        .collect::<PyResult<Vec<_>>>()?;
    let measures = mesoflow_graph::subgraph::through_all(&file, measures);
    let versus = mesoflow_graph::subgraph::through_all(&file, versus);
    let sweep = Sweep::prepare(
        name,
        &file,
        varies(&vary)?,
        measures,
        versus,
        max_runs,
        engine.registry(),
    )
    .map_err(refused)?;
    let cancel = Arc::new(AtomicBool::new(false));
    let policy = RunPolicy {
        device: device_mode(device)?,
        use_cache,
        cancel: cancel.clone(),
        ..Default::default()
    };
    let (name, out) = (name.to_string(), out_dir.clone());
    let ((sweep, result), interrupted) = crate::wait::run_interruptibly(
        py,
        "the sweep",
        move || {
            let options = |run_dir: &Path| {
                RunOptions::new(
                    &name,
                    base_dir.clone(),
                    run_dir.to_path_buf(),
                    policy.clone(),
                )
            };
            let result = sweep.run(&engine, &out, options, |i, row, _| {
                if progress {
                    eprintln!("{}", sweep.progress_line(i, row));
                }
            });
            (sweep, result)
        },
        || cancel.store(true, Ordering::Relaxed),
    )?;
    let rows = result.map_err(|e| PyRuntimeError::new_err(format!("{e:#}")))?;
    let problems = sweep
        .write(&out_dir, &rows)
        .map_err(|e| PyRuntimeError::new_err(format!("{}: {e}", out_dir.display())))?;
    if let Some(e) = interrupted {
        return Err(e);
    }
    let names = sweep.varies.iter().map(Vary::name).collect();
    let rows = rows
        .into_iter()
        .map(|r| {
            (
                Value::Array(r.values).to_string(),
                r.measures,
                r.node_seconds,
                r.run_seconds,
                r.ok,
            )
        })
        .collect();
    Ok((names, sweep.measured_nodes, rows, problems))
}

fn refused(r: Refusal) -> PyErr {
    let problems: Vec<Problem> = match &r {
        Refusal::Asked(_) => Vec::new(),
        Refusal::Measure(m, message) => vec![(
            Some(m.node.clone()),
            Some(m.port.clone()),
            message.replacen("--measure", "measure", 1),
        )],
        Refusal::Graph(e) => e
            .errors
            .iter()
            .map(|e| {
                (
                    e.node().map(String::from),
                    e.field().map(String::from),
                    e.to_string(),
                )
            })
            .collect(),
    };
    let message = match &r {
        Refusal::Measure(_, m) => m.replacen("--measure", "measure", 1),
        other => other.to_string(),
    };
    PyValueError::new_err((message, problems))
}
