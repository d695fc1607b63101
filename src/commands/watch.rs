//! `mesoflow watch`: re-run when the graph file or any file a node read changes. The engine (and
//! its memory cache) lives across runs, so only the nodes a change touches recompute.

use super::run::Runner;
use crate::args::RunArgs;
use crate::load;
use crate::session::exit_code;
use mesoflow_runtime::NodeStatus;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// What identifies a file's state: its length and content hash (mtimes can be too coarse).
fn fingerprint(paths: &[PathBuf]) -> Vec<Option<(u64, [u8; 32])>> {
    paths
        .iter()
        .map(|p| {
            let bytes = std::fs::read(p).ok()?;
            Some((bytes.len() as u64, *blake3::hash(&bytes).as_bytes()))
        })
        .collect()
}

pub fn watch(args: &RunArgs, interval_ms: u64, max_runs: Option<usize>) -> anyhow::Result<i32> {
    if args.cluster.engine != crate::args::EngineArg::Local {
        return Err(crate::exit::invalid(
            "watch runs here: --engine slurm is for run and sweep",
        ));
    }
    let mut runner = Runner::new(args)?;
    // A re-run says what changed.
    runner.explain = true;
    let mut runs = 0usize;
    loop {
        let last_code;
        let mut watched = vec![args.graph.path.clone()];
        // The graph's state as loaded: an edit saved while the run is under way is then seen
        // as a change afterwards instead of becoming the baseline.
        let mut before = fingerprint(&watched);
        match load::load(&args.graph.path, &args.graph.set, runner.engine.registry()) {
            Ok(graph) => {
                let report = runner.run_once(&graph, &runner.base.out_dir)?;
                last_code = exit_code(&report);
                let reran: Vec<&str> = report
                    .nodes
                    .iter()
                    .filter(|n| n.status == NodeStatus::Computed)
                    .map(|n| n.id.as_str())
                    .collect();
                println!(
                    "[watch] run {}: re-ran {}",
                    runs + 1,
                    if reran.is_empty() {
                        "nothing".into()
                    } else {
                        reran.join(", ")
                    }
                );
                let read: Vec<PathBuf> = report.read.iter().map(PathBuf::from).collect();
                before.extend(fingerprint(&read));
                watched.extend(read);
            }
            Err(e) => {
                last_code = crate::exit::code_of(&e);
                eprintln!("error: {e:#}");
            }
        }
        runs += 1;
        if max_runs.is_some_and(|m| runs >= m) || runner.base.policy.cancel.load(Ordering::Relaxed)
        {
            return Ok(last_code);
        }
        println!(
            "[watch] waiting for changes to {} files (Ctrl-C to stop)",
            watched.len()
        );
        loop {
            std::thread::sleep(Duration::from_millis(interval_ms));
            if runner.base.policy.cancel.load(Ordering::Relaxed) {
                return Ok(crate::exit::CANCELLED);
            }
            if fingerprint(&watched) != before {
                break;
            }
        }
    }
}
