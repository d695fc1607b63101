//! End-to-end runs through the command line and a real disk cache: incremental re-execution,
//! cache keys, corruption, concurrency, cancellation, failure isolation, determinism, sweeps.

mod common;
use common::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// A reader, two derived nodes and writers: enough to see exactly what a change touches.
fn pipeline(s: &Scratch) -> std::path::PathBuf {
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

fn write_npy(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> f32) {
    let payload: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .flat_map(|(x, y)| f(x, y).to_le_bytes())
        .collect();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, npy_bytes("<f4", false, &[h, w], &payload)).unwrap();
}

/// `mesoflow run GRAPH --quiet --no-cache --out-dir OUT` in the background, for Ctrl-C tests.
fn spawn_run(graph: &Path, out: &Path, cwd: &Path) -> std::process::Child {
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
fn interrupt(child: &std::process::Child) {
    let ok = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
}

fn run(s: &Scratch, graph: &Path, out: &str, extra: &[&str]) -> (Run, serde_json::Value) {
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

fn ids<'a>(st: &'a std::collections::BTreeMap<String, String>, status: &str) -> Vec<&'a str> {
    st.iter()
        .filter(|(_, v)| *v == status)
        .map(|(k, _)| k.as_str())
        .collect()
}

#[test]
fn incremental_reexecution_recomputes_exactly_what_changed() {
    let s = Scratch::new();
    let g = pipeline(&s);
    let (r, rep) = run(&s, &g, "o1", &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(ids(&statuses(&rep), "computed").len(), 6);
    assert!(
        s.path("data/.mesoflow/cache").is_dir(),
        "default cache beside the graph"
    );

    // Again: every node reported is a cache hit and nothing is computed; the writers' files
    // are written again from the cache.
    let (r, rep) = run(&s, &g, "o2", &[]);
    assert_eq!(r.code, 0);
    let st = statuses(&rep);
    assert!(ids(&st, "computed").is_empty(), "{st:?}");
    assert_eq!(ids(&st, "disk"), vec!["w_surface", "w_tile"]);
    assert!(s.path("o2/tile.png").is_file() && s.path("o2/surface.npy").is_file());

    // One parameter: exactly that node and its descendants recompute.
    let (r, rep) = run(&s, &g, "o3", &["--set", "n_surface.scale=2"]);
    assert_eq!(r.code, 0);
    let st = statuses(&rep);
    assert_eq!(ids(&st, "computed"), vec!["n_surface", "w_surface"]);
    assert_eq!(ids(&st, "disk"), vec!["surface", "w_tile"]);

    // A file a source node reads: its descendants recompute, nothing else.
    write_npy(&s.path("data/tile.npy"), 8, 8, |x, y| ((x + y) % 3) as f32);
    let (r, rep) = run(&s, &g, "o4", &[]);
    assert_eq!(r.code, 0);
    let st = statuses(&rep);
    assert_eq!(ids(&st, "computed"), vec!["n_tile", "tile", "w_tile"]);
    assert_eq!(ids(&st, "disk"), vec!["w_surface"]);
    assert!(rep["read"]
        .as_array()
        .unwrap()
        .iter()
        .any(|p| p.as_str().unwrap().ends_with("tile.npy")));
}

#[test]
fn requested_outputs_limit_what_runs() {
    let s = Scratch::new();
    let g = pipeline(&s);
    let (r, rep) = run(&s, &g, "o", &["--output", "n_surface.rms_slope"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(
        statuses(&rep).keys().cloned().collect::<Vec<_>>(),
        vec!["n_surface", "surface"]
    );
    assert!(rep["nodes"][1]["metrics"]["rms_slope"].as_f64().unwrap() > 0.0);
    let (r, _) = run(&s, &g, "o", &["--output", "n_surface.nope"]);
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("has no output `nope`"), "{}", r.stderr);
}

#[test]
fn keys_do_not_depend_on_folder_process_or_parameter_order() {
    let a = Scratch::new();
    let b = Scratch::new();
    let ga = pipeline(&a);
    // The same graph, parameters written in another order, in another folder.
    write_npy(&b.path("elsewhere/tile.npy"), 8, 8, |x, y| {
        ((x * 3 + y * 5) % 7) as f32
    });
    let text = std::fs::read_to_string(&ga).unwrap().replace(
        r#""params": {"size": 16, "pattern": "bumps", "count": 2}"#,
        r#""params": {"pattern": "bumps", "count": 2, "size": 16}"#,
    );
    assert!(text.contains(r#""pattern": "bumps", "count": 2, "size""#));
    let gb = b.write("elsewhere/g.json", &text);
    let (_, ra) = run(&a, &ga, "o", &[]);
    let (_, rb) = run(&b, &gb, "o", &[]);
    assert_eq!(keys(&ra), keys(&rb));
    // The file named by an absolute path (as on another machine's shared filesystem): the same
    // keys, because a key holds the file's name and contents, not where it was found.
    let abs = b.path("elsewhere/tile.npy");
    let gc = b.write(
        "other/g.json",
        &text.replace(
            r#""path": "tile.npy""#,
            &format!(r#""path": "{}""#, abs.display()),
        ),
    );
    assert!(std::fs::read_to_string(&gc)
        .unwrap()
        .contains(&abs.display().to_string()));
    let (_, rc) = run(&b, &gc, "o2", &[]);
    assert_eq!(keys(&ra), keys(&rc));

    // The last bit of a float parameter changes the key (6.0 and the next double up).
    let (_, r1) = run(&a, &ga, "p", &["--set", "surface.depth=6.0", "--no-cache"]);
    let (_, r2) = run(
        &a,
        &ga,
        "q",
        &["--set", "surface.depth=6.000000000000001", "--no-cache"],
    );
    assert_ne!(keys(&r1)["surface"], keys(&r2)["surface"]);
    assert_eq!(keys(&r1)["tile"], keys(&r2)["tile"]);
    // Writing a default explicitly is the same as omitting it (defaults enter the canonical form).
    let (_, r3) = run(&a, &ga, "r", &["--set", "surface.seed=1", "--no-cache"]);
    assert_eq!(keys(&r3)["surface"], keys(&ra)["surface"]);
}

#[test]
fn corrupted_cache_entries_are_warned_about_and_recomputed() {
    let s = Scratch::new();
    let g = pipeline(&s);
    let (_, rep) = run(&s, &g, "o1", &[]);
    let cache = s.path("data/.mesoflow/cache");
    let entry = |id: &str| {
        let node = rep["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["id"] == id)
            .unwrap();
        let key = node["key"].as_str().unwrap().to_string();
        cache.join(&key[..2]).join(format!("{key}.mfc"))
    };
    let (truncate, flip) = (entry("w_tile"), entry("w_surface"));
    let bytes = std::fs::read(&truncate).unwrap();
    std::fs::write(&truncate, &bytes[..bytes.len() / 2]).unwrap();
    let mut bytes = std::fs::read(&flip).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(&flip, bytes).unwrap();

    let (r, rep) = run(&s, &g, "o2", &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let st = statuses(&rep);
    assert_eq!(st["w_tile"], "computed");
    assert_eq!(st["w_surface"], "computed");
    let warnings = rep["warnings"].as_array().unwrap();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(warnings
        .iter()
        .all(|w| w["message"].as_str().unwrap().contains("recomputing")));
    // The recomputed entries replaced the bad ones.
    let (_, rep) = run(&s, &g, "o3", &[]);
    assert!(ids(&statuses(&rep), "computed").is_empty());
    assert!(rep["warnings"].as_array().unwrap().is_empty());
}

#[test]
fn two_processes_share_one_cache() {
    let s = Scratch::new();
    let g = pipeline(&s);
    let cache = s.path("shared-cache");
    let spawn = |out: &str| {
        bin()
            .args([
                "run",
                g.to_str().unwrap(),
                "--quiet",
                "--out-dir",
                s.path(out).to_str().unwrap(),
            ])
            .arg("--cache-dir")
            .arg(&cache)
            .current_dir(s.dir.path())
            .spawn()
            .unwrap()
    };
    for round in 0..3 {
        let (a, b) = (format!("a{round}"), format!("b{round}"));
        let (mut pa, mut pb) = (spawn(&a), spawn(&b));
        assert!(pa.wait().unwrap().success());
        assert!(pb.wait().unwrap().success());
        for f in ["tile.png", "surface.npy"] {
            assert_eq!(
                std::fs::read(s.path(&a).join(f)).unwrap(),
                std::fs::read(s.path(&b).join(f)).unwrap()
            );
        }
    }
    assert_no_temp_files(&cache);
}

#[test]
fn ctrl_c_cancels_with_130_and_leaves_no_partial_entry() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "quick": {"kind": "debug.sleep", "params": {"ms": 1}},
            "slow": {"kind": "debug.sleep", "inputs": {"x": "quick.y"}, "params": {"ms": 60000}},
            "after": {"kind": "scalar.affine", "inputs": {"x": "slow.y"}}
        }}"#,
    );
    let out = s.path("o");
    let mut child = bin()
        .args([
            "run",
            g.to_str().unwrap(),
            "--quiet",
            "--out-dir",
            out.to_str().unwrap(),
        ])
        .current_dir(s.dir.path())
        .spawn()
        .unwrap();
    // Wait until `quick` is cached, i.e. `slow` is running.
    let cache = s.path(".mesoflow/cache");
    let start = Instant::now();
    while mesoflow(
        &[
            "cache",
            "stats",
            "--json",
            "--cache-dir",
            cache.to_str().unwrap(),
        ],
        s.dir.path(),
    )
    .stdout
    .contains("\"entries\": 0")
    {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "quick never finished"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(300));
    interrupt(&child);
    let t = Instant::now();
    let status = child.wait().unwrap();
    assert!(
        t.elapsed() < Duration::from_secs(10),
        "cancellation took {:?}",
        t.elapsed()
    );
    assert_eq!(status.code(), Some(130));
    let rep = report(&out);
    assert_eq!(rep["cancelled"], true);
    let st = statuses(&rep);
    assert_eq!(
        (
            st["quick"].as_str(),
            st["slow"].as_str(),
            st["after"].as_str()
        ),
        ("computed", "cancelled", "cancelled")
    );
    let stats = mesoflow(
        &[
            "cache",
            "stats",
            "--json",
            "--cache-dir",
            cache.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    let stats: serde_json::Value = serde_json::from_str(&stats.stdout).unwrap();
    assert_eq!(stats["entries"], 1, "only `quick` is cached: {stats}");
    assert_no_temp_files(&cache);
}

#[test]
fn a_second_ctrl_c_quits_at_once_and_still_writes_the_report() {
    // `slow` ignores cancellation (a node stuck in a long loop): the first Ctrl-C cannot end the
    // run, the second ends the process, and the report says what had finished.
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "quick": {"kind": "debug.sleep", "params": {"ms": 1}},
            "slow": {"kind": "debug.sleep", "inputs": {"x": "quick.y"}, "params": {"ms": 60000, "deaf": true}}
        }}"#,
    );
    let out = s.path("o");
    let child = spawn_run(&g, &out, s.dir.path());
    // Give the run time to finish `quick` and start `slow`.
    std::thread::sleep(Duration::from_millis(1500));
    interrupt(&child);
    std::thread::sleep(Duration::from_millis(500));
    interrupt(&child);
    let t = Instant::now();
    let mut child = child;
    let status = child.wait().unwrap();
    assert!(
        t.elapsed() < Duration::from_secs(10),
        "took {:?}",
        t.elapsed()
    );
    assert_eq!(status.code(), Some(130));
    let rep = report(&out);
    assert_eq!(rep["cancelled"], true);
    assert_eq!(rep["ok"], false);
    assert_eq!(statuses(&rep)["quick"], "computed");
    assert!(
        rep["warnings"][0]["message"]
            .as_str()
            .unwrap()
            .contains("interrupted twice"),
        "{rep}"
    );
}

#[test]
fn a_failure_stops_its_dependants_and_lets_independent_nodes_finish() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "bad": {"kind": "heightfield.read", "params": {"path": "missing.npy"}},
            "uses_bad": {"kind": "heightfield.normals", "inputs": {"height": "bad.height"}},
            "boom": {"kind": "debug.sleep", "params": {"ms": 1, "fail": true}},
            "after_boom": {"kind": "scalar.affine", "inputs": {"x": "boom.y"}},
            "fine": {"kind": "debug.sleep", "params": {"ms": 200}}
        }}"#,
    );
    let (r, rep) = run(&s, &g, "o", &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(rep["ok"], false);
    let st = statuses(&rep);
    assert_eq!(st["fine"], "computed");
    assert_eq!(st["bad"], "failed");
    assert_eq!(st["boom"], "failed");
    assert_eq!(st["uses_bad"], "cancelled");
    assert_eq!(st["after_boom"], "cancelled");
    let err = |id: &str| {
        rep["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["id"] == id)
            .unwrap()["error"]
            .as_str()
            .unwrap()
            .to_string()
    };
    assert!(
        err("bad").contains("node `bad`") && err("bad").contains("missing.npy"),
        "{}",
        err("bad")
    );
    assert!(
        err("after_boom").contains("`boom` failed"),
        "{}",
        err("after_boom")
    );
    assert!(r.stderr.contains("node `boom`"), "{}", r.stderr);
}

#[test]
fn outputs_are_bit_identical_whatever_the_thread_count() {
    let s = Scratch::new();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let g = root.join("graphs/quickstart.json");
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = s.path(&format!("t{threads}"));
        let r = bin()
            .args([
                "run",
                g.to_str().unwrap(),
                "--quiet",
                "--no-cache",
                "--device",
                "cpu",
                "--out-dir",
                out.to_str().unwrap(),
            ])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        outs.push(out);
    }
    let files = ["normals.png", "height.exr", "height.png", "height.npy"];
    for f in files {
        assert_eq!(
            std::fs::read(outs[0].join(f)).unwrap(),
            std::fs::read(outs[1].join(f)).unwrap(),
            "{f}"
        );
    }
    let m = |o: &Path| {
        report(o)["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["id"] == "normals")
            .unwrap()["metrics"]["rms_slope"]
            .clone()
    };
    assert_eq!(m(&outs[0]), m(&outs[1]));
}

#[test]
fn verify_cache_recomputes_hits_and_accepts_matching_ones() {
    let s = Scratch::new();
    let g = pipeline(&s);
    run(&s, &g, "o1", &[]);
    let (r, rep) = run(&s, &g, "o2", &["--verify-cache"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let nodes = rep["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 6, "verification pulls every ancestor");
    assert!(
        nodes
            .iter()
            .all(|n| n["verified"] == true && n["status"] == "disk"),
        "{nodes:?}"
    );
}

#[test]
fn sweep_writes_csv_and_charts_and_computes_upstream_once() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "surface": {"kind": "heightfield.procedural", "params": {"size": 32, "pattern": "noise"}},
            "normals": {"kind": "heightfield.normals", "inputs": {"height": "surface.height"}},
            "save": {"kind": "image.write", "inputs": {"image": "normals.preview"}, "params": {"path": "n.png"}}
        }}"#,
    );
    let out = s.path("sweep");
    let r = mesoflow(
        &[
            "sweep",
            g.to_str().unwrap(),
            "--vary",
            "normals.scale=0.5,1,2",
            "--measure",
            "normals.rms_slope",
            "--quiet",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "normals.scale,normals.rms_slope,normals.seconds,run_seconds,ok"
    );
    assert_eq!(lines.len(), 4);
    // rms slope is linear in the scale (∇(s·h) = s·∇h): compare with the first row exactly.
    let slope = |l: &str| l.split(',').nth(1).unwrap().parse::<f64>().unwrap();
    let base = slope(lines[2]);
    assert!(
        (slope(lines[1]) - 0.5 * base).abs() < 1e-6 * base
            && (slope(lines[3]) - 2.0 * base).abs() < 1e-6 * base,
        "{csv}"
    );
    for f in [
        "normals.rms_slope_vs_normals.scale",
        "normals.rms_slope_vs_seconds",
    ] {
        for ext in ["png", "svg"] {
            let p = out.join(format!("{f}.{ext}"));
            assert!(
                std::fs::metadata(&p)
                    .map(|m| m.len() > 1000)
                    .unwrap_or(false),
                "{} missing or empty",
                p.display()
            );
        }
    }
    let r = mesoflow(
        &[
            "sweep",
            g.to_str().unwrap(),
            "--vary",
            "normals.scale=1",
            "--measure",
            "normals.preview",
            "--quiet",
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains("a measure must be a scalar output"),
        "{}",
        r.stderr
    );
    let computed =
        |i: usize| statuses(&report(&out.join(format!("runs/{i:03}"))))["surface"].clone();
    assert_eq!(computed(0), "computed");
    assert_eq!(computed(1), "memory");
    assert_eq!(computed(2), "memory");
}

#[test]
fn watch_reruns_only_what_a_change_touches() {
    let s = Scratch::new();
    let g = pipeline(&s);
    let out = s.path("w");
    let child = bin()
        .args([
            "watch",
            g.to_str().unwrap(),
            "--quiet",
            "--max-runs",
            "2",
            "--interval-ms",
            "50",
            "--out-dir",
            out.to_str().unwrap(),
        ])
        .current_dir(s.dir.path())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !out.join("report.json").exists() {
        assert!(start.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(300));
    write_npy(&s.path("data/tile.npy"), 8, 8, |x, _| x as f32);
    let o = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}");
    assert!(
        stdout.contains("run 2: re-ran tile, n_tile, w_tile"),
        "{stdout}"
    );
}

#[test]
fn quickstart_writes_png_and_exr() {
    let s = Scratch::new();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = s.path("q");
    let r = mesoflow(
        &[
            "run",
            root.join("graphs/quickstart.json").to_str().unwrap(),
            "--out-dir",
            out.to_str().unwrap(),
            "--no-cache",
        ],
        root,
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains("normals") && r.stdout.contains("ok in"),
        "summary table: {}",
        r.stdout
    );
    for f in ["normals.png", "height.exr", "height.npy", "report.json"] {
        assert!(out.join(f).is_file(), "{f}");
    }
}

#[test]
fn gpu_nodes_fall_back_to_the_cpu_unless_a_gpu_is_required() {
    // WGPU_BACKEND=dx12 on Linux leaves wgpu without any adapter: the no-GPU machine, simulated.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let go = |out: &str, require: &str| {
        let out = s.path(out);
        let r = Run::from(
            bin()
                .args([
                    "run",
                    g.to_str().unwrap(),
                    "--quiet",
                    "--no-cache",
                    "--output",
                    "normals.rms_slope",
                    "--out-dir",
                    out.to_str().unwrap(),
                ])
                .env("WGPU_BACKEND", "dx12")
                .env("MESOFLOW_REQUIRE_GPU", require)
                .output()
                .unwrap(),
        );
        (r, report(&out))
    };
    let (r, rep) = go("fallback", "0");
    assert_eq!(r.code, 0, "{}", r.stderr);
    let normals = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "normals")
        .unwrap()
        .clone();
    assert_eq!(normals["device"], "cpu");
    let w = rep["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w["node"] == "normals"
            && w["message"].as_str().unwrap().contains("ran the CPU path")),
        "{w:?}"
    );

    let (r, rep) = go("required", "1");
    assert_eq!(r.code, 1);
    let normals = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "normals")
        .unwrap()
        .clone();
    assert_eq!(normals["status"], "failed");
    assert!(
        normals["error"]
            .as_str()
            .unwrap()
            .contains("MESOFLOW_REQUIRE_GPU=1"),
        "{normals}"
    );

    // --device cpu is an explicit choice: no adapter needed, no warning.
    let out = s.path("cpu");
    let r = bin()
        .args([
            "run",
            g.to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--device",
            "cpu",
            "--out-dir",
            out.to_str().unwrap(),
        ])
        .env("WGPU_BACKEND", "dx12")
        .env("MESOFLOW_REQUIRE_GPU", "1")
        .output()
        .unwrap();
    assert!(r.status.success());
    assert!(report(&out)["warnings"].as_array().unwrap().is_empty());
}

