//! A command's session with the engine, as every front end of the command line sets it up: the
//! graph's folder and name, the cache folder, the engine with its memory budget, the device and
//! the GPU requirement, Ctrl-C, the `--output` targets, the report file and the exit code, and
//! the Slurm run folder. `run`, `watch`, `sweep`, `plan`, `info`, the studio and the cluster all
//! take these from here.

use crate::args::{CacheOptions, ClusterOptions, DeviceArg};
use crate::exit::{self, invalid};
use anyhow::Context;
use mesoflow_graph::{CheckedGraph, PortRef};
use mesoflow_runtime::cache::{default_memory_budget, DiskCache};
use mesoflow_runtime::{DeviceMode, Engine, EngineConfig, RunPolicy, RunReport};
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
        mesoflow_nodes::registry::builtin(),
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

/// The command's run policy: its `--device`, its cache flags, `MESOFLOW_REQUIRE_GPU` and Ctrl-C.
pub fn policy(device: DeviceArg, cache: &CacheOptions) -> RunPolicy {
    RunPolicy {
        device: device_mode(device),
        use_cache: !cache.no_cache,
        verify_cache: cache.verify_cache,
        cancel: cancel_flag(),
        ..RunPolicy::default()
    }
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

pub fn write_report(report: &RunReport, out_dir: &Path) -> anyhow::Result<()> {
    report
        .write_into(out_dir)
        .with_context(|| format!("writing {}", out_dir.join("report.json").display()))?;
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
