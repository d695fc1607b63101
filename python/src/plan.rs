//! `mesoflow.plan(graph, render, budget=…)`: the planner library on a graph from Python, on the
//! same engine and cache as `Graph.run`. Returns the plan document (`<graph>.plan.json`'s fields) and
//! the planned graph's text; the Python layer makes them a `Plan` object. `plan_truth` is
//! `against="truth"`: every candidate, brute force included, judged against the truth the graph
//! makes (`mesoflow_plan::arbitrate`).

use crate::session::{device_mode, engine, parse_with_sets};
use mesoflow_graph::{check, GraphFile};
use mesoflow_plan::{
    arbitrate, plan_view, Budget, Measure, PlanError, ProbeOptions, Split, TruthOptions,
};
use mesoflow_runtime::RunOptions;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The engine (on `cache_dir`) with `file` checked against its kinds, and the options of a
/// plan's runs with their cancel flag: the session both planners share.
fn session(
    name: &str,
    file: &mesoflow_graph::GraphFile,
    base_dir: PathBuf,
    device: &str,
    cache_dir: Option<String>,
    use_cache: bool,
) -> PyResult<(Arc<mesoflow_runtime::Engine>, RunOptions, Arc<AtomicBool>)> {
    let engine = engine(cache_dir.as_deref());
    check(name, file, engine.registry())
        .map_err(|e| PyValueError::new_err(e.to_string().trim_end().to_string()))?;
    let cancel = Arc::new(AtomicBool::new(false));
    let policy = mesoflow_runtime::RunPolicy {
        device: device_mode(device)?,
        use_cache,
        cancel: cancel.clone(),
        ..Default::default()
    };
    let opts = RunOptions::new(name, base_dir, std::env::temp_dir(), policy);
    Ok((engine, opts, cancel))
}

/// Plans node `render` of the graph `text` for a FLIP `budget` at `ppd` pixels per degree
/// (FLIP's default 67 when `None`). Returns `(plan_json, planned_graph_json)`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (text, name, base_dir, render, budget, sets, ppd=None, split="joint", device="auto", cache_dir=None, use_cache=true, probe_budget=1.0, probe_share=0.25))]
pub fn plan(
    py: Python<'_>,
    text: &str,
    name: &str,
    base_dir: PathBuf,
    render: &str,
    budget: f64,
    sets: Vec<String>,
    ppd: Option<f64>,
    split: &str,
    device: &str,
    cache_dir: Option<String>,
    use_cache: bool,
    probe_budget: f64,
    probe_share: f64,
) -> PyResult<(String, String)> {
    if !(probe_budget.is_finite() && probe_budget >= 0.0) {
        return Err(PyValueError::new_err(format!(
            "probe_budget={probe_budget}: a number of renders ≥ 0"
        )));
    }
    if !(probe_share > 0.0 && probe_share <= 1.0) {
        return Err(PyValueError::new_err(format!(
            "probe_share={probe_share}: a fraction of the frame in (0, 1]"
        )));
    }
    let probe = (probe_budget > 0.0).then_some(ProbeOptions {
        share: probe_share,
        budget: probe_budget,
    });
    let file = flat(parse_with_sets(text, &sets, &base_dir)?)?;
    let split = match split {
        "joint" => Split::Joint,
        "equal" => Split::Equal,
        other => {
            return Err(PyValueError::new_err(format!(
                "split={other:?}: expected \"joint\" or \"equal\""
            )))
        }
    };
    let budget = Budget {
        flip: budget,
        ppd: ppd.unwrap_or(mesoflow_nodes::image::flip::DEFAULT_PPD),
    };
    let (engine, opts, cancel) = session(name, &file, base_dir, device, cache_dir, use_cache)?;
    let (name, render) = (name.to_string(), render.to_string());
    let worker = engine.clone();
    let planned = interruptible(
        py,
        move || plan_view(&worker, &name, &file, &render, budget, split, opts, probe),
        &cancel,
    )?;
    Ok((json_text(&planned.to_json())?, planned.plan.file.to_json()))
}

/// Plans node `render` of the graph `text` against the truth the graph makes, for a relative
/// RMSE `budget` (`mesoflow plan --against truth --budget rmse=B`), or with `measure="flip"` a
/// mean FLIP budget at `ppd` pixels per degree (FLIP's default without; `--budget flip=B --ppd
/// P`). Returns
/// `(plan_json, planned_graph_json)`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (text, name, base_dir, render, budget, sets, device="auto", cache_dir=None, use_cache=true, probe_share=0.1, measure="rmse", ppd=None))]
pub fn plan_truth(
    py: Python<'_>,
    text: &str,
    name: &str,
    base_dir: PathBuf,
    render: &str,
    budget: f64,
    sets: Vec<String>,
    device: &str,
    cache_dir: Option<String>,
    use_cache: bool,
    probe_share: f64,
    measure: &str,
    ppd: Option<f64>,
) -> PyResult<(String, String)> {
    if !(probe_share > 0.0 && probe_share <= 1.0) {
        return Err(PyValueError::new_err(format!(
            "probe_share={probe_share}: a fraction of the frame in (0, 1]"
        )));
    }
    if let Some(p) = ppd.filter(|p| !(p.is_finite() && *p >= 0.5)) {
        return Err(PyValueError::new_err(format!(
            "ppd={p}: pixels per degree, a number ≥ 0.5"
        )));
    }
    let measure = match measure {
        "rmse" => Measure::RelativeRmse,
        "flip" => Measure::Flip {
            ppd: ppd.unwrap_or(mesoflow_nodes::image::flip::DEFAULT_PPD),
        },
        m => {
            return Err(PyValueError::new_err(format!(
                "measure={m:?}: \"rmse\" or \"flip\""
            )))
        }
    };
    let file = flat(parse_with_sets(text, &sets, &base_dir)?)?;
    let (engine, opts, cancel) = session(name, &file, base_dir, device, cache_dir, use_cache)?;
    let (name, render) = (name.to_string(), render.to_string());
    let worker = engine.clone();
    let options = TruthOptions {
        budget,
        measure,
        share: probe_share,
    };
    let a = interruptible(
        py,
        move || arbitrate(&worker, &name, &file, &render, &opts, options),
        &cancel,
    )?;
    Ok((json_text(&a.to_json())?, a.planned.to_json()))
}

/// Runs a planner off the Python thread (Ctrl-C cancels it through `cancel` and is raised
/// once it stopped); a plan that cannot be made is a `ValueError`, a probe that failed a
/// `RuntimeError`.
fn interruptible<T: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce() -> Result<T, PlanError> + Send + 'static,
    cancel: &AtomicBool,
) -> PyResult<T> {
    let (result, interrupted) = crate::wait::run_interruptibly(py, "the plan", work, || {
        cancel.store(true, Ordering::Relaxed)
    })?;
    if let Some(e) = interrupted {
        return Err(e);
    }
    result.map_err(|e| match e {
        PlanError::Probe(_) => PyRuntimeError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    })
}

fn json_text(v: &serde_json::Value) -> PyResult<String> {
    serde_json::to_string(v).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// The planner edits nodes one by one: the graph with its subgraphs inlined, their nodes under
/// their paths.
fn flat(file: GraphFile) -> PyResult<GraphFile> {
    mesoflow_graph::subgraph::expand(&file)
        .map_err(|e| PyValueError::new_err(crate::session::errors_text(&e)))
}