#[test]
fn btf_pipeline_reports_the_error_it_measures() {
    // btf.pca reports the Eckart–Young RMSE; btf.compare measures the reconstruction. They agree
    // to f32 storage precision of the basis (1e-4 relative is generous).
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let r = mesoflow(
        &[
            "run",
            root.join("graphs/btf_compress.json").to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--set",
            "surface.size=16",
            "--set",
            "surface.count=2",
            "--set",
            "pca.rank=3",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        root,
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let metric = |id: &str, m: &str| metric(&rep, id, m);
    let (reported, measured) = (metric("pca", "rmse"), metric("compare", "rmse"));
    assert!(
        reported > 0.0 && (reported - measured).abs() <= 1e-4 * reported,
        "{reported} vs {measured}"
    );
    assert_eq!(metric("pca", "rank"), 3.0);
    let table = std::fs::read_to_string(out.join("btf_errors.csv")).unwrap();
    assert_eq!(table.lines().count(), 1 + 9 * 9, "a row per direction pair");
    assert!(table.contains(",30,0,"), "degrees print cleanly: {table}");
    assert!(out.join("per_pair_rmse.exr").is_file() && out.join("capture.png").is_file());
}

#[test]
fn ubo2003_files_written_by_one_graph_read_back_bit_exactly_in_another() {
    // btf_capture.json writes EXR files; a second graph captures the same surface, reads the
    // files and compares: EXR holds f32 exactly and the running index keeps the pair order, so
    // the error is exactly zero.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let small = ["--set", "surface.size=16", "--set", "surface.count=2"];
    let mut args = vec![
        "run".to_string(),
        root.join("graphs/btf_capture.json")
            .to_str()
            .unwrap()
            .to_string(),
    ];
    args.extend(small.iter().map(|a| a.to_string()));
    args.extend(["--quiet", "--no-cache", "--out-dir", out.to_str().unwrap()].map(String::from));
    let r = mesoflow(&args.iter().map(String::as_str).collect::<Vec<_>>(), root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let text = std::fs::read_to_string(root.join("graphs/btf_capture.json")).unwrap();
    let mut g: serde_json::Value = serde_json::from_str(&text).unwrap();
    let nodes = g["nodes"].as_object_mut().unwrap();
    nodes.remove("files");
    nodes.remove("preview_png");
    nodes.insert(
        "read".into(),
        serde_json::json!({ "kind": "btf.read_ubo2003", "params": { "path": "o/ubo2003" } }),
    );
    nodes.insert(
        "compare".into(),
        serde_json::json!({ "kind": "btf.compare",
            "inputs": { "reference": "capture.btf", "btf": "read.btf" } }),
    );
    let graph = s.write("readback.json", &g.to_string());
    let out2 = s.path("o2");
    let mut args = vec!["run".to_string(), graph.to_str().unwrap().to_string()];
    args.extend(small.iter().map(|a| a.to_string()));
    args.extend(["--quiet", "--no-cache", "--out-dir", out2.to_str().unwrap()].map(String::from));
    let r = mesoflow(&args.iter().map(String::as_str).collect::<Vec<_>>(), root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out2);
    let compare = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "compare")
        .unwrap();
    assert_eq!(compare["metrics"]["rmse"], 0.0);
    assert_eq!(compare["metrics"]["max_error"], 0.0);
}

#[test]
fn mdf_render_graph_renders_with_and_without_silhouettes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let dirs = r#"{"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#;
    let mut args: Vec<String> = vec![
        "run".into(),
        root.join("graphs/mdf_render.json").display().to_string(),
        "--quiet".into(),
        "--no-cache".into(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    let mut set = |kv: String| {
        args.push("--set".into());
        args.push(kv);
    };
    set("surface.size=16".into());
    set("surface.count=2".into());
    set(format!("capture.views={dirs}"));
    set(format!("capture.lights={dirs}"));
    set(format!("mdf.views={dirs}"));
    for r in [
        "sphere_plain",
        "sphere_mdf",
        "torus_plain",
        "torus_mdf",
        "torus_reference",
    ] {
        set(format!("{r}.camera.resolution=[48,36]"));
        set(format!("{r}.shadow_resolution=128"));
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = mesoflow(&args, root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let metric = |id: &str, m: &str| metric(&rep, id, m);
    // The MDF carves the outline: fewer pixels show the torus than without it.
    assert!(metric("torus_mdf", "coverage") < metric("torus_plain", "coverage"));
    // Timings are in the report, not among the outputs (they are not cached).
    let node = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "torus_mdf")
        .unwrap();
    assert!(node["timings"]["frame_ms"].as_f64().unwrap() > 0.0);
    assert!(node["metrics"].get("frame_ms").is_none());
    let rmse = metric("error", "rmse");
    assert!(
        rmse.is_finite() && rmse > 0.0,
        "PCA rank 16 of 81 pairs is lossy: {rmse}"
    );
    let row = image::open(out.join("torus_plain_vs_mdf.png")).unwrap();
    assert_eq!((row.width(), row.height()), (48 + 4 + 48, 36));
    let mut f = std::fs::File::open(out.join("weave_mdf.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[9, 16, 16]);
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("weave_mdf.json")).unwrap())
            .unwrap();
    assert_eq!(side["views"].as_array().unwrap().len(), 9);
    assert_eq!(side["views"][1], serde_json::json!([40.0, 0.0]));
}

/// `mesoflow run GRAPH --quiet --no-cache --out-dir OUT` with `--set` pairs; the report.
fn run_graph(root: &Path, graph: &str, out: &Path, sets: &[String]) -> serde_json::Value {
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
    assert_eq!(r.code, 0, "{}", r.stderr);
    report(out)
}

#[test]
fn sss_models_graph_compares_a_model_with_monte_carlo_and_writes_f64_profiles() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/sss_models.json",
        &out,
        &["reference.photons=20000".into(), "profile.points=64".into()],
    );
    // Ketchup red: the dipole is ~10% high against Monte Carlo (domain notes: ≈12%).
    let e = metric(&rep, "error", "total_error_r");
    assert!((0.04..0.2).contains(&e), "{e}");
    assert!(metric(&rep, "reference", "stderr_r") > 0.0);
    // The NPY contract: (4, n) little-endian f64, radii first.
    let bytes = std::fs::read(out.join("profile.npy")).unwrap();
    let header = String::from_utf8_lossy(&bytes[10..128]).to_string();
    assert!(
        header.contains("'descr': '<f8'") && header.contains("'shape': (4, 64"),
        "{header}"
    );
}

#[test]
fn sss_render_and_qh_render_graphs_render() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let small = |ids: &[&str]| -> Vec<String> {
        ids.iter()
            .flat_map(|id| {
                [
                    format!("{id}.camera.resolution=[32,24]"),
                    format!("{id}.shadow_resolution=128"),
                    format!("{id}.max_points=3000"),
                ]
            })
            .collect()
    };
    let rep = run_graph(
        root,
        "graphs/sss_render.json",
        &s.path("a"),
        &small(&["marble", "skin", "marble_reference"]),
    );
    // The octree at 0.05 is close to brute force (the sss.render tests bound it).
    assert!(metric(&rep, "marble_error", "rmse") < 0.01);
    assert!(metric(&rep, "skin", "points") <= 3000.0);
    assert!(s.path("a").join("marble_and_skin.png").exists());
    let mut sets = small(&["homogeneous", "qh"]);
    sets.extend([
        "surface.size=16".into(),
        "surface.count=2".into(),
        r#"lrf.views={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#.into(),
        r#"lrf.lights={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#.into(),
    ]);
    run_graph(root, "graphs/qh_render.json", &s.path("b"), &sets);
    assert!(s.path("b").join("homogeneous_vs_qh.png").exists());
}

#[test]
fn isomap_graph_embeds_the_swiss_roll_as_f64_npy() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(root, "graphs/isomap.json", &out, &[]);
    assert_eq!(metric(&rep, "isomap", "graph_components"), 1.0);
    let rv = metric(&rep, "isomap", "residual_variance");
    assert!((0.0..0.05).contains(&rv), "{rv}");
    let mut f = std::fs::File::open(out.join("embedding.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[2000, 2]);
    assert!(npy.dtype().descr().contains("f8"));
}

#[test]
fn weathering_graph_recovers_the_degree_of_the_built_in_sample() {
    // The issue's bound (Spearman ≥ 0.95 against the true degree), from the command line, on a
    // 32² sample so the debug build stays quick; every pixel's fit converges.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/weathering.json",
        &out,
        &["sample.size=32".to_string()],
    );
    let rho = metric(&rep, "degree", "spearman");
    assert!(rho >= 0.95, "{rho}");
    assert_eq!(metric(&rep, "fit", "not_converged"), 0.0);
    assert!(out.join("degree_true_vs_recovered.png").exists());
    for dir in ["weathering", "deweathering"] {
        assert!(out.join(dir).join("frame_007.png").exists());
        let gif = std::fs::read(out.join(dir).join("frame.gif")).unwrap();
        assert_eq!(&gif[..6], b"GIF89a");
    }
    assert!(metric(&rep, "evolve", "mean_degree") > metric(&rep, "deweather", "mean_degree"));
    assert!(metric(&rep, "fit", "error_rho_d") < 1e-3);
    let mut f = std::fs::File::open(out.join("ward_maps.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[32, 32, 5]);
    assert!(npy.dtype().descr().contains("f8"));
}

#[test]
fn a_ward_fit_of_a_cook_torrance_sample_is_a_cross_model_check() {
    // The Ward fit of a Ward-rendered sample is a solver check (the data come from the model
    // fitted). Rendered with Cook–Torrance (Beckmann, Fresnel, masking–shadowing) the Ward fit
    // cannot match exactly: how far its parameters land and whether the degree survives is the
    // accuracy a user of real captures can expect. Bounds: about twice what a 32² sample
    // measured (ρd 0.19%, ρs 11%, α 5.4%, Spearman 0.9986), quoted in the README.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/weathering.json",
        &out,
        &[
            "sample.size=32".to_string(),
            "sample.reflectance=cook_torrance".to_string(),
        ],
    );
    let m = |id: &str, k: &str| metric(&rep, id, k);
    assert!(
        m("fit", "error_rho_d") < 0.005,
        "{}",
        m("fit", "error_rho_d")
    );
    assert!(m("fit", "error_rho_s") < 0.2, "{}", m("fit", "error_rho_s"));
    assert!(m("fit", "error_alpha") < 0.1, "{}", m("fit", "error_alpha"));
    assert!(
        m("fit", "error_rho_s") > 0.01,
        "not a solver check: the models differ"
    );
    assert!(
        m("degree", "spearman") >= 0.99,
        "{}",
        m("degree", "spearman")
    );
}

#[test]
fn weathering_transfer_graph_lays_the_degree_onto_a_larger_guided_target() {
    // The saved pipeline end to end: the synthesized degree map has the target's size, its
    // energy fell during the finest stage, it follows the guide (rust gathers where the ramp is
    // high: the bottom third's mean degree above the top third's), and the transferred maps and
    // the weathering frames exist.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(root, "graphs/weathering_transfer.json", &out, &[]);
    assert!(metric(&rep, "degree", "spearman") >= 0.95);
    assert!(metric(&rep, "synth", "energy") < metric(&rep, "synth", "energy_start"));
    let mut f = std::fs::File::open(out.join("target_degree.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[128, 192, 1]);
    let d: Vec<f32> = npy.into_vec().unwrap();
    let third = |rows: std::ops::Range<usize>| {
        let n = rows.len() * 192;
        rows.map(|y| d[y * 192..(y + 1) * 192].iter().sum::<f32>())
            .sum::<f32>()
            / n as f32
    };
    let (top, bottom) = (third(0..42), third(86..128));
    assert!(bottom > top + 0.3, "top {top}, bottom {bottom}");
    let mut f = std::fs::File::open(out.join("target_ward_maps.npy")).unwrap();
    assert_eq!(npyz::NpyFile::new(&mut f).unwrap().shape(), &[128, 192, 5]);
    assert!(out.join("target_weathering").join("frame_005.png").exists());
    assert!(out.join("target_guide_degree_appearance.png").exists());
    let m = metric(&rep, "evolve", "mean_degree");
    assert!(m > metric(&rep, "transfer", "mean_degree"), "{m}");
}

#[test]
fn weathering_graph_fits_a_bumpy_sample_with_photometric_normals() {
    // A relief tilting pixels up to 25° (sample.bumps): the photometric-stereo normals and the
    // joint refinement bring the fit back to the flat sample's accuracy (measured at 64²:
    // normal median 0.001°, parameter medians < 1e-6, Spearman 0.998; the flat fit on the same
    // data: 19% / 26% / 59%, Spearman 0.957). Bounds: the issue's 1e-3 and 0.95, normals 0.05°.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/weathering.json",
        &out,
        &[
            "sample.size=32".to_string(),
            "sample.bumps=0.08".to_string(),
            "fit.normals=photometric".to_string(),
        ],
    );
    assert!(metric(&rep, "fit", "error_normal_deg") < 0.05);
    for m in ["error_rho_d", "error_rho_s", "error_alpha"] {
        assert!(metric(&rep, "fit", m) < 1e-3, "{m}");
    }
    assert!(metric(&rep, "degree", "spearman") >= 0.95);
    assert_eq!(metric(&rep, "fit", "normal_fallbacks"), 0.0);
}

#[test]
fn qh_fit_graph_recovers_known_coefficients_through_the_monte_carlo_table() {
    // issue 5: σa and σs′ within 5% from a Monte Carlo profile made with known values. The
    // saved graph with fewer photons so the test build stays quick (measured at these counts:
    // about 3% σs′, 1–2% σa); PBD's bias shows in the same run.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/qh_fit.json",
        &out,
        &[
            "measured.photons=100000".to_string(),
            "fit_mc.photons=200000".to_string(),
            "refit.photons=50000".to_string(),
        ],
    );
    let (es, ea) = (
        metric(&rep, "fit_mc", "error_sigma_s_prime"),
        metric(&rep, "fit_mc", "error_sigma_a"),
    );
    assert!(es < 0.05 && ea < 0.05, "σs′ {es}, σa {ea}");
    assert!(metric(&rep, "fit_pbd", "error_sigma_a") > ea);
}

#[test]
fn a_machine_whose_only_adapter_is_software_opengl_runs_the_gpu_graphs_on_the_cpu_path() {
    // WGPU_BACKEND=gl: the machine without Mesa's Vulkan driver. `auto` must not pick llvmpipe
    // through GL (no float render targets, slower than the CPU path): the CPU path, a warning.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let dirs = r#"{"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#;
    let mut args: Vec<String> = vec![
        "run".into(),
        root.join("graphs/mdf_render.json").display().to_string(),
        "--quiet".into(),
        "--no-cache".into(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    let mut sets: Vec<String> = vec![
        "surface.size=16".into(),
        format!("capture.views={dirs}"),
        format!("capture.lights={dirs}"),
        format!("mdf.views={dirs}"),
    ];
    for r in [
        "sphere_plain",
        "sphere_mdf",
        "torus_plain",
        "torus_mdf",
        "torus_reference",
    ] {
        sets.push(format!("{r}.camera.resolution=[32,24]"));
    }
    for kv in sets {
        args.push("--set".into());
        args.push(kv);
    }
    let r = Run::from(
        bin()
            .args(&args)
            .env("WGPU_BACKEND", "gl")
            .env_remove("MESOFLOW_REQUIRE_GPU")
            .output()
            .unwrap(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let devices = per_node(&rep, "device");
    for id in ["mdf", "sphere_mdf", "torus_mdf"] {
        assert_eq!(devices[id], "cpu", "{id}: {rep}");
    }
    let w = rep["warnings"].as_array().unwrap();
    let why = |text: &str| {
        w.iter()
            .any(|w| w["node"] == "torus_mdf" && w["message"].as_str().unwrap().contains(text))
    };
    // CI installs Mesa's GL driver, so there the adapter exists and the reason is named.
    if std::env::var("CI").is_ok() {
        assert!(why("software OpenGL"), "{w:?}");
    } else {
        assert!(why("software OpenGL") || why("no GPU adapter"), "{w:?}");
    }
}

#[test]
fn hostile_inputs_get_clear_errors_not_panics_or_hangs() {
    let s = Scratch::new();
    let run = |name: &str, graph: &str, env: &[(&str, &str)]| {
        let g = s.write(&format!("{name}.json"), graph);
        let out = s.path(&format!("out_{name}"));
        let mut c = bin();
        c.args([
            "run",
            g.to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--out-dir",
        ])
        .arg(&out)
        .current_dir(s.dir.path());
        for (k, v) in env {
            c.env(k, v);
        }
        let started = Instant::now();
        let r = Run::from(c.output().unwrap());
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "{name}: took too long"
        );
        assert!(!r.stderr.contains("panicked"), "{name}: {}", r.stderr);
        r
    };
    // Writes stay inside the output folder: refused at validation, exit 2.
    for (name, path) in [("abs", "/tmp/mesoflow_escape.png"), ("up", "../escape.png")] {
        let r = run(
            name,
            &format!(
                r#"{{"mesoflow": 1, "nodes": {{
                  "s": {{"kind": "heightfield.procedural", "params": {{"size": 8}}}},
                  "n": {{"kind": "heightfield.normals", "inputs": {{"height": "s.height"}}}},
                  "w": {{"kind": "image.write", "inputs": {{"image": "n.preview"}}, "params": {{"path": "{path}"}}}}}}}}"#
            ),
            &[],
        );
        assert_eq!(r.code, 2, "{name}: {}", r.stderr);
        assert!(
            r.stderr.contains("node `w`: parameter `path`"),
            "{}",
            r.stderr
        );
    }
    // Integers the parameter cannot hold: exit 2 naming the field.
    for (name, param, value) in [
        ("big", "size", "4294967296"),
        ("negzero", "seed", "-0.0"),
        ("huge", "seed", "18446744073709551616"),
    ] {
        let r = run(
            name,
            &format!(
                r#"{{"mesoflow": 1, "nodes": {{"s": {{"kind": "heightfield.procedural", "params": {{"{param}": {value}}}}}}}}}"#
            ),
            &[],
        );
        assert_eq!(r.code, 2, "{name}: {}", r.stderr);
        assert!(
            r.stderr.contains(&format!("parameter `{param}`")),
            "{name}: {}",
            r.stderr
        );
    }
    // A non-regular file as input: refused, not read forever.
    let r = run(
        "devzero",
        r#"{"mesoflow": 1, "nodes": {"h": {"kind": "heightfield.read", "params": {"path": "/dev/zero"}}}}"#,
        &[],
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    let rep = report(&s.path("out_devzero"));
    assert!(
        rep["nodes"][0]["error"]
            .as_str()
            .unwrap()
            .contains("not a regular file"),
        "{rep}"
    );
    // A malformed memory budget is an error, not ignored.
    let r = run(
        "budget",
        r#"{"mesoflow": 1, "nodes": {"s": {"kind": "heightfield.procedural", "params": {"size": 8}}}}"#,
        &[("MESOFLOW_MEMORY_BUDGET_GB", "abc")],
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("MESOFLOW_MEMORY_BUDGET_GB"),
        "{}",
        r.stderr
    );
    // An absurd thread count is capped, not spawned.
    let r = run(
        "threads",
        r#"{"mesoflow": 1, "nodes": {"s": {"kind": "heightfield.procedural", "params": {"size": 8}}}}"#,
        &[("RAYON_NUM_THREADS", "100000")],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stderr.contains("using"), "{}", r.stderr);
}

#[test]
fn output_prints_the_values_asked_for_and_suggests_near_names() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let out = s.path("o");
    let go = |output: &str| {
        mesoflow(
            &[
                "run",
                g.to_str().unwrap(),
                "--quiet",
                "--no-cache",
                "--set",
                "surface.size=16",
                "--output",
                output,
                "--out-dir",
                out.to_str().unwrap(),
            ],
            root,
        )
    };
    let r = go("normals.rms_slope");
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stdout.contains("normals.rms_slope = "), "{}", r.stdout);
    let r = go("normals.rms_slop");
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains("did you mean `rms_slope`"),
        "{}",
        r.stderr
    );
    let r = go("normal.rms_slope");
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("did you mean `normals`"), "{}", r.stderr);
}

