//! The cache end to end: incremental re-execution, what a request runs, keys independent of
//! folder, process and parameter order, corrupt entries, two processes on one cache,
//! `--verify-cache`, the path a key names, garbage collection, and bits independent of threads.

use crate::common::*;
use std::path::Path;

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
fn a_value_from_the_cpu_path_is_not_served_for_the_gpu_path() {
    // CPU and GPU paths agree to tested tolerances, not to the bit: the path is part of the key.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let cache = s.path("cache");
    let go = |out: &str, device: &str| {
        let (code, stderr, rep) = normals_on(&s, &g, &cache, out, device);
        assert_eq!(code, 0, "{stderr}");
        rep
    };
    let cpu = go("cpu", "cpu");
    let cpu_again = go("cpu2", "cpu");
    assert_eq!(statuses(&cpu_again)["normals"], "disk");
    // Where auto takes the CPU path (no adapter, or a software one it passes over), it is the
    // CPU path's value.
    let auto = go("auto", "auto");
    if per_node(&auto, "device")["normals"] == "cpu" {
        assert_eq!(keys(&cpu)["normals"], keys(&auto)["normals"]);
        assert_eq!(statuses(&auto)["normals"], "disk");
    }
    // `--device gpu`, not `auto`: auto passes over a software adapter such as CI's lavapipe.
    let (code, stderr, gpu) = normals_on(&s, &g, &cache, "gpu", "gpu");
    if code != 0 {
        // Only a missing adapter may skip; any other failure of the GPU run is this test's.
        assert!(
            stderr.contains("no GPU adapter"),
            "--device gpu failed for another reason than a missing adapter: {stderr}"
        );
        mesoflow_testkit::skip_unless_required(
            "MESOFLOW_REQUIRE_GPU",
            "no GPU adapter: the GPU half (its own key) did not run",
        );
        return;
    }
    assert_eq!(per_node(&gpu, "device")["normals"], "gpu", "{gpu}");
    assert_ne!(keys(&cpu)["normals"], keys(&gpu)["normals"]);
    assert_eq!(statuses(&gpu)["normals"], "computed");
    // The CPU-only node upstream is shared.
    assert_eq!(statuses(&gpu)["surface"], "disk");
}

/// The quickstart's normals on `device` into `cache`: the exit code, stderr and the report.
fn normals_on(
    s: &Scratch,
    g: &Path,
    cache: &Path,
    out: &str,
    device: &str,
) -> (i32, String, serde_json::Value) {
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
        Path::new(env!("CARGO_MANIFEST_DIR")),
    );
    let rep = if r.code == 0 {
        report(&out_dir)
    } else {
        serde_json::Value::Null
    };
    (r.code, r.stderr, rep)
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
fn a_large_meshs_bvh_is_kept_for_the_next_process_and_gives_the_same_image() {
    // 160 000 triangles: above the size whose BVH is kept (`tracer::KEEP_FROM`, 100 000).
    let s = Scratch::new();
    let g = s.write(
        "bvh.json",
        r#"{"mesoflow": 1, "nodes": {
            "mesh": {"kind": "mesh.primitive", "params": {"shape": "sphere", "size": 1.0, "segments": [400, 200]}},
            "truth": {"kind": "render.reference", "inputs": {"mesh": "mesh.mesh"},
                      "params": {"camera": {"eye": [0, 0, 4], "target": [0, 0, 0], "fov": 40, "resolution": [32, 24]},
                                 "samples": 1, "seed": 1}}}}"#,
    );
    let cache = s.path("cache");
    let cache_arg = cache.to_str().unwrap();
    let truth = |rep: &serde_json::Value| mesoflow_testkit::cli::node(rep, "truth").clone();
    let stored = |rep: &serde_json::Value| truth(rep)["timings"]["bvh_stored"].as_f64().unwrap();
    let bvh_entries = || {
        let r = mesoflow(&["cache", "stats", "--cache-dir", cache_arg], s.dir.path());
        assert_eq!(r.code, 0, "{}", r.stderr);
        let line = r.stdout.lines().find(|l| l.contains("raytrace.bvh"));
        line.map(|l| l.split_whitespace().nth(1).unwrap().to_string())
    };

    // The first process builds it and keeps it in the cache, counted under its own kind.
    let (r, rep) = run(&s, &g, "o1", &["--cache-dir", cache_arg]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(stored(&rep), 0.0);
    assert_eq!(bvh_entries().as_deref(), Some("1"));

    // A second process verifying the cached frame renders it again through the stored BVH,
    // and gets the same bits as the frame rendered through a built one.
    let (r, rep) = run(&s, &g, "o2", &["--cache-dir", cache_arg, "--verify-cache"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(truth(&rep)["verified"], true);
    assert_eq!(stored(&rep), 1.0, "{}", truth(&rep));

    // Another frame of the same surface in a new process reads it too.
    let (r, rep) = run(
        &s,
        &g,
        "o3",
        &["--cache-dir", cache_arg, "--set", "truth.seed=2"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(stored(&rep), 1.0);

    // A damaged entry is rebuilt, not traversed, and replaced.
    let entry = walk(&cache)
        .into_iter()
        .find(|p| {
            let head = std::fs::read(p).unwrap_or_default();
            head.len() > 512 && head[..512].windows(12).any(|w| w == b"raytrace.bvh")
        })
        .expect("the stored BVH's entry");
    let mut bytes = std::fs::read(&entry).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xff;
    std::fs::write(&entry, bytes).unwrap();
    let (r, rep) = run(
        &s,
        &g,
        "o4",
        &["--cache-dir", cache_arg, "--set", "truth.seed=3"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(stored(&rep), 0.0);
    assert_eq!(bvh_entries().as_deref(), Some("1"));
    let (r, rep) = run(
        &s,
        &g,
        "o5",
        &["--cache-dir", cache_arg, "--set", "truth.seed=4"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(stored(&rep), 1.0);
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            files.extend(walk(&p));
        } else {
            files.push(p);
        }
    }
    files
}
