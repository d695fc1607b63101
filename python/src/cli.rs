//! `mesoflow.cli([...])`: the command line run inside the Python process (plan, watch, dot,
//! cache, … — whatever the `mesoflow` binary does), with the GIL released and Ctrl-C cancelling
//! the command as it would in a terminal (`wait`).

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

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
    let (code, interrupted) = crate::wait::run_interruptibly(
        py,
        "the command",
        move || mesoflow::run_embedded(&argv),
        mesoflow::cancel,
    )?;
    match interrupted {
        Some(e) => Err(e),
        None => Ok(code),
    }
}
