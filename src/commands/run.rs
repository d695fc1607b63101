//! `mesoflow run`, and the set-up that `watch` and `sweep` share with it: the engine, the cache
//! folder, the output folder, Ctrl-C.

use crate::args::{CacheOptions, ClusterOptions, DeviceArg, EngineArg, RunArgs};
use crate::exit::{self, invalid};
use crate::load;
use crate::progress::{summary, Bars};
use anyhow::Context;
use mesoflow_graph::{CheckedGraph, PortRef};
use mesoflow_runtime::cache::{default_memory_budget, DiskCache};
use mesoflow_runtime::{
    DeviceMode, Engine, EngineConfig, RunObserver, RunOptions, RunReport, SilentObserver,
};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// The folder a graph's relative input paths resolve against.
pub fn graph_dir(graph: &Path) -> PathBuf {
    match graph.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

pub fn graph_name(graph: &Path) -> String {
    graph
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "graph".into())
}

/// `--cache-dir`, else `MESOFLOW_CACHE` (clap reads it into the same field), else
/// `.mesoflow/cache` beside the graph.
pub fn cache_dir(opts: &CacheOptions, graph: &Path) -> PathBuf {
    opts.cache_dir
        .clone()
        .unwrap_or_else(|| graph_dir(graph).join(".mesoflow").join("cache"))
}

pub fn parse_size(text: &str) -> anyhow::Result<usize> {
    let t = text.trim();
    let (digits, mult) = match t.chars().last().map(|c| c.to_ascii_uppercase()) {
        Some('K') => (&t[..t.len() - 1], 1usize << 10),
        Some('M') => (&t[..t.len() - 1], 1 << 20),
        Some('G') => (&t[..t.len() - 1], 1 << 30),
        _ => (t, 1),
    };
    let n: f64 = digits.trim().parse().map_err(|_| {
        invalid(format!(
            "--mem-budget {text}: expected bytes or a size like 512M, 2G"
        ))
    })?;
    if !n.is_finite() || n < 0.0 {
        return Err(invalid(format!(
            "--mem-budget {text}: must be a finite, non-negative size"
        )));
    }
    Ok((n * mult as f64) as usize)
}

pub fn engine(opts: &CacheOptions, graph: &Path) -> anyhow::Result<Engine> {
    let memory_budget = match &opts.mem_budget {
        Some(s) => parse_size(s)?,
        None => default_memory_budget(),
    };
    let disk = (!opts.no_cache).then(|| DiskCache::new(cache_dir(opts, graph)));
    Ok(Engine::new(
        mesoflow_nodes::registry(),
        EngineConfig {
            memory_budget,
            disk,
        },
    ))
}

/// The run's cancellation flag (Ctrl-C; see `interrupt`).
pub fn cancel_flag() -> Arc<AtomicBool> {
    crate::interrupt::cancel_flag()
}

pub fn device_mode(d: DeviceArg) -> DeviceMode {
    match d {
        DeviceArg::Auto => DeviceMode::Auto,
        DeviceArg::Cpu => DeviceMode::Cpu,
        DeviceArg::Gpu => DeviceMode::Gpu,
    }
}

pub fn require_gpu() -> bool {
    mesoflow_runtime::require_gpu_from_env()
}

/// `--output` targets checked against the graph, with a did-you-mean for a node or port.
pub fn check_outputs(
    outputs: &[PortRef],
    graph: &CheckedGraph,
    engine: &Engine,
) -> anyhow::Result<()> {
    for o in outputs {
        let Some(i) = graph.index(&o.node) else {
            let hint =
                mesoflow_graph::did_you_mean(&o.node, graph.nodes.iter().map(|n| n.id.as_str()));
            return Err(invalid(format!("--output {o}: no node `{}`{hint}", o.node)));
        };
        let kind = &graph.nodes[i].kind;
        if let Some(sig) = engine.registry().node(kind).map(|n| n.signature()) {
            if sig.output(&o.port).is_none() {
                let names: Vec<&str> = sig.outputs.iter().map(|p| p.name.as_str()).collect();
                let hint = mesoflow_graph::did_you_mean(&o.port, names.iter().copied());
                return Err(invalid(format!(
                    "--output {o}: `{}` ({kind}) has no output `{}`{hint}; it has {}",
                    o.node,
                    o.port,
                    names.join(", ")
                )));
            }
        }
    }
    Ok(())
}

pub fn parse_outputs(outputs: &[String]) -> anyhow::Result<Vec<PortRef>> {
    outputs
        .iter()
        .map(|o| {
            PortRef::parse(o).ok_or_else(|| invalid(format!("--output {o}: expected id.port")))
        })
        .collect()
}

