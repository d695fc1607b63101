//! `mesoflow run`: the graph loaded and checked, run on this machine (`Runner`, which `watch`
//! reuses) or on a Slurm cluster; the set-up every command shares is `crate::session`.

use crate::args::{EngineArg, RunArgs};
use crate::exit::{self, invalid};
use crate::load;
use crate::progress::{summary_with, Bars};
use crate::session::{
    cache_dir, check_outputs, device_name, engine, exit_code, graph_dir, graph_name, parse_outputs,
    policy, slurm_run_dir, write_report,
};
use mesoflow_graph::CheckedGraph;
use mesoflow_runtime::{Engine, RunObserver, RunOptions, RunReport, SilentObserver};
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub struct Runner {
    pub engine: Engine,
    pub base: RunOptions,
    pub quiet: bool,
    /// The run table says why each computed node ran (`--explain`; always in `watch`).
    pub explain: bool,
    /// After a cluster run, the errors of nodes that failed in their jobs: the final pass finds
    /// them missing from the cache, and its report says why, as the job saw it.
    pub cluster_errors: std::collections::BTreeMap<String, String>,
}

impl Runner {
    pub fn new(args: &RunArgs) -> anyhow::Result<Runner> {
        let engine = engine(&args.cache, &args.graph.path)?;
        let out_dir = args
            .out_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("out").join(graph_name(&args.graph.path)));
        let mut base = RunOptions::new(
            &args.graph.path.display().to_string(),
            graph_dir(&args.graph.path),
            out_dir,
            policy(args.device, &args.cache),
        );
        base.outputs = load::through_subgraphs(
            &args.graph.path,
            &args.graph.set,
            parse_outputs(&args.output)?,
        )?;
        Ok(Runner {
            engine,
            base,
            quiet: args.quiet,
            explain: args.explain,
            cluster_errors: Default::default(),
        })
    }

    /// Runs once, writes report.json and prints the summary.
    pub fn run_once(&self, graph: &CheckedGraph, out_dir: &Path) -> anyhow::Result<RunReport> {
        let opts = RunOptions {
            out_dir: out_dir.to_path_buf(),
            ..self.base.clone()
        };
        let shown: Arc<dyn RunObserver> = if self.quiet {
            Arc::new(SilentObserver)
        } else {
            Arc::new(Bars::new())
        };
        let observer: Arc<dyn RunObserver> = Arc::new(crate::interrupt::Recording::start(
            &opts.graph_name,
            out_dir.to_path_buf(),
            shown,
        ));
        let started = std::time::SystemTime::now();
        let mut report = self
            .engine
            .run(graph, &opts, observer)
            .map_err(|e| invalid(e.to_string()))?;
        for n in &mut report.nodes {
            if let Some(e) = self.cluster_errors.get(&n.id) {
                if n.error
                    .as_deref()
                    .is_some_and(|x| x.contains(mesoflow_runtime::NOT_IN_CACHE))
                {
                    n.error = Some(format!("node `{}`: {e}", n.id));
                }
            }
        }
        if opts.outputs.is_empty() {
            write_report(&report, out_dir)?;
        } else {
            // Some outputs only: the folder's report keeps the nodes this run did not need.
            // Only a regular file of a report's size is read (never a link, FIFO or device).
            let path = out_dir.join("report.json");
            let previous = std::fs::symlink_metadata(&path)
                .ok()
                .filter(|m| m.is_file() && m.len() < 64 << 20)
                .and_then(|_| std::fs::read_to_string(&path).ok())
                .and_then(|t| serde_json::from_str::<mesoflow_runtime::RunReport>(&t).ok());
            let whole = match &previous {
                Some(p) => report.clone().keeping_earlier(p),
                None => report.clone(),
            };
            write_report(&whole, out_dir)?;
        }
        if !report.ok {
            // A failed run rewrites only some of the folder's files: say which ones are older,
            // so they are not taken for this run's.
            let old = files_older_than(out_dir, started);
            if !old.is_empty() {
                eprintln!(
                    "warning: {} still holds {} file{} from an earlier run that this run did not write: {}",
                    out_dir.display(),
                    old.len(),
                    if old.len() == 1 { "" } else { "s" },
                    if old.len() > 20 {
                        format!("{}, …", old[..20].join(", "))
                    } else {
                        old.join(", ")
                    }
                );
            }
        }
        if !self.quiet {
            print!("{}", summary_with(&report, self.explain));
            // Where the files went: the output folder is relative to the current folder, not
            // the graph's (a new user looked beside the graph).
            let shown = std::fs::canonicalize(out_dir).unwrap_or_else(|_| out_dir.to_path_buf());
            println!(
                "{} file{} and report.json in {}",
                report.files.len(),
                if report.files.len() == 1 { "" } else { "s" },
                shown.display()
            );
        }
        // The values asked for with --output, one per line (scalars by value).
        for o in &opts.outputs {
            let Some(n) = report.node(&o.node) else {
                continue;
            };
            match n.metrics.get(&o.port) {
                Some(v) => println!("{o} = {v}"),
                None if n.error.is_none() => {
                    let ty = self
                        .engine
                        .registry()
                        .node(&n.kind)
                        .and_then(|k| k.signature().output(&o.port).map(|p| p.ty.clone()))
                        .unwrap_or_default();
                    println!(
                        "{o}: a {ty} ({}, {})",
                        crate::progress::human_bytes(n.bytes),
                        crate::progress::status_text(n.status)
                    );
                }
                None => {}
            }
        }
        if self.quiet {
            for n in report.nodes.iter().filter_map(|n| {
                n.error
                    .as_ref()
                    .filter(|_| n.status == mesoflow_runtime::NodeStatus::Failed)
            }) {
                eprintln!("error: {n}");
            }
        }
        Ok(report)
    }
}

