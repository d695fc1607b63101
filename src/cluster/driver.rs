//! The driver of `--engine slurm`: splits the run into units, submits each with `sbatch` once
//! the values it reads are in the shared cache, follows them with one `squeue` per poll and the
//! units' result files, and retries what was lost. Readiness is tracked here rather than with
//! Slurm's `afterok`, which leaves dependants pending forever when a job fails. The caller then
//! makes a local pass in which every node must be a cache hit (the normal run code path).

use super::folder::{Folder, RunSpec, Submission};
use super::slurm;
use super::units::{self, UnitSpec};
use crate::args::ClusterOptions;
use mesoflow_graph::CheckedGraph;
use mesoflow_runtime::cache::DiskCache;
use mesoflow_runtime::{Engine, Key, RunObserver, RunOptions};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

#[derive(Clone, Debug, PartialEq)]
enum State {
    Pending { attempts: u32 },
    Running { job: String, attempt: u32 },
    Done,
    Failed(String),
    Cancelled(String),
}

/// How the units of a run ended.
#[derive(Debug, Default)]
pub struct Outcome {
    pub done: usize,
    pub failed: usize,
    pub cancelled: usize,
    pub submitted: usize,
    pub interrupted: bool,
    /// The error of each node of a failed unit, as its job reported it.
    pub errors: BTreeMap<String, String>,
}

fn poll_interval() -> Duration {
    let ms = std::env::var("MESOFLOW_SLURM_POLL_MS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(500u64);
    Duration::from_millis(ms.clamp(20, 60_000))
}

fn all_cached(cache: &DiskCache, keys: &[String]) -> bool {
    keys.iter()
        .all(|k| Key::from_hex(k).is_some_and(|key| cache.contains(&key)))
}

fn absolute(p: &Path) -> std::path::PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| {
        std::env::current_dir()
            .map(|d| d.join(p))
            .unwrap_or_else(|_| p.to_path_buf())
    })
}

