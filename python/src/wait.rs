//! Engine work off the Python thread: it runs on a thread of its own while the caller waits
//! without the GIL (other Python threads, and Python nodes, go on), waking every 50 ms to let
//! Python see signals. Ctrl-C calls `on_interrupt` (which cancels the work) once, and the wait
//! goes on until the work has stopped; the interrupt is handed back for the caller to raise.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::mpsc::RecvTimeoutError;
use std::sync::Mutex;
use std::time::Duration;

pub fn run_interruptibly<T: Send + 'static>(
    py: Python<'_>,
    name: &str,
    work: impl FnOnce() -> T + Send + 'static,
    on_interrupt: impl Fn(),
) -> PyResult<(T, Option<PyErr>)> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let _ = tx.send(work());
        })
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start {name}: {e}")))?;
    // `detach` needs what it borrows to be shareable; the receiver is used by this thread only.
    let rx = Mutex::new(rx);
    let mut interrupted = None;
    loop {
        let next = py.detach(|| {
            rx.lock()
                .unwrap_or_else(|e| e.into_inner())
                .recv_timeout(Duration::from_millis(50))
        });
        match next {
            Ok(value) => return Ok((value, interrupted)),
            Err(RecvTimeoutError::Timeout) => {
                if interrupted.is_none() {
                    if let Err(e) = py.check_signals() {
                        on_interrupt();
                        interrupted = Some(e);
                    }
                }
            }
            Err(RecvTimeoutError::Disconnected) => {
                return Err(PyRuntimeError::new_err(format!(
                    "{name} stopped without a result"
                )))
            }
        }
    }
}
