//! The environment variables the engine reads, checked once at start-up so a typo is an error
//! (exit 2) rather than a silently ignored setting, and the process set-up they imply.

use crate::exit::invalid;

/// More worker threads than this many per core only add scheduling overhead and memory.
const MAX_THREADS_PER_CORE: usize = 4;

pub fn check() -> anyhow::Result<()> {
    if let Ok(v) = std::env::var("MESOFLOW_MEMORY_BUDGET_GB") {
        match v.trim().parse::<f64>() {
            Ok(gb) if gb.is_finite() && gb > 0.0 => {}
            _ => {
                return Err(invalid(format!(
                    "MESOFLOW_MEMORY_BUDGET_GB={v}: expected a positive number of gigabytes"
                )))
            }
        }
    }
    if let Ok(v) = std::env::var("MESOFLOW_REQUIRE_GPU") {
        if !matches!(v.as_str(), "0" | "1" | "") {
            return Err(invalid(format!(
                "MESOFLOW_REQUIRE_GPU={v}: expected 0 or 1"
            )));
        }
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if let Ok(v) = std::env::var("RAYON_NUM_THREADS") {
        let asked: usize = v.trim().parse().map_err(|_| {
            invalid(format!(
                "RAYON_NUM_THREADS={v}: expected a number of threads"
            ))
        })?;
        let cap = cores * MAX_THREADS_PER_CORE;
        if asked > cap {
            eprintln!("warning: RAYON_NUM_THREADS={asked} on {cores} cores; using {cap} threads");
            // The first (and only) initialisation of the global pool; results do not depend on
            // the thread count, only the time does.
            let _ = rayon::ThreadPoolBuilder::new()
                .num_threads(cap)
                .build_global();
        }
    }
    Ok(())
}

/// Mesa's Vulkan device-select layer connects to a Wayland or X display to find the GPU driving
/// it, and prints `error: XDG_RUNTIME_DIR is invalid` on every headless run. mesoflow chooses its
/// adapter itself and draws nothing, so the layer is switched off unless the user set it.
pub fn quiet_vulkan_device_select() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // Called at start-up, before any thread exists.
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

/// Restores the default SIGPIPE action, so `mesoflow nodes | head` ends quietly like any Unix
/// tool instead of panicking on a closed pipe.
pub fn quiet_broken_pipes() {
    // SIG_DFL. Called once at start-up, before any thread exists.
    set_sigpipe(0);
}

/// Ignores SIGPIPE again, for the studio's server: with the default action a write to a socket
/// whose client has gone ends the process (the flood test found it); ignored, the write fails
/// with EPIPE, which the server handles by dropping the connection.
pub fn ignore_broken_pipes() {
    // SIG_IGN: valid at any time and in any thread; no handler runs.
    set_sigpipe(1);
}

/// Sets SIGPIPE's disposition to `SIG_DFL` (0) or `SIG_IGN` (1).
fn set_sigpipe(handler: usize) {
    #[cfg(unix)]
    {
        const SIGPIPE: i32 = 13;
        extern "C" {
            fn signal(signum: i32, handler: usize) -> usize;
        }
        // SAFETY: only SIG_DFL or SIG_IGN are passed, both always valid dispositions; neither
        // installs a handler.
        unsafe {
            signal(SIGPIPE, handler);
        }
    }
    #[cfg(not(unix))]
    let _ = handler;
}
