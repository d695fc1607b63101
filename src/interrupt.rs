//! Ctrl-C. The first press cancels the run: running nodes stop at their next check and the run
//! ends with its normal report (status `cancelled`, exit 130). A second press ends the process at
//! once; it still writes `report.json` first, with the nodes that had finished, so a script that
//! reads the report always finds one.

use crate::exit;
use mesoflow_runtime::{NodeReport, RunObserver, RunReport, Warning};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

/// What a report written on a second Ctrl-C can say: the run in progress.
struct InFlight {
    graph: String,
    out_dir: PathBuf,
    started: Instant,
    finished: Vec<NodeReport>,
}

fn in_flight() -> &'static Mutex<Option<InFlight>> {
    static RUN: OnceLock<Mutex<Option<InFlight>>> = OnceLock::new();
    RUN.get_or_init(|| Mutex::new(None))
}

/// Set when the command line runs inside another program (the Python package's `mesoflow.cli`):
/// Ctrl-C is then the host's to handle, and it cancels through [`cancel_flag`] itself.
static EMBEDDED: AtomicBool = AtomicBool::new(false);

pub fn set_embedded() {
    EMBEDDED.store(true, Ordering::SeqCst);
}

/// The run's cancellation flag, set by the first Ctrl-C.
pub fn cancel_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        if EMBEDDED.load(Ordering::SeqCst) {
            return flag;
        }
        let f = flag.clone();
        let _ = ctrlc::set_handler(move || {
            if f.swap(true, Ordering::SeqCst) {
                write_abandoned_report();
                std::process::exit(exit::CANCELLED);
            }
            eprintln!("\ncancelling: waiting for running nodes to stop (Ctrl-C again to quit now)");
        });
        flag
    })
    .clone()
}

fn write_abandoned_report() {
    let guard = in_flight().lock().unwrap_or_else(|e| e.into_inner());
    let Some(run) = guard.as_ref() else {
        return;
    };
    let report = RunReport {
        mesoflow: 1,
        version: env!("CARGO_PKG_VERSION").into(),
        graph: run.graph.clone(),
        adapter: None,
        ok: false,
        seconds: run.started.elapsed().as_secs_f64(),
        nodes: run.finished.clone(),
        warnings: vec![Warning {
            expected: false,
            node: String::new(),
            message: "interrupted twice: nodes still running were abandoned, and are missing \
                      from this report"
                .into(),
        }],
        skipped: Vec::new(),
        files: Vec::new(),
        cancelled: true,
        read: Vec::new(),
        earlier: Vec::new(),
    };
    if let Ok(text) = serde_json::to_string_pretty(&report) {
        let _ = mesoflow_runtime::write_atomic(&run.out_dir.join("report.json"), text + "\n");
    }
}

/// Forwards to `inner` and remembers finished nodes for a report on a second Ctrl-C.
pub struct Recording {
    inner: Arc<dyn RunObserver>,
}

impl Recording {
    /// Starts recording a run of `graph` into `out_dir`.
    pub fn start(graph: &str, out_dir: PathBuf, inner: Arc<dyn RunObserver>) -> Recording {
        *in_flight().lock().unwrap_or_else(|e| e.into_inner()) = Some(InFlight {
            graph: graph.into(),
            out_dir,
            started: Instant::now(),
            finished: Vec::new(),
        });
        Recording { inner }
    }
}

impl RunObserver for Recording {
    fn node_started(&self, id: &str, kind: &str, device: &str) {
        self.inner.node_started(id, kind, device);
    }
    fn progress(&self, id: &str, done: u64, total: u64) {
        self.inner.progress(id, done, total);
    }
    fn node_finished(&self, report: &NodeReport) {
        if let Some(run) = in_flight()
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_mut()
        {
            run.finished.push(report.clone());
        }
        self.inner.node_finished(report);
    }
}
