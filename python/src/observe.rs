//! Progress of a run from Python: the engine's events handed to a Python callable as
//! `callback(event, node, detail, done, total)`, with `event` one of "started" (detail: the
//! device), "progress" and "finished" (detail: the status). Progress is forwarded in steps of 5%
//! so that a node reporting every row does not take the GIL every row. A node's workers report
//! from several threads, so counts can arrive out of order: only a step past the highest one
//! forwarded goes through, which bounds the events to 21 a node (steps 0 to 20) under any load.

use mesoflow_runtime::{NodeReport, ProgressSteps, RunObserver};
use pyo3::prelude::*;

pub struct PyObserver {
    callback: Py<PyAny>,
    steps: ProgressSteps,
}

impl PyObserver {
    pub fn new(callback: Py<PyAny>) -> PyObserver {
        PyObserver {
            callback,
            steps: ProgressSteps::new(20),
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
        if !self.steps.admit(id, done, total) {
            return;
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
