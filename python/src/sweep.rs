//! `sweep.csv` and the sweep charts for `mesoflow.sweep`, through the command line's own
//! module (`mesoflow::sweep`), so both front ends write the same files.

use mesoflow::sweep::{write_all, Row, Vary};
use mesoflow_graph::PortRef;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use serde_json::Value;
use std::path::PathBuf;

type PyRow = (String, Vec<Option<f64>>, Vec<Option<f64>>, f64, bool);

fn port(text: &str) -> PyResult<PortRef> {
    PortRef::parse(text)
        .ok_or_else(|| PyValueError::new_err(format!("{text:?}: expected \"node.port\"")))
}

/// Writes `sweep.csv` and the charts under `out_dir`. `varies` are ("node.param", JSON list of
/// values); each row is (JSON list of the values chosen, measures, seconds of each measured
/// node, run seconds, ok). Returns the charts that could not be drawn.
#[pyfunction]
pub fn write_sweep(
    out_dir: PathBuf,
    varies: Vec<(String, String)>,
    measures: Vec<String>,
    measured_nodes: Vec<String>,
    versus: Vec<String>,
    rows: Vec<PyRow>,
) -> PyResult<Vec<String>> {
    let json = |t: &str| -> PyResult<Value> {
        serde_json::from_str(t).map_err(|e| PyValueError::new_err(e.to_string()))
    };
    let varies = varies
        .iter()
        .map(|(name, values)| {
            let (node, param) = name.split_once('.').ok_or_else(|| {
                PyValueError::new_err(format!("{name:?}: expected \"node.param\""))
            })?;
            let values = match json(values)? {
                Value::Array(v) => v,
                other => vec![other],
            };
            Ok(Vary {
                node: node.into(),
                param: param.into(),
                values,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let rows = rows
        .into_iter()
        .map(|(values, measures, node_seconds, run_seconds, ok)| {
            let values = match json(&values)? {
                Value::Array(v) => v,
                other => vec![other],
            };
            Ok(Row {
                values,
                measures,
                node_seconds,
                run_seconds,
                ok,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let measures = measures
        .iter()
        .map(|m| port(m))
        .collect::<PyResult<Vec<_>>>()?;
    let versus = versus
        .iter()
        .map(|m| port(m))
        .collect::<PyResult<Vec<_>>>()?;
    write_all(
        &out_dir,
        &varies,
        &measures,
        &measured_nodes,
        &versus,
        &rows,
    )
    .map_err(|e| PyRuntimeError::new_err(format!("{}: {e}", out_dir.display())))
}