#[allow(clippy::too_many_arguments)]
pub fn drive(
    engine: &Engine,
    variants: &[(String, CheckedGraph)],
    opts: &RunOptions,
    cache_dir: &Path,
    run_dir: &Path,
    cluster: &ClusterOptions,
    device: &str,
    quiet: bool,
) -> anyhow::Result<Outcome> {
    std::fs::create_dir_all(cache_dir)?;
    let folder = Folder::new(run_dir);
    std::fs::create_dir_all(folder.logs())?;
    let _ = std::fs::remove_file(folder.cancel_path());
    let keyed: Vec<(CheckedGraph, BTreeMap<String, Key>)> = variants
        .iter()
        .map(|(_, g)| {
            let keys = engine
                .keys(g, opts)
                .into_iter()
                .filter_map(|(id, k)| k.ok().map(|k| (id, k)))
                .collect();
            (g.clone(), keys)
        })
        .collect();
    let split: BTreeSet<String> = cluster.split.iter().cloned().collect();
    let units = units::split(&keyed, &split);
    let exe = absolute(&std::env::current_exe()?);
    let spec = RunSpec {
        build: mesoflow_runtime::producer::build_id().into(),
        exe: exe.clone(),
        cache_dir: absolute(cache_dir),
        base_dir: absolute(&opts.base_dir),
        graph_name: opts.graph_name.clone(),
        device: device.into(),
        variants: variants.iter().map(|(t, _)| t.clone()).collect(),
        units: units.clone(),
    };
    folder.write_spec(&spec)?;
    let cache = DiskCache::new(&spec.cache_dir);
    let queue = slurm::queue()?;
    // Resume: what is cached is done; a job still queued from an earlier driver is followed.
    let mut state: BTreeMap<String, State> = units
        .iter()
        .map(|(id, u)| {
            let s = if all_cached(&cache, &u.keys) {
                State::Done
            } else {
                match folder.submission(id) {
                    Some(sub) if queue.contains_key(&sub.job) => State::Running {
                        job: sub.job,
                        attempt: sub.attempt,
                    },
                    Some(sub) => State::Pending {
                        attempts: sub.attempt,
                    },
                    None => State::Pending { attempts: 0 },
                }
            };
            (id.clone(), s)
        })
        .collect();
    let mut out = Outcome::default();
    let say = |line: String| {
        if !quiet {
            println!("[slurm] {line}");
        }
    };
    let resumed = state.values().filter(|s| **s == State::Done).count();
    say(format!(
        "{} units of {} nodes{}; run folder {}",
        units.len(),
        units.values().map(|u| u.nodes.len()).sum::<usize>(),
        if resumed > 0 {
            format!(", {resumed} already in the cache")
        } else {
            String::new()
        },
        run_dir.display()
    ));
    let extra = cluster
        .sbatch_args
        .as_deref()
        .map(slurm::words)
        .unwrap_or_default();
    let interval = poll_interval();
    let started = Instant::now();
    // The progress display of a local run, with a bar per unit in flight.
    let bars = (!quiet).then(crate::progress::Bars::new);
    let label = |id: &str| format!("{id} {}", units[id].nodes.join(","));
    let finished = |id: &str, ok: bool| {
        if let Some(b) = &bars {
            b.node_finished(&mesoflow_runtime::NodeReport {
                reason: None,
                id: label(id),
                kind: "unit".into(),
                device: "slurm".into(),
                status: if ok {
                    mesoflow_runtime::NodeStatus::Computed
                } else {
                    mesoflow_runtime::NodeStatus::Failed
                },
                seconds: 0.0,
                bytes: 0,
                key: String::new(),
                metrics: Default::default(),
                timings: Default::default(),
                kind_version: 0,
                error: None,
                verified: false,
            });
        }
    };
    for (id, s) in &state {
        if let (Some(b), State::Running { job, .. }) = (&bars, s) {
            b.node_started(&label(id), "unit", &format!("slurm job {job}"));
        }
    }
    loop {
        if opts.policy.cancel.load(Ordering::Relaxed) || folder.cancel_path().exists() {
            let jobs: Vec<String> = state
                .values()
                .filter_map(|s| match s {
                    State::Running { job, .. } => Some(job.clone()),
                    _ => None,
                })
                .collect();
            slurm::scancel(&jobs)?;
            out.interrupted = true;
            say(format!("cancelled; {} jobs cancelled", jobs.len()));
            break;
        }
        let queue = slurm::queue()?;
        // Results and losses.
        let ids: Vec<String> = state.keys().cloned().collect();
        for id in &ids {
            let State::Running { job, attempt } = state[id].clone() else {
                continue;
            };
            let status = folder.status(id).filter(|s| s.attempt == attempt);
            let next = match status.as_ref().map(|s| s.status.as_str()) {
                Some("done") => {
                    let s = status.as_ref().map(|s| (s.host.clone(), s.seconds));
                    if let Some((host, secs)) = s {
                        say(format!(
                            "{id} ({}) done on {host} in {secs:.2} s",
                            units[id].nodes.join(", ")
                        ));
                    }
                    Some(State::Done)
                }
                Some("failed") => {
                    let error = status.and_then(|s| s.error).unwrap_or_default();
                    say(format!(
                        "{id} ({}) failed: {error}",
                        units[id].nodes.join(", ")
                    ));
                    Some(State::Failed(error))
                }
                Some(_) => retry(
                    id,
                    attempt,
                    cluster.retries,
                    "an input was not in the cache",
                ),
                None if !queue.contains_key(&job) => {
                    say(format!(
                        "{id}: job {job} ended without a result (lost, killed or timed out)"
                    ));
                    retry(id, attempt, cluster.retries, "its job was lost")
                }
                None => None,
            };
            if let Some(next) = next {
                finished(id, next == State::Done);
                if let State::Failed(_) = next {
                    for d in units::dependants(&units, id) {
                        if !matches!(state[&d], State::Done | State::Failed(_)) {
                            state.insert(d, State::Cancelled(format!("unit {id} failed")));
                        }
                    }
                }
                state.insert(id.clone(), next);
            }
        }
        // Submissions.
        let mut running = state
            .values()
            .filter(|s| matches!(s, State::Running { .. }))
            .count();
        for id in &ids {
            if running >= cluster.max_queued.max(1) {
                break;
            }
            let State::Pending { attempts } = state[id] else {
                continue;
            };
            let u: &UnitSpec = &units[id];
            if all_cached(&cache, &u.keys) {
                state.insert(id.clone(), State::Done);
                continue;
            }
            if !all_cached(&cache, &u.inputs) {
                continue;
            }
            let attempt = attempts + 1;
            let argv = vec![
                exe.display().to_string(),
                "exec".into(),
                absolute(run_dir).display().to_string(),
                "--unit".into(),
                id.clone(),
            ];
            let job = slurm::sbatch(
                &format!("mf-{id}"),
                &folder.logs().join(format!("{id}.%j.log")),
                &extra,
                &[("MESOFLOW_ATTEMPT", attempt.to_string())],
                &argv,
            )?;
            folder.write_submission(
                id,
                &Submission {
                    job: job.clone(),
                    attempt,
                },
            )?;
            out.submitted += 1;
            running += 1;
            if let Some(b) = &bars {
                b.node_started(&label(id), "unit", &format!("slurm job {job}"));
            }
            state.insert(id.clone(), State::Running { job, attempt });
        }
        let pending = state
            .values()
            .filter(|s| matches!(s, State::Pending { .. }))
            .count();
        if running == 0 {
            if pending == 0 {
                break;
            }
            // Nothing runs and nothing can start: the inputs of what is left will never come.
            for s in state.values_mut() {
                if matches!(s, State::Pending { .. }) {
                    *s = State::Failed("an input is produced by no unit".into());
                }
            }
            break;
        }
        std::thread::sleep(interval);
    }
    for (id, s) in &state {
        if let State::Failed(e) = s {
            for node in &units[id].nodes {
                out.errors.insert(
                    node.clone(),
                    format!("failed on the cluster (unit {id}): {e}"),
                );
            }
        }
    }
    for s in state.values() {
        match s {
            State::Done => out.done += 1,
            State::Failed(_) => out.failed += 1,
            State::Cancelled(_) | State::Pending { .. } | State::Running { .. } => {
                out.cancelled += 1
            }
        }
    }
    say(format!(
        "{} done, {} failed, {} cancelled; {} jobs submitted in {:.1} s",
        out.done,
        out.failed,
        out.cancelled,
        out.submitted,
        started.elapsed().as_secs_f64()
    ));
    Ok(out)
}

/// A unit to try again (lost job, missing input), or failed once it has used its retries.
fn retry(id: &str, attempt: u32, retries: u32, why: &str) -> Option<State> {
    if attempt > retries {
        Some(State::Failed(format!(
            "unit {id}: {why}, {attempt} times (--retries {retries})"
        )))
    } else {
        Some(State::Pending { attempts: attempt })
    }
}

/// `--detach`: the driver itself as a job, with the same arguments.
pub fn detach(run_dir: &Path, sbatch_args: Option<&str>) -> anyhow::Result<String> {
    let folder = Folder::new(run_dir);
    std::fs::create_dir_all(folder.logs())?;
    let mut argv: Vec<String> = vec![absolute(&std::env::current_exe()?).display().to_string()];
    argv.extend(std::env::args().skip(1).filter(|a| a != "--detach"));
    let extra = sbatch_args.map(slurm::words).unwrap_or_default();
    slurm::sbatch(
        "mf-driver",
        &folder.logs().join("driver.%j.log"),
        &extra,
        &[],
        &argv,
    )
}