pub struct Runner {
    pub engine: Engine,
    pub base: RunOptions,
    pub quiet: bool,
    /// After a cluster run, the errors of nodes that failed in their jobs: the final pass finds
    /// them missing from the cache, and its report says why, as the job saw it.
    pub cluster_errors: std::collections::BTreeMap<String, String>,
}

impl Runner {
    pub fn new(args: &RunArgs) -> anyhow::Result<Runner> {
        let engine = engine(&args.cache, &args.graph)?;
        let out_dir = args
            .out_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("out").join(graph_name(&args.graph)));
        let mut base = RunOptions::new(
            &args.graph.display().to_string(),
            graph_dir(&args.graph),
            out_dir,
        );
        base.outputs = parse_outputs(&args.output)?;
        base.device = device_mode(args.device);
        base.require_gpu = require_gpu();
        base.use_cache = !args.cache.no_cache;
        base.verify_cache = args.cache.verify_cache;
        base.cancel = cancel_flag();
        Ok(Runner {
            engine,
            base,
            quiet: args.quiet,
            cluster_errors: Default::default(),
        })
    }

    /// Runs once, writes report.json and prints the summary.
    pub fn run_once(&self, graph: &CheckedGraph, out_dir: &Path) -> anyhow::Result<RunReport> {
        let opts = RunOptions {
            graph_name: self.base.graph_name.clone(),
            base_dir: self.base.base_dir.clone(),
            out_dir: out_dir.to_path_buf(),
            outputs: self.base.outputs.clone(),
            device: self.base.device,
            require_gpu: self.base.require_gpu,
            use_cache: self.base.use_cache,
            verify_cache: self.base.verify_cache,
            compute_only: self.base.compute_only.clone(),
            cache_everything: self.base.cache_everything,
            cancel: self.base.cancel.clone(),
            confine: None,
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
        write_report(&report, out_dir)?;
        if !self.quiet {
            print!("{}", summary(&report));
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

pub fn write_report(report: &RunReport, out_dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let path = out_dir.join("report.json");
    let text = serde_json::to_string_pretty(report)?;
    mesoflow_runtime::write_atomic(&path, text + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

pub fn exit_code(report: &RunReport) -> i32 {
    if report.cancelled {
        exit::CANCELLED
    } else if report.ok {
        exit::OK
    } else {
        exit::FAILED
    }
}

pub fn device_name(d: DeviceArg) -> &'static str {
    match d {
        DeviceArg::Auto => "auto",
        DeviceArg::Cpu => "cpu",
        DeviceArg::Gpu => "gpu",
    }
}

/// `--engine slurm`, the checks and `--detach` that `run` and `sweep` share: the run folder
/// (`--run-dir`, else `cluster` in the output folder), or `None` once `--detach` has submitted
/// the driver as a job and nothing is left to do here.
pub fn slurm_run_dir(
    cluster: &ClusterOptions,
    cache: &CacheOptions,
    out_dir: &Path,
) -> anyhow::Result<Option<PathBuf>> {
    if cache.no_cache {
        return Err(invalid(
            "--engine slurm: the jobs hand their results over through the cache; drop --no-cache",
        ));
    }
    let run_dir = cluster
        .run_dir
        .clone()
        .unwrap_or_else(|| out_dir.join("cluster"));
    if cluster.detach {
        let job = crate::cluster::driver::detach(&run_dir, cluster.sbatch_args.as_deref())?;
        println!(
            "submitted the driver as job {job}; follow it with: mesoflow status {}",
            run_dir.display()
        );
        return Ok(None);
    }
    Ok(Some(run_dir))
}

pub fn run(args: &RunArgs) -> anyhow::Result<i32> {
    let mut runner = Runner::new(args)?;
    let graph = load::load(&args.graph, &args.set, runner.engine.registry())?;
    check_outputs(&runner.base.outputs, &graph, &runner.engine)?;
    if args.cluster.engine == EngineArg::Slurm {
        let Some(run_dir) = slurm_run_dir(&args.cluster, &args.cache, &runner.base.out_dir)? else {
            return Ok(exit::OK);
        };
        let mut file = load::read(&args.graph)?;
        load::apply_sets(&mut file, &args.set)?;
        let outcome = crate::cluster::driver::drive(
            &runner.engine,
            &[(file.to_json(), graph.clone())],
            &runner.base,
            &cache_dir(&args.cache, &args.graph),
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