#[test]
fn listing_into_a_closed_pipe_ends_quietly() {
    use std::io::Read;
    use std::process::Stdio;
    for cmd in ["schema", "nodes"] {
        let mut child = bin()
            .arg(cmd)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Read one byte, then close the pipe: the writer meets EPIPE.
        let mut stdout = child.stdout.take().unwrap();
        let mut one = [0u8; 1];
        stdout.read_exact(&mut one).unwrap();
        drop(stdout);
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked"), "{cmd}: {err}");
    }
}

#[test]
fn a_value_from_the_cpu_path_is_not_served_for_the_gpu_path() {
    // CPU and GPU paths agree to tested tolerances, not to the bit: the path is part of the key.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let cache = s.path("cache");
    let go = |out: &str, device: &str| {
        let out_dir = s.path(out);
        let r = mesoflow(
            &[
                "run",
                g.to_str().unwrap(),
                "--quiet",
                "--set",
                "surface.size=16",
                "--device",
                device,
                "--output",
                "normals.rms_slope",
                "--cache-dir",
                cache.to_str().unwrap(),
                "--out-dir",
                out_dir.to_str().unwrap(),
            ],
            root,
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        report(&out_dir)
    };
    let cpu = go("cpu", "cpu");
    let cpu_again = go("cpu2", "cpu");
    assert_eq!(statuses(&cpu_again)["normals"], "disk");
    let auto = go("auto", "auto");
    let on_gpu = per_node(&auto, "device")["normals"] == "gpu";
    if std::env::var("MESOFLOW_REQUIRE_GPU").as_deref() == Ok("1") {
        assert!(on_gpu, "CI has lavapipe: {auto}");
    }
    let (k_cpu, k_auto) = (
        keys(&cpu)["normals"].clone(),
        keys(&auto)["normals"].clone(),
    );
    if on_gpu {
        assert_ne!(k_cpu, k_auto);
        assert_eq!(statuses(&auto)["normals"], "computed");
        // The CPU-only node upstream is shared.
        assert_eq!(statuses(&auto)["surface"], "disk");
    } else {
        assert_eq!(
            k_cpu, k_auto,
            "no adapter: auto is the CPU path, the same value"
        );
        mesoflow_testkit::skip("no GPU adapter: the GPU half (its own key) did not run");
    }
}

#[test]
fn a_measured_time_is_one_column_read_from_the_report() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "surface": {"kind": "heightfield.procedural", "params": {"size": 16, "pattern": "noise"}},
            "normals": {"kind": "heightfield.normals", "inputs": {"height": "surface.height"}}
        }}"#,
    );
    let out = s.path("sweep");
    let r = mesoflow(
        &[
            "sweep",
            g.to_str().unwrap(),
            "--vary",
            "normals.scale=1,2",
            "--measure",
            "normals.rms_slope",
            "--measure",
            "normals.seconds",
            "--device",
            "cpu",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    // Each run's line shows its measures.
    assert!(r.stdout.contains("normals.rms_slope="), "{}", r.stdout);
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert_eq!(
        header,
        "normals.scale,normals.rms_slope,normals.seconds,run_seconds,ok"
    );
    for line in csv.lines().skip(1) {
        let t: f64 = line.split(',').nth(2).unwrap().parse().unwrap();
        assert!(t >= 0.0 && t.is_finite(), "{line}");
    }
    // A misspelt measure is refused with what there is.
    let r = mesoflow(
        &[
            "sweep",
            g.to_str().unwrap(),
            "--vary",
            "normals.scale=1",
            "--measure",
            "normals.secnds",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("did you mean `seconds`"), "{}", r.stderr);
}

#[test]
fn ctrl_c_stops_a_monte_carlo_profile_within_a_second() {
    // 10⁹ photons would take hours: the photon loop must see the flag.
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "material": {"kind": "sss.material", "params": {"preset": "marble"}},
            "profile": {"kind": "sss.profile", "inputs": {"material": "material.material"},
                        "params": {"model": "montecarlo", "photons": 1000000000}}
        }}"#,
    );
    let out = s.path("o");
    let child = spawn_run(&g, &out, s.dir.path());
    std::thread::sleep(Duration::from_millis(1500));
    interrupt(&child);
    let t = Instant::now();
    let mut child = child;
    let status = child.wait().unwrap();
    // A second is the issue's bound; a loaded CI machine gets a margin.
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "took {:?}",
        t.elapsed()
    );
    assert_eq!(status.code(), Some(130));
    let rep = report(&out);
    assert_eq!(statuses(&rep)["profile"], "cancelled");
}

