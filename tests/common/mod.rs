//! Helpers for the command-line tests: a scratch folder, graph files, running the binary, the
//! small pipeline the cache and cancellation tests share.
#![allow(dead_code)]

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub struct Scratch {
    pub dir: tempfile::TempDir,
}

impl Scratch {
    pub fn new() -> Self {
        Scratch {
            dir: tempfile::tempdir().expect("temp dir"),
        }
    }
    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }
    pub fn write(&self, rel: &str, text: &str) -> PathBuf {
        let p = self.path(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).unwrap();
        }
        std::fs::write(&p, text).unwrap();
        p
    }
}

/// The `mesoflow` binary as the test kit finds it (one place for every test and bench), with
/// no inherited cache folder.
pub fn bin() -> Command {
    let mut c = Command::new(mesoflow_testkit::cli::bin());
    c.env_remove("MESOFLOW_CACHE");
    c
}

pub struct Run {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

impl Run {
    pub fn from(o: Output) -> Run {
        Run {
            code: o.status.code().unwrap_or(-1),
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        }
    }
}

pub fn mesoflow(args: &[&str], cwd: &Path) -> Run {
    Run::from(
        bin()
            .args(args)
            .current_dir(cwd)
            .output()
            .expect("run mesoflow"),
    )
}

pub fn report(out_dir: &Path) -> Value {
    let text = std::fs::read_to_string(out_dir.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("report is JSON")
}

/// The metric `m` of node `id` in a report; panics naming what is missing.
pub fn metric(report: &Value, id: &str, m: &str) -> f64 {
    report["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == id)
        .unwrap_or_else(|| panic!("no node {id}"))["metrics"][m]
        .as_f64()
        .unwrap_or_else(|| panic!("{id} has no {m}"))
}

/// node id → the string `field` of that node, for the nodes in a report.
pub fn per_node(report: &Value, field: &str) -> std::collections::BTreeMap<String, String> {
    report["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            (
                n["id"].as_str().unwrap().to_string(),
                n[field].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

pub fn statuses(report: &Value) -> std::collections::BTreeMap<String, String> {
    per_node(report, "status")
}

pub fn keys(report: &Value) -> std::collections::BTreeMap<String, String> {
    per_node(report, "key")
}

/// A cache folder holds no temporary (half-written) entry.
pub fn assert_no_temp_files(cache: &Path) {
    let tmp = cache.join("tmp");
    assert!(
        !tmp.exists() || std::fs::read_dir(&tmp).unwrap().next().is_none(),
        "temporary files left in {}",
        tmp.display()
    );
}

pub use mesoflow_testkit::npy::npy_bytes;

/// The Python the peers run from, if it can `import` every module of `imports` (comma
/// separated): `MESOFLOW_PEER_PYTHON`, else `target/peer-venv/bin/python` (what `.ci/run`
/// makes). Without one the caller says so and passes, unless `MESOFLOW_REQUIRE_PEERS=1` (set by
/// CI), where this fails.
pub fn peer_python(imports: &str) -> Option<PathBuf> {
    let candidate = std::env::var_os("MESOFLOW_PEER_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("target/peer-venv/bin/python")
        });
    let ok = Command::new(&candidate)
        .args(["-c", &format!("import {imports}")])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(candidate);
    }
    let msg = format!(
        "no Python that can import {imports} at {} (set MESOFLOW_PEER_PYTHON, or run .ci/run once)",
        candidate.display()
    );
    mesoflow_testkit::skip_unless_required("MESOFLOW_REQUIRE_PEERS", &msg);
    None
}

/// Runs `tests/peers/<script>` with the peer Python and these arguments; fails with the
/// script's own error output when it does.
pub fn run_peer(python: &Path, script: &str, args: &[&Path]) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/peers")
        .join(script);
    let out = Command::new(python)
        .arg(&path)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", python.display()));
    assert!(
        out.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// An `.npy` of f32 as (shape, values).
pub fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let npy = npyz::NpyFile::new(&bytes[..]).expect("an .npy file");
    let shape: Vec<usize> = npy.shape().iter().map(|d| *d as usize).collect();
    (shape, npy.into_vec().expect("f32 values"))
}

/// A reader, two derived nodes and writers: enough to see exactly what a change touches.
pub fn pipeline(s: &Scratch) -> std::path::PathBuf {
    // A 2-D float32 NPY file written by hand (numpy's v1.0 format) so the test needs no numpy.
    write_npy(&s.path("data/tile.npy"), 8, 8, |x, y| {
        ((x * 3 + y * 5) % 7) as f32
    });
    s.write(
        "data/g.json",
        r#"{
          "mesoflow": 1,
          "nodes": {
            "tile": {"kind": "heightfield.read", "params": {"path": "tile.npy", "depth": 2.0}},
            "surface": {"kind": "heightfield.procedural", "params": {"size": 16, "pattern": "bumps", "count": 2}},
            "n_tile": {"kind": "heightfield.normals", "inputs": {"height": "tile.height"}},
            "n_surface": {"kind": "heightfield.normals", "inputs": {"height": "surface.height"}},
            "w_tile": {"kind": "image.write", "inputs": {"image": "n_tile.preview"}, "params": {"path": "tile.png"}},
            "w_surface": {"kind": "npy.write", "inputs": {"value": "n_surface.normals"}, "params": {"path": "surface.npy"}}
          }
        }"#,
    )
}

pub fn write_npy(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> f32) {
    let payload: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .flat_map(|(x, y)| f(x, y).to_le_bytes())
        .collect();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, npy_bytes("<f4", false, &[h, w], &payload)).unwrap();
}

/// `mesoflow run GRAPH --quiet --no-cache --out-dir OUT` in the background, for Ctrl-C tests.
pub fn spawn_run(graph: &Path, out: &Path, cwd: &Path) -> std::process::Child {
    bin()
        .args([
            "run",
            graph.to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--out-dir",
        ])
        .arg(out)
        .current_dir(cwd)
        .spawn()
        .unwrap()
}

/// Ctrl-C, as a terminal sends it.
pub fn interrupt(child: &std::process::Child) {
    let ok = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
}

pub fn run(s: &Scratch, graph: &Path, out: &str, extra: &[&str]) -> (Run, serde_json::Value) {
    let out_dir = s.path(out);
    let mut args = vec![
        "run",
        graph.to_str().unwrap(),
        "--quiet",
        "--out-dir",
        out_dir.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let r = mesoflow(&args, s.dir.path());
    let rep = report(&out_dir);
    (r, rep)
}

pub fn ids<'a>(st: &'a std::collections::BTreeMap<String, String>, status: &str) -> Vec<&'a str> {
    st.iter()
        .filter(|(_, v)| *v == status)
        .map(|(k, _)| k.as_str())
        .collect()
}

