//! `--engine slurm` against a real Slurm: the two-node cluster of `scripts/slurm-local` (w1, w2,
//! one CPU each), which `.ci/run` starts and names in `SLURM_CONF`. Without it these tests say
//! so and pass, except where `MESOFLOW_REQUIRE_SLURM=1` (CI), where they fail.

use crate::common::*;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The tests share one cluster, and some take a node down: one at a time.
static CLUSTER: Mutex<()> = Mutex::new(());

/// The cluster's folder (pid files), or `None` when there is no cluster to test against.
fn cluster() -> Option<PathBuf> {
    let conf = std::env::var("SLURM_CONF").ok().map(PathBuf::from);
    let up = conf.as_ref().is_some_and(|c| c.is_file())
        && Command::new("sinfo")
            .arg("-h")
            .output()
            .is_ok_and(|o| o.status.success());
    if !up {
        mesoflow_testkit::skip_unless_required(
            "MESOFLOW_REQUIRE_SLURM",
            "no Slurm cluster (SLURM_CONF unset or sinfo failing): start one with \
             scripts/slurm-local and export its SLURM_CONF",
        );
        return None;
    }
    conf.and_then(|c| c.parent().map(Path::to_path_buf))
}

/// Both nodes up and idle (a test that took one down puts it back).
fn nodes_up(dir: &Path) {
    let conf = std::env::var("SLURM_CONF").unwrap_or_default();
    for node in ["w1", "w2"] {
        let pid = std::fs::read_to_string(dir.join(format!("slurmd-{node}.pid"))).ok();
        let alive = pid.is_some_and(|p| Path::new(&format!("/proc/{}", p.trim())).exists());
        if !alive {
            let _ = Command::new("slurmd")
                .args(["-f", &conf, "-N", node])
                .status();
        }
    }
    let start = Instant::now();
    loop {
        let _ = Command::new("scontrol")
            .args(["update", "nodename=w1,w2", "state=resume"])
            .output();
        let out = Command::new("sinfo")
            .args(["-h", "-N", "-o", "%N %T"])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        if text
            .lines()
            .filter(|l| l.contains("idle") || l.contains("mix") || l.contains("alloc"))
            .count()
            >= 2
        {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "nodes not up: {text}"
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// The cluster to myself with both nodes up, and its folder; `None` without a cluster.
fn begin() -> Option<(std::sync::MutexGuard<'static, ()>, PathBuf)> {
    let one = CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = cluster()?;
    nodes_up(&dir);
    Some((one, dir))
}

/// The driver's submissions (`units/*.job`): job id and attempt of each unit's last one.
fn submissions(run: &Path) -> Vec<Value> {
    std::fs::read_dir(run.join("units"))
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "job"))
        .map(|e| serde_json::from_str(&std::fs::read_to_string(e.path()).unwrap()).unwrap())
        .collect()
}

/// Every file under `dir` except reports and the cluster folder, by relative path.
fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let p = e.path();
            if p.file_name().is_some_and(|n| n == "cluster") {
                continue;
            }
            if p.is_dir() {
                walk(root, &p, out);
            } else if p.file_name().is_some_and(|n| n != "report.json") {
                out.insert(
                    p.strip_prefix(root).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn csv_without_timings(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let rows: Vec<Vec<String>> = text
        .lines()
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    let keep: Vec<usize> = rows[0]
        .iter()
        .enumerate()
        .filter(|(_, h)| !h.ends_with("seconds"))
        .map(|(i, _)| i)
        .collect();
    rows.iter()
        .map(|r| keep.iter().map(|&i| r[i].clone()).collect())
        .collect()
}

fn statuses(run: &Path) -> BTreeMap<String, Value> {
    std::fs::read_dir(run.join("units"))
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
        .map(|e| {
            let p = e.path();
            let id = p.file_stem().unwrap().to_string_lossy().to_string();
            (
                id,
                serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap(),
            )
        })
        .collect()
}

fn spec(run: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(run.join("run.json")).unwrap()).unwrap()
}

fn keys(report: &Value) -> BTreeMap<String, String> {
    per_node(report, "key")
}

#[test]
fn a_sweep_on_two_workers_writes_what_a_local_sweep_writes() {
    let Some((_one, _)) = begin() else { return };
    let s = Scratch::new();
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/btf_compress.json");
    let sweep = |engine: &str, out: &str, cache: &str| {
        mesoflow(
            &[
                "sweep",
                graph.to_str().unwrap(),
                "--quiet",
                "--set",
                "surface.size=32",
                "--vary",
                "pca.rank=1,2,3,4,5,6,7,8",
                "--measure",
                "pca.rmse",
                "--measure",
                "compare.rmse",
                "--engine",
                engine,
                "--out-dir",
                s.path(out).to_str().unwrap(),
                "--cache-dir",
                s.path(cache).to_str().unwrap(),
            ],
            s.dir.path(),
        )
    };
    let local = sweep("local", "local", "local-cache");
    assert_eq!(local.code, 0, "{}", local.stderr);
    let t = Instant::now();
    let slurm = sweep("slurm", "slurm", "shared-cache");
    assert_eq!(slurm.code, 0, "{}\n{}", slurm.stdout, slurm.stderr);
    eprintln!(
        "8-variant sweep on w1 + w2: {:.1} s",
        t.elapsed().as_secs_f64()
    );
    // The same files, byte for byte, and the same keys in every run.
    let (a, b) = (files(&s.path("local")), files(&s.path("slurm")));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (path, bytes) in &a {
        let is_time_chart = path.to_string_lossy().contains("seconds")
            || path.to_string_lossy().ends_with("sweep.csv");
        if !is_time_chart {
            assert!(bytes == &b[path], "{} differs", path.display());
        }
    }
    assert_eq!(
        csv_without_timings(&s.path("local/sweep.csv")),
        csv_without_timings(&s.path("slurm/sweep.csv"))
    );
    for i in 0..8 {
        let run = format!("runs/{i:03}");
        // The final pass skips what its cache hits make unnecessary; every node it reports has
        // the local run's key.
        let (kl, ks) = (
            keys(&report(&s.path("local").join(&run))),
            keys(&report(&s.path("slurm").join(&run))),
        );
        assert!(!ks.is_empty());
        for (id, k) in &ks {
            assert_eq!(Some(k), kl.get(id), "{run}: {id}");
        }
        // The final pass computed nothing: every value came from the cluster.
        let r = report(&s.path("slurm").join(&run));
        assert!(r["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .all(|n| n["status"] != "computed"));
    }
    // Both workers ran units; the shared upstream part (the capture) was one unit, run once.
    let run = s.path("slurm/cluster");
    let st = statuses(&run);
    let hosts: Vec<String> = st
        .values()
        .map(|v| v["host"].as_str().unwrap().to_string())
        .collect();
    assert!(
        hosts.iter().any(|h| h.ends_with("w1")) && hosts.iter().any(|h| h.ends_with("w2")),
        "{hosts:?}"
    );
    let units = spec(&run)["units"].as_object().unwrap().clone();
    let capture: Vec<&String> = units
        .iter()
        .filter(|(_, u)| {
            u["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .any(|n| n == "capture")
        })
        .map(|(id, _)| id)
        .collect();
    assert_eq!(capture.len(), 1, "{units:?}");
    assert_eq!(st[capture[0]]["attempt"], 1);
    let logs = std::fs::read_dir(run.join("logs"))
        .unwrap()
        .flatten()
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with(capture[0].as_str())
        })
        .count();
    assert_eq!(logs, 1, "the capture ran once");
}

/// Four independent branches of a slow node and a cheap one: units that take seconds.
fn slow_graph(s: &Scratch, fail: bool) -> PathBuf {
    let mut nodes = serde_json::Map::new();
    for i in 0..4 {
        nodes.insert(
            format!("slow{i}"),
            serde_json::json!({"kind": "debug.sleep", "params": {"ms": 3000 + i, "fail": fail && i == 0}}),
        );
        nodes.insert(
            format!("out{i}"),
            serde_json::json!({"kind": "scalar.affine", "inputs": {"x": format!("slow{i}.y")}, "params": {"offset": i}}),
        );
    }
    let g = serde_json::json!({"mesoflow": 1, "nodes": nodes});
    s.write("slow.json", &g.to_string())
}

fn spawn(s: &Scratch, graph: &Path, out: &str) -> std::process::Child {
    bin()
        .args([
            "run",
            graph.to_str().unwrap(),
            "--quiet",
            "--engine",
            "slurm",
            "--retries",
            "3",
            "--out-dir",
            s.path(out).to_str().unwrap(),
            "--cache-dir",
            s.path("shared-cache").to_str().unwrap(),
        ])
        .env("MESOFLOW_SLURM_POLL_MS", "200")
        .current_dir(s.dir.path())
        .spawn()
        .unwrap()
}

/// The job ids running now, with their node.
fn running() -> BTreeMap<String, String> {
    let out = Command::new("squeue")
        .args(["-h", "-t", "R", "-o", "%i %N"])
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let mut it = l.split_whitespace();
            Some((it.next()?.to_string(), it.next()?.to_string()))
        })
        .collect()
}

fn wait_for(what: &str, secs: u64, mut f: impl FnMut() -> bool) {
    let start = Instant::now();
    while !f() {
        assert!(
            start.elapsed() < Duration::from_secs(secs),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The `mesoflow exec` process of a job, found by its unit in the command line.
fn exec_pid(run: &Path, job: &str) -> Option<u32> {
    let unit = std::fs::read_dir(run.join("units"))
        .ok()?
        .flatten()
        .find_map(|e| {
            let p = e.path();
            let text = std::fs::read_to_string(&p).ok()?;
            (p.extension()? == "job" && text.contains(&format!("\"{job}\"")))
                .then(|| p.file_stem().unwrap().to_string_lossy().to_string())
        })?;
    let out = Command::new("pgrep")
        .args(["-f", &format!("exec .* --unit {unit}")])
        .output()
        .ok()?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .next()?
        .trim()
        .parse()
        .ok()
}

fn metrics(report: &Value) -> BTreeMap<String, f64> {
    report["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|n| n["id"].as_str().is_some_and(|id| id.starts_with("out")))
        .filter_map(|n| Some((n["id"].as_str()?.to_string(), n["metrics"]["y"].as_f64()?)))
        .collect()
}

fn local_reference(s: &Scratch, graph: &Path) -> Value {
    let r = mesoflow(
        &[
            "run",
            graph.to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--out-dir",
            s.path("local").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    report(&s.path("local"))
}

#[test]
#[ignore = "slow: a Slurm kill test"]
fn a_worker_killed_mid_run_is_replaced_and_the_run_completes() {
    let Some((_one, dir)) = begin() else { return };
    let s = Scratch::new();
    let g = slow_graph(&s, false);
    let mut driver = spawn(&s, &g, "o");
    let run = s.path("o/cluster");
    let mut victim = None;
    wait_for("a job on w2", 60, || {
        victim = running()
            .into_iter()
            .find(|(_, n)| n == "w2")
            .map(|(j, _)| j);
        victim.is_some()
    });
    let job = victim.unwrap();
    wait_for("its exec process", 30, || exec_pid(&run, &job).is_some());
    // SIGKILL w2's daemon and the job's process: the node is lost with its work.
    let slurmd: i32 = std::fs::read_to_string(dir.join("slurmd-w2.pid"))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let exec = exec_pid(&run, &job).unwrap();
    Command::new("kill")
        .args(["-9", &slurmd.to_string(), &exec.to_string()])
        .status()
        .unwrap();
    let status = driver.wait().unwrap();
    nodes_up(&dir);
    assert_eq!(status.code(), Some(0));
    let r = report(&s.path("o"));
    assert_eq!(metrics(&r), metrics(&local_reference(&s, &g)));
}

#[test]
#[ignore = "slow: a Slurm kill test"]
fn a_killed_exec_is_resubmitted() {
    let Some((_one, _)) = begin() else { return };
    let s = Scratch::new();
    let g = slow_graph(&s, false);
    let mut driver = spawn(&s, &g, "o");
    let run = s.path("o/cluster");
    let mut pid = None;
    wait_for("a running exec", 60, || {
        pid = running().keys().find_map(|j| exec_pid(&run, j));
        pid.is_some()
    });
    Command::new("kill")
        .args(["-9", &pid.unwrap().to_string()])
        .status()
        .unwrap();
    assert_eq!(driver.wait().unwrap().code(), Some(0));
    let resubmitted = submissions(&run)
        .iter()
        .filter(|s| s["attempt"] == 2)
        .count();
    assert_eq!(resubmitted, 1);
    assert_eq!(
        metrics(&report(&s.path("o"))),
        metrics(&local_reference(&s, &g))
    );
}

#[test]
#[ignore = "slow: a Slurm kill test"]
fn a_driver_killed_and_started_again_resumes() {
    let Some((_one, _)) = begin() else { return };
    let s = Scratch::new();
    let g = slow_graph(&s, false);
    let mut first = spawn(&s, &g, "o");
    let run = s.path("o/cluster");
    wait_for("a finished unit", 60, || {
        std::fs::read_dir(run.join("units")).is_ok_and(|d| {
            d.flatten()
                .any(|e| e.path().extension().is_some_and(|x| x == "json"))
        })
    });
    first.kill().unwrap();
    let _ = first.wait();
    let before = statuses(&run);
    let mut second = spawn(&s, &g, "o");
    assert_eq!(second.wait().unwrap().code(), Some(0));
    let after = statuses(&run);
    // Finished units were not run again: their results are the first driver's.
    for (id, st) in &before {
        if st["status"] == "done" {
            assert_eq!(&after[id], st, "unit {id} ran again");
        }
    }
    // No unit was submitted more than once (running ones were followed, not resubmitted).
    for sub in submissions(&run) {
        assert_eq!(sub["attempt"], 1, "{sub}");
    }
    assert_eq!(
        metrics(&report(&s.path("o"))),
        metrics(&local_reference(&s, &g))
    );
}

#[test]
fn a_node_error_fails_its_branch_and_the_rest_is_cached() {
    let Some((_one, _)) = begin() else { return };
    let s = Scratch::new();
    let g = slow_graph(&s, true);
    let mut driver = spawn(&s, &g, "o");
    assert_eq!(driver.wait().unwrap().code(), Some(1));
    let r = report(&s.path("o"));
    let st = per_node(&r, "status");
    assert_eq!(st["slow0"], "failed");
    // The report says why, as the job saw it.
    let error = r["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "slow0")
        .and_then(|n| n["error"].as_str())
        .unwrap()
        .to_string();
    assert!(
        error.contains("failed on the cluster") && error.contains("on purpose"),
        "{error}"
    );
    assert_eq!(st["out0"], "cancelled");
    for i in 1..4 {
        assert_eq!(st[&format!("out{i}")], "disk", "{st:?}");
    }
    // Not retried: a node error would fail again.
    let run = s.path("o/cluster");
    let failed: Vec<Value> = statuses(&run)
        .into_values()
        .filter(|v| v["status"] == "failed")
        .collect();
    assert_eq!(failed.len(), 1);
    assert_eq!(failed[0]["attempt"], 1);
    assert!(failed[0]["error"].as_str().unwrap().contains("slow0"));
}

#[test]
fn status_follows_a_run_and_cancel_stops_it() {
    let Some((_one, _)) = begin() else { return };
    let s = Scratch::new();
    let g = slow_graph(&s, false);
    let mut driver = spawn(&s, &g, "o");
    let run = s.path("o/cluster");
    wait_for("a running job", 60, || {
        !running().is_empty() && run.join("run.json").exists()
    });
    let st = mesoflow(&["status", run.to_str().unwrap()], s.dir.path());
    assert_eq!(st.code, 0, "{}", st.stderr);
    assert!(
        st.stdout.contains("running") && st.stdout.contains("slow0"),
        "{}",
        st.stdout
    );
    let c = mesoflow(&["cancel", run.to_str().unwrap()], s.dir.path());
    assert_eq!(c.code, 0, "{}", c.stderr);
    let t = Instant::now();
    assert_eq!(driver.wait().unwrap().code(), Some(130));
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    wait_for("the run's jobs to leave the queue", 30, || {
        running().is_empty()
    });
}

#[test]
fn a_detached_driver_runs_as_a_job() {
    let Some((_one, _)) = begin() else { return };
    let s = Scratch::new();
    // Two short units: the driver holds one CPU, they take the other.
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "a": {"kind": "scalar.constant", "params": {"value": 2}},
            "b": {"kind": "scalar.affine", "inputs": {"x": "a.value"}, "params": {"scale": 3}}}}"#,
    );
    let r = mesoflow(
        &[
            "run",
            g.to_str().unwrap(),
            "--engine",
            "slurm",
            "--detach",
            "--out-dir",
            s.path("o").to_str().unwrap(),
            "--cache-dir",
            s.path("shared-cache").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains("submitted the driver as job"),
        "{}",
        r.stdout
    );
    wait_for("the detached run's report", 120, || {
        s.path("o/report.json").exists()
    });
    let rep = report(&s.path("o"));
    assert_eq!(rep["ok"], true);
    assert_eq!(metric(&rep, "b", "y"), 6.0);
}
