//! Progress of a run from Python: the engine's events handed to a Python callable as
//! `callback(event, node, detail, done, total)`, with `event` one of "started" (detail: the
//! device), "progress" and "finished" (detail: the status). Progress is forwarded in steps of 5%
//! so that a node reporting every row does not take the GIL every row.

use mesoflow_runtime::{NodeReport, RunObserver};
use pyo3::prelude::*;
use std::collections::HashMap;
use std::sync::Mutex;

pub struct PyObserver {
    callback: Py<PyAny>,
    last: Mutex<HashMap<String, u64>>,
}

impl PyObserver {
    pub fn new(callback: Py<PyAny>) -> PyObserver {
        PyObserver {
            callback,
            last: Mutex::new(HashMap::new()),
        }
    }

    fn send(&self, event: &str, node: &str, detail: &str, done: u64, total: u64) {
        Python::attach(|py| {
            // A failing callback must not fail the run: Python prints it as unraisable.
            if let Err(e) = self
                .callback
                .bind(py)
                .call1((event, node, detail, done, total))
            {
                e.write_unraisable(py, None);
            }
        });
    }
}

impl RunObserver for PyObserver {
    fn node_started(&self, id: &str, _kind: &str, device: &str) {
        self.send("started", id, device, 0, 0);
    }
    fn progress(&self, id: &str, done: u64, total: u64) {
        let step = (done.saturating_mul(20)) / total.max(1);
        {
            let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
            let seen = last.entry(id.to_string()).or_insert(u64::MAX);
            if *seen == step {
                return;
            }
            *seen = step;
        }
        self.send("progress", id, "", done, total);
    }
    fn node_finished(&self, report: &NodeReport) {
        let status = serde_json::to_value(report.status)
            .ok()
            .and_then(|v| v.as_str().map(String::from))
            .unwrap_or_default();
        self.send("finished", &report.id, &status, 0, 0);
    }
}