#[test]
fn cache_gc_keeps_what_was_used_recently_and_fits_the_budget() {
    let s = Scratch::new();
    let g = pipeline(&s);
    let (_, rep) = run(&s, &g, "o", &[]);
    assert_eq!(rep["ok"], true);
    let cache = s.path("data/.mesoflow/cache");
    let cache = cache.to_str().unwrap();
    let stats = |s: &Scratch| -> serde_json::Value {
        let r = mesoflow(
            &["cache", "stats", "--json", "--cache-dir", cache],
            s.dir.path(),
        );
        serde_json::from_str(&r.stdout).unwrap()
    };
    let before = stats(&s);
    assert!(before["entries"].as_u64().unwrap() >= 4, "{before}");
    // Everything was used seconds ago: an age limit of a day removes nothing.
    let r = mesoflow(
        &["cache", "gc", "--older-than", "1d", "--cache-dir", cache],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(stats(&s)["entries"], before["entries"]);
    // A budget of half the bytes leaves at most half.
    let half = before["bytes"].as_u64().unwrap() / 2;
    let r = mesoflow(
        &[
            "cache",
            "gc",
            "--max-bytes",
            &half.to_string(),
            "--cache-dir",
            cache,
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(stats(&s)["bytes"].as_u64().unwrap() <= half);
    // The next run recomputes only what was removed, and every result is the same.
    let (_, again) = run(&s, &g, "o2", &[]);
    assert_eq!(again["ok"], true);
    for f in ["tile.png", "surface.npy"] {
        assert_eq!(
            std::fs::read(s.path("o").join(f)).unwrap(),
            std::fs::read(s.path("o2").join(f)).unwrap()
        );
    }
    let bad = mesoflow(&["cache", "gc", "--cache-dir", cache], s.dir.path());
    assert_eq!(bad.code, 2);
    assert!(bad.stderr.contains("--max-bytes"), "{}", bad.stderr);
    let bad = mesoflow(
        &["cache", "gc", "--older-than", "soon", "--cache-dir", cache],
        s.dir.path(),
    );
    assert_eq!(bad.code, 2);
    assert!(bad.stderr.contains("30d"), "{}", bad.stderr);
}

#[test]
fn a_tile_too_small_for_its_pattern_is_flat_and_says_so() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "small": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 16}},
            "fine": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 32}}}}"#,
    );
    let (r, rep) = run(&s, &g, "o", &["--no-cache"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let warnings: Vec<(String, String)> = rep["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| {
            (
                w["node"].as_str().unwrap().to_string(),
                w["message"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    // 8 threads across 16 texels: 2 texels each, every centre at the same phase.
    assert!(
        warnings
            .iter()
            .any(|(n, m)| n == "small" && m.contains("flat")),
        "{warnings:?}"
    );
    assert!(!warnings.iter().any(|(n, _)| n == "fine"), "{warnings:?}");
}
