//! `mesoflow serve GRAPH`: the studio, a single-page app in the browser on the same engine and
//! cache as `run`. The page (HTML, CSS, JS in `assets/`, embedded in the binary) shows the graph,
//! edits parameters through the validator, re-runs only what a change made dirty with live
//! status, previews every value type and runs sweeps.
//!
//! Safety: the server listens on 127.0.0.1 unless told otherwise, every request needs the random
//! token printed with the URL, the Host header must name this server (no DNS rebinding), and no
//! file outside the graph's folder, the output folder and the cache is read or written through
//! it. The server (`server.rs`, hyper) bounds what a request may cost before it is admitted:
//! head size, head and body time, body size, connections.

mod api;
mod events;
mod plan;
mod plan_state;
mod preview;
mod server;
mod session;
mod sweep;
mod sweep_state;

use crate::args::ServeArgs;
use crate::session::{cache_dir, device_mode, engine, graph_name};
use session::Studio;
use std::hash::{BuildHasher, Hasher};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

/// 128 random bits as hex: each `RandomState` is seeded by the operating system's randomness.
fn random_token() -> String {
    let word = || {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u128(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or_default(),
        );
        h.finish()
    };
    format!("{:016x}{:016x}", word(), word())
}

pub fn serve(args: &ServeArgs) -> anyhow::Result<i32> {
    crate::env::ignore_broken_pipes();
    let engine = engine(&args.cache, &args.graph)?;
    let out_dir = args
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(graph_name(&args.graph)));
    let cache = (!args.cache.no_cache).then(|| cache_dir(&args.cache, &args.graph));
    let mut studio = Studio::new(
        args.graph.clone(),
        out_dir,
        cache,
        engine,
        device_mode(args.device),
    )?;
    studio.verify_cache = args.cache.verify_cache;
    let studio = Arc::new(studio);
    let listener = std::net::TcpListener::bind((args.host.as_str(), args.port)).map_err(|e| {
        crate::exit::invalid(format!("cannot listen on {}:{}: {e}", args.host, args.port))
    })?;
    let port = listener.local_addr().map(|a| a.port()).unwrap_or(args.port);
    let token = random_token();
    let shown_host = if args.host == "0.0.0.0" {
        "127.0.0.1"
    } else {
        &args.host
    };
    let url = format!("http://{shown_host}:{port}/?token={token}");
    println!("mesoflow studio on {}: {url}", args.graph.display());
    println!("(Ctrl-C to stop; the token in the URL is required by every request)");
    use std::io::Write as _;
    let _ = std::io::stdout().flush();
    if args.open {
        open_browser(&url);
    }
    let guard = api::Guard::new(token, &args.host, port);
    let quit = crate::interrupt::cancel_flag();
    {
        let s = studio.clone();
        std::thread::spawn(move || s.run_worker());
    }
    {
        let s = studio.clone();
        let interval = Duration::from_millis(args.interval_ms.max(50));
        std::thread::spawn(move || watch_file(s, interval));
    }
    if let Err(e) = server::serve(listener, studio.clone(), Arc::new(guard), quit.clone()) {
        eprintln!("error: the studio's server stopped: {e}");
        studio.request_run();
        return Ok(crate::exit::FAILED);
    }
    studio.request_run(); // wakes the worker so that it sees Ctrl-C and stops
    Ok(crate::exit::CANCELLED)
}

/// Reloads the graph when an editor changes its file (as `watch` does, by content). It starts
/// from the text the studio loaded, not from a first read of its own: an edit made between the
/// load and this thread's first turn (the URL is printed, a client may already write) would
/// otherwise become the baseline and never be picked up.
fn watch_file(studio: Arc<Studio>, interval: Duration) {
    let quit = crate::interrupt::cancel_flag();
    let mut last = Some(studio.doc().disk_text.clone().into_bytes());
    while !quit.load(Ordering::Relaxed) {
        std::thread::sleep(interval);
        let now = std::fs::read(&studio.graph_path).ok();
        if now != last {
            if let Some(text) = now.as_ref().and_then(|b| String::from_utf8(b.clone()).ok()) {
                studio.file_changed(text);
            }
            last = now;
        }
    }
}

fn open_browser(url: &str) {
    let opener = if cfg!(target_os = "macos") {
        "open"
    } else if cfg!(windows) {
        "explorer"
    } else {
        "xdg-open"
    };
    if let Err(e) = std::process::Command::new(opener).arg(url).spawn() {
        eprintln!("warning: --open: cannot start {opener}: {e}; open the URL above yourself");
    }
}
