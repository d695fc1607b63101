//! A node's panic is the node's failure: the run's report and error carry its message, so the
//! default hook's "thread '…' panicked at …" on stderr is left out for panics inside a node's run
//! (on its thread, or on a rayon worker it handed work to). A panic anywhere else still reaches
//! the hook that was installed before (the default one prints it).

use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Once;

thread_local!(static IN_NODE: Cell<bool> = const { Cell::new(false) });
static INSTALL: Once = Once::new();

/// Runs a node's `f`, its panic caught and kept off stderr.
pub(crate) fn catching<T>(f: impl FnOnce() -> T) -> std::thread::Result<T> {
    INSTALL.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if quiet_here() {
                tracing::debug!("a node panicked (its failure carries the message): {info}");
            } else {
                previous(info);
            }
        }));
    });
    let was = IN_NODE.with(|c| c.replace(true));
    let result = catch_unwind(AssertUnwindSafe(f));
    IN_NODE.with(|c| c.set(was));
    result
}

/// Whether a panic on this thread is a node's: inside [`catching`], or on a rayon worker (the
/// nodes are the pool's only users: the scheduler runs them there and they split their work
/// there; a worker's panic comes back to the node that split it).
fn quiet_here() -> bool {
    IN_NODE.with(Cell::get) || rayon::current_thread_index().is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_inside_is_caught_and_kept_quiet_and_one_outside_is_not() {
        let r = catching(|| -> u32 { panic!("boom") });
        assert!(r.is_err());
        assert!(!quiet_here(), "outside a node, on the test's own thread");
        let inside = catching(quiet_here);
        assert_eq!(inside.ok(), Some(true));
        // Nested, the outer scope stays a node's after the inner one ends.
        let nested = catching(|| {
            let _ = catching(|| 1);
            quiet_here()
        });
        assert_eq!(nested.ok(), Some(true));
        assert!(!quiet_here());
    }
}
