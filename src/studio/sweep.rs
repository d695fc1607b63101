//! Sweeps started from the studio: the same `Sweep` as `mesoflow sweep` (`crate::sweep`: the
//! grid, the checks, the runs, `sweep.csv` and the charts), on the studio's engine and cache,
//! with each row sent to the browsers as it is measured. The files go under `<out-dir>/sweep`.

use super::session::{Problem, Refused, Studio};
use crate::sweep::{Refusal, Sweep, Vary, MAX_RUNS};
use mesoflow_graph::PortRef;
use serde::Deserialize;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Deserialize)]
pub struct VarySpec {
    /// `node.param`
    pub param: String,
    pub values: Vec<Value>,
}

#[derive(Deserialize)]
pub struct SweepSpec {
    pub vary: Vec<VarySpec>,
    /// `node.port` or `node.timing`
    pub measure: Vec<String>,
    #[serde(default)]
    pub versus: Vec<String>,
}

fn refused(m: impl Into<String>) -> Refused {
    Refused {
        errors: vec![Problem::plain(m)],
    }
}

fn port(text: &str, what: &str) -> Result<PortRef, Refused> {
    PortRef::parse(text).ok_or_else(|| refused(format!("{what} {text}: expected id.port")))
}

/// Checks the sweep (every combination must validate) and starts it; a sweep in progress is
/// cancelled.
pub fn start(studio: &Arc<Studio>, spec: SweepSpec) -> Result<u64, Refused> {
    let mut varies = Vec::new();
    for v in &spec.vary {
        let (node, param) = v
            .param
            .split_once('.')
            .ok_or_else(|| refused(format!("vary {}: expected id.param", v.param)))?;
        varies.push(Vary {
            node: node.into(),
            param: param.into(),
            values: v.values.clone(),
        });
    }
    let measures: Vec<PortRef> = spec
        .measure
        .iter()
        .map(|m| port(m, "measure"))
        .collect::<Result<_, _>>()?;
    let versus: Vec<PortRef> = spec
        .versus
        .iter()
        .map(|m| port(m, "versus"))
        .collect::<Result<_, _>>()?;
    let base = studio.doc().file.clone();
    let sweep = Sweep::prepare(
        &studio.graph_path.display().to_string(),
        &base,
        varies,
        measures,
        versus,
        MAX_RUNS,
        studio.engine.registry(),
    )
    .map_err(|r| match r {
        Refusal::Asked(m) | Refusal::Measure(_, m) => refused(m),
        Refusal::Graph(e) => Refused {
            errors: e.errors.iter().map(Problem::of).collect(),
        },
    })?;
    let cancel = Arc::new(AtomicBool::new(false));
    let total = sweep.combos.len();
    let id = {
        let mut st = studio.sweep.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = &st.cancel {
            c.store(true, Ordering::SeqCst);
        }
        st.id += 1;
        st.running = true;
        st.total = total;
        st.columns = sweep
            .varies
            .iter()
            .map(Vary::name)
            .chain(sweep.measures.iter().map(|m| m.to_string()))
            .collect();
        st.rows.clear();
        st.charts.clear();
        st.error = None;
        st.cancel = Some(cancel.clone());
        st.id
    };
    studio
        .hub
        .publish("sweep_started", json!({ "sweep": id, "total": total }));
    let studio = studio.clone();
    std::thread::spawn(move || {
        let out_dir = studio.out_dir.join("sweep");
        let options = |run_dir: &std::path::Path| studio.options(run_dir, cancel.clone());
        let rows = sweep.run(&studio.engine, &out_dir, options, |i, row, _| {
            let cells: Vec<Value> = row
                .values
                .iter()
                .cloned()
                .chain(row.measures.iter().map(|m| json!(m)))
                .collect();
            let row_json = json!({ "index": i, "cells": cells, "ok": row.ok,
                                   "seconds": row.run_seconds });
            {
                let mut st = studio.sweep.lock().unwrap_or_else(|e| e.into_inner());
                if st.id == id {
                    st.rows.push(row_json.clone());
                }
            }
            studio
                .hub
                .publish("sweep_row", json!({ "sweep": id, "row": row_json }));
        });
        let rows = match rows {
            Ok(rows) => rows,
            Err(e) => {
                finish(&studio, id, Vec::new(), Some(format!("{e:#}")));
                return;
            }
        };
        let result = sweep.write(&out_dir, &rows);
        let mut charts: Vec<String> = std::fs::read_dir(&out_dir)
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.ends_with(".svg"))
                    .map(|n| format!("sweep/{n}"))
                    .collect()
            })
            .unwrap_or_default();
        charts.sort();
        let error = match result {
            Ok(errors) => errors.first().cloned(),
            Err(e) => Some(e.to_string()),
        };
        finish(&studio, id, charts, error);
    });
    Ok(id)
}

fn finish(studio: &Studio, id: u64, charts: Vec<String>, error: Option<String>) {
    let mut st = studio.sweep.lock().unwrap_or_else(|e| e.into_inner());
    if st.id != id {
        return;
    }
    st.running = false;
    st.cancel = None;
    st.charts = charts.clone();
    st.error = error.clone();
    drop(st);
    studio.hub.publish(
        "sweep_done",
        json!({ "sweep": id, "charts": charts, "csv": "sweep/sweep.csv", "error": error }),
    );
}