pub fn run(args: &RunArgs) -> anyhow::Result<i32> {
    let mut runner = Runner::new(args)?;
    let graph = load::load(&args.graph.path, &args.graph.set, runner.engine.registry())?;
    check_outputs(&runner.base.outputs, &graph, &runner.engine)?;
    if args.cluster.engine == EngineArg::Slurm {
        let Some(run_dir) = slurm_run_dir(&args.cluster, &args.cache, &runner.base.out_dir)? else {
            return Ok(exit::OK);
        };
        let mut file = load::read(&args.graph.path)?;
        load::apply_sets(&mut file, &args.graph.set)?;
        let outcome = crate::cluster::driver::drive(
            &runner.engine,
            &[(file.to_json(), graph.clone())],
            &runner.base,
            &cache_dir(&args.cache, &args.graph.path),
            &run_dir,
            &args.cluster,
            device_name(args.device),
            runner.quiet,
        )?;
        if outcome.interrupted {
            return Ok(exit::CANCELLED);
        }
        // The final pass computes nothing: every value came from the cluster, through the cache.
        runner.base.compute_only = Some(Default::default());
        let mut report = runner.run_once(&graph, &runner.base.out_dir)?;
        // A node that failed in its job is missing from the cache: its report says why, as the
        // job saw it, rather than that it is missing.
        let mut patched = false;
        for n in &mut report.nodes {
            if let Some(e) = outcome.errors.get(&n.id) {
                if n.error
                    .as_deref()
                    .is_some_and(|x| x.contains(mesoflow_runtime::NOT_IN_CACHE))
                {
                    n.error = Some(format!("node `{}`: {e}", n.id));
                    patched = true;
                }
            }
        }
        if patched {
            write_report(&report, &runner.base.out_dir)?;
        }
        return Ok(exit_code(&report));
    }
    let report = runner.run_once(&graph, &runner.base.out_dir)?;
    Ok(exit_code(&report))
}

/// `mesoflow explain`: what `run` with these arguments would do, node by node, and why a node
/// would run; nothing runs and nothing is written. Exit 0.
pub fn explain(args: &RunArgs) -> anyhow::Result<i32> {
    let runner = Runner::new(args)?;
    let graph = load::load(&args.graph.path, &args.graph.set, runner.engine.registry())?;
    check_outputs(&runner.base.outputs, &graph, &runner.engine)?;
    let rows = runner.engine.explain(&graph, &runner.base);
    let width = |f: &dyn Fn(&mesoflow_runtime::Explained) -> usize, h: &str| {
        rows.iter().map(f).max().unwrap_or(0).max(h.len())
    };
    let (wi, wk, wa) = (
        width(&|r| r.id.chars().count(), "node"),
        width(&|r| r.kind.chars().count(), "kind"),
        width(&|r| r.action.chars().count(), "would"),
    );
    println!("{:<wi$}  {:<wk$}  {:<wa$}  why", "node", "kind", "would");
    for r in &rows {
        let line = format!(
            "{:<wi$}  {:<wk$}  {:<wa$}  {}",
            r.id,
            r.kind,
            r.action,
            r.reason.as_deref().unwrap_or("")
        );
        println!("{}", line.trim_end());
    }
    let runs = rows.iter().filter(|r| r.action == "run").count();
    println!(
        "{runs} of {} node{} would run (records of the last runs: {})",
        rows.len(),
        if rows.len() == 1 { "" } else { "s" },
        runner
            .base
            .out_dir
            .join(mesoflow_runtime::explain::RECORD_FILE)
            .display()
    );
    Ok(exit::OK)
}

/// Files under `dir` (not `report.json`) last written before `t`, by path relative to `dir`,
/// sorted.
fn files_older_than(dir: &Path, t: std::time::SystemTime) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    let mut seen = 0usize;
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            seen += 1;
            if seen > 100_000 {
                break;
            }
            let path = e.path();
            let Ok(meta) = e.metadata() else { continue };
            if meta.is_dir() {
                // A sweep's folder (`out/<graph>/sweep/`) is its own, not a run's.
                if !(d == dir && e.file_name() == "sweep") {
                    stack.push(path);
                }
            } else if meta.modified().is_ok_and(|m| m < t)
                && e.file_name() != "report.json"
                && e.file_name() != mesoflow_runtime::explain::RECORD_FILE
            {
                let rel = path.strip_prefix(dir).unwrap_or(&path);
                found.push(rel.display().to_string());
            }
        }
    }
    found.sort();
    found
}
