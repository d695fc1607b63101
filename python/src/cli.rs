//! `mesoflow.cli([...])`: the command line run inside the Python process (plan, watch, dot,
//! cache, … — whatever the `mesoflow` binary does), with the GIL released and Ctrl-C cancelling
//! the command as it would in a terminal.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Duration;

/// Runs `mesoflow ARGS…` and returns its exit code; its output goes to the process's stdout and
/// stderr. Ctrl-C cancels the command, then raises KeyboardInterrupt.
#[pyfunction]
pub fn cli(py: Python<'_>, args: Vec<String>) -> PyResult<i32> {
    // One command at a time: the command line keeps one cancellation flag for the process.
    static BUSY: AtomicBool = AtomicBool::new(false);
    if BUSY.swap(true, Ordering::SeqCst) {
        return Err(PyRuntimeError::new_err(
            "another mesoflow.cli command is running in this process; wait for it",
        ));
    }
    struct Done;
    impl Drop for Done {
        fn drop(&mut self) {
            BUSY.store(false, Ordering::SeqCst);
        }
    }
    let _done = Done;
    let mut argv = vec!["mesoflow".to_string()];
    argv.extend(args);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("mesoflow-cli".into())
        .spawn(move || {
            let _ = tx.send(mesoflow::run_embedded(&argv));
        })
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the command: {e}")))?;
    let rx = Mutex::new(rx);
    let mut interrupted = None;
    loop {
        let next = py.detach(|| {
            rx.lock()
                .unwrap_or_else(|e| e.into_inner())
                .recv_timeout(Duration::from_millis(50))
        });
        match next {
            Ok(code) => {
                return match interrupted {
                    Some(e) => Err(e),
                    None => Ok(code),
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                if interrupted.is_none() {
                    if let Err(e) = py.check_signals() {
                        mesoflow::cancel();
                        interrupted = Some(e);
                    }
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(PyRuntimeError::new_err(
                    "the command stopped without an exit code",
                ))
            }
        }
    }
}
