//! Sweeps started from the studio: the same grid, runs, `sweep.csv` and charts as `mesoflow
//! sweep` (through `sweep_table`), on the studio's engine and cache, with each row sent to the
//! browsers as it is measured. The files go under `<out-dir>/sweep`.

use super::session::{Problem, Refused, Studio};
use crate::sweep_table::{self, Vary};
use mesoflow_graph::{Override, PortRef};
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
    if spec.vary.is_empty() || spec.measure.is_empty() {
        return Err(refused(
            "a sweep needs at least one varied parameter and one measure",
        ));
    }
    let mut varies = Vec::new();
    for v in &spec.vary {
        let (node, param) = v
            .param
            .split_once('.')
            .ok_or_else(|| refused(format!("vary {}: expected id.param", v.param)))?;
        if v.values.is_empty() {
            return Err(refused(format!("vary {}: no values", v.param)));
        }
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
    if let Some(x) = versus.iter().find(|x| !measures.contains(x)) {
        return Err(refused(format!("versus {x}: measure it too")));
    }
    let base = studio.doc().file.clone();
    sweep_table::grid_size(&varies, sweep_table::MAX_RUNS).map_err(refused)?;
    let combos = sweep_table::cartesian(&varies);
    let mut graphs = Vec::new();
    for combo in &combos {
        let mut file = base.clone();
        for (v, value) in varies.iter().zip(combo) {
            file.apply(&Override {
                node: v.node.clone(),
                param: v.param.clone(),
                value: value.clone(),
            })
            .map_err(refused)?;
        }
        let g = mesoflow_graph::check(
            &studio.graph_path.display().to_string(),
            &file,
            studio.engine.registry(),
        )
        .map_err(|e| Refused {
            errors: e.errors.iter().map(Problem::of).collect(),
        })?;
        graphs.push(g);
    }
    let outputs = sweep_table::sweep_outputs(studio.engine.registry(), &graphs[0], &measures)
        .map_err(refused)?;
    let cancel = Arc::new(AtomicBool::new(false));
    let id = {
        let mut st = studio.sweep.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = &st.cancel {
            c.store(true, Ordering::SeqCst);
        }
        st.id += 1;
        st.running = true;
        st.total = combos.len();
        st.columns = varies
            .iter()
            .map(Vary::name)
            .chain(measures.iter().map(|m| m.to_string()))
            .collect();
        st.rows.clear();
        st.charts.clear();
        st.error = None;
        st.cancel = Some(cancel.clone());
        st.id
    };
    studio.hub.publish(
        "sweep_started",
        json!({ "sweep": id, "total": combos.len() }),
    );
    let studio = studio.clone();
    std::thread::spawn(move || {
        let out_dir = studio.out_dir.join("sweep");
        let measured_nodes = sweep_table::measured_nodes(&measures);
        let mut rows = Vec::new();
        for (i, (combo, graph)) in combos.iter().zip(&graphs).enumerate() {
            if cancel.load(Ordering::SeqCst) {
                break;
            }
            let run_dir = out_dir.join("runs").join(format!("{i:03}"));
            let mut opts = studio.options(&run_dir, cancel.clone());
            opts.outputs = outputs.clone();
            let report =
                match studio
                    .engine
                    .run(graph, &opts, Arc::new(mesoflow_runtime::SilentObserver))
                {
                    Ok(r) => r,
                    Err(e) => {
                        finish(&studio, id, Vec::new(), Some(e.to_string()));
                        return;
                    }
                };
            let _ = crate::commands::run::write_report(&report, &run_dir);
            let row = sweep_table::row_of(&report, combo.clone(), &measures, &measured_nodes);
            let cells: Vec<Value> = combo
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
            rows.push(row);
        }
        let result = sweep_table::write_all(
            &out_dir,
            &varies,
            &measures,
            &measured_nodes,
            &versus,
            &rows,
        );
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