/// `mesoflow run GRAPH --quiet --no-cache --out-dir OUT` with `--set` pairs; the report.
pub fn run_graph(root: &Path, graph: &str, out: &Path, sets: &[String]) -> serde_json::Value {
    let (r, report) = try_run_graph(root, graph, out, sets);
    assert_eq!(r.code, 0, "{}", r.stderr);
    report
}

/// As [`run_graph`], for a run that may fail: its exit status and stderr, and the report
/// (written for a failed run too, the failed nodes marked).
pub fn try_run_graph(
    root: &Path,
    graph: &str,
    out: &Path,
    sets: &[String],
) -> (Run, serde_json::Value) {
    let mut args: Vec<String> = vec![
        "run".into(),
        root.join(graph).display().to_string(),
        "--quiet".into(),
        "--no-cache".into(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    for kv in sets {
        args.push("--set".into());
        args.push(kv.clone());
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = mesoflow(&args, root);
    (r, report(out))
}

/// Runs a graph file into `out/` beside it (`--quiet`, the cache beside the file); the folder
/// and its report.
pub fn run_beside(s: &Scratch, file: &Path) -> (PathBuf, Value) {
    let out = s.path("out");
    let r = mesoflow(
        &[
            "run",
            file.to_str().unwrap(),
            "--quiet",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    (out, rep)
}

/// Our image (RGB) against a peer's two renders at two seeds (RGBA): the relative RMSE against
/// their mean, the peer's own noise (half the two renders' difference, relative) and the
/// channel sums' ratios, ours over theirs.
pub fn compare_to_peer(ours: &[f32], theirs: [&[f32]; 2]) -> (f64, f64, [f64; 3]) {
    let n = ours.len() / 3;
    assert_eq!(
        theirs[0].len(),
        n * 4,
        "the peer's image has the same pixels"
    );
    let (mut diff2, mut ref2, mut half2) = (0.0, 0.0, 0.0);
    let (mut our_sum, mut their_sum) = ([0.0; 3], [0.0; 3]);
    for i in 0..n {
        for k in 0..3 {
            let (a, b) = (theirs[0][i * 4 + k] as f64, theirs[1][i * 4 + k] as f64);
            let m = 0.5 * (a + b);
            let o = ours[i * 3 + k] as f64;
            diff2 += (o - m) * (o - m);
            ref2 += m * m;
            half2 += (a - b) * (a - b) / 4.0;
            our_sum[k] += o;
            their_sum[k] += m;
        }
    }
    let ratio = [0, 1, 2].map(|k| our_sum[k] / their_sum[k]);
    ((diff2 / ref2).sqrt(), (half2 / ref2).sqrt(), ratio)
}
