//! The other commands and options end to end: `sweep`, `watch`, `--output`, listing into a
//! closed pipe, timings as sweep columns, hostile inputs, the quickstart's files.

use crate::common::*;
use std::path::Path;
use std::time::{Duration, Instant};

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
fn a_run_of_some_outputs_keeps_the_folder_s_report_whole() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let out = s.path("o");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            g.to_str().unwrap(),
            "--quiet",
            "--set",
            "surface.size=16",
            "--out-dir",
            out.to_str().unwrap(),
            "--cache-dir",
        ];
        let cache = s.path("cache");
        let cache = cache.to_str().unwrap().to_string();
        args.push(&cache);
        args.extend_from_slice(extra);
        let r = mesoflow(&args, root);
        assert_eq!(r.code, 0, "{}", r.stderr);
        report(&out)
    };
    let full = run(&[]);
    let ids = |v: &serde_json::Value, key: &str| -> Vec<String> {
        v[key]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|n| n["id"].as_str().unwrap().to_string())
                    .collect()
            })
            .unwrap_or_default()
    };
    let all = ids(&full, "nodes");
    assert!(all.len() >= 3, "{full}");
    let part = run(&["--output", "normals.rms_slope"]);
    let (now, earlier) = (ids(&part, "nodes"), ids(&part, "earlier"));
    assert!(now.contains(&"normals".to_string()), "{part}");
    // Every node of the full run is still reported, this run's or an earlier one's.
    for id in &all {
        assert!(
            now.contains(id) || earlier.contains(id),
            "{id} lost: {part}"
        );
    }
    assert!(!earlier.is_empty(), "{part}");
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

/// A new user's first mistake (issue 58): a graph whose input file does not exist. `validate`
/// refuses it naming the node and the folder the path resolves against (it said "ok"), and a run
/// says the same (it said only "./nosuch.png: No such file or directory").
#[test]
fn a_missing_input_file_is_refused_by_validate_and_run_naming_the_graphs_folder() {
    let s = Scratch::new();
    let g = s.write(
        "graphs/g.json",
        r#"{"mesoflow": 1, "nodes": {
            "photo": {"kind": "image.read", "params": {"path": "nosuch.png"}},
            "save": {"kind": "image.write", "inputs": {"image": "photo.image"}, "params": {"path": "copy.png"}}
        }}"#,
    );
    let folder = s.path("graphs");
    let r = mesoflow(&["validate", g.to_str().unwrap()], s.dir.path());
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("node `photo`")
            && r.stderr.contains("nosuch.png")
            && r.stderr.contains(&folder.display().to_string()),
        "{}",
        r.stderr
    );
    let out = s.path("out");
    let r = mesoflow(
        &[
            "run",
            g.to_str().unwrap(),
            "--quiet",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("no such file") && r.stderr.contains(&folder.display().to_string()),
        "{}",
        r.stderr
    );
}

/// `run` says where its files went (issue 58: the output folder is relative to the current
/// folder, not the graph's, and a new user looked for them beside the graph).
#[test]
fn run_says_where_its_files_went() {
    let s = Scratch::new();
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/quickstart.json");
    let r = mesoflow(
        &[
            "run",
            graph.to_str().unwrap(),
            "--set",
            "surface.size=32",
            "--no-cache",
            "--out-dir",
            "somewhere",
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let folder = s.path("somewhere").canonicalize().unwrap();
    assert!(
        r.stdout
            .contains(&format!("files and report.json in {}", folder.display())),
        "{}",
        r.stdout
    );
}

/// A run that fails names the files in its output folder that an earlier run wrote (issue 58:
/// after a failed run they stayed in `out/` looking current).
#[test]
fn a_failed_run_names_the_earlier_runs_files_it_left() {
    let s = Scratch::new();
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/quickstart.json");
    let args = |g: &str| {
        vec![
            "run".to_string(),
            g.to_string(),
            "--quiet".into(),
            "--no-cache".into(),
            "--out-dir".into(),
            "o".into(),
        ]
    };
    let mut first = args(graph.to_str().unwrap());
    first.extend(["--set".into(), "surface.size=32".into()]);
    let first: Vec<&str> = first.iter().map(String::as_str).collect();
    let r = mesoflow(&first, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(!r.stderr.contains("earlier run"), "{}", r.stderr);
    // A file that exists (so the graph validates) but is not an image: the run fails.
    s.write("bad.png", "not a png");
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "photo": {"kind": "image.read", "params": {"path": "bad.png"}},
            "save": {"kind": "image.write", "inputs": {"image": "photo.image"}, "params": {"path": "copy.png"}}
        }}"#,
    );
    let second = args(g.to_str().unwrap());
    let second: Vec<&str> = second.iter().map(String::as_str).collect();
    let r = mesoflow(&second, s.dir.path());
    assert_ne!(r.code, 0);
    assert!(
        r.stderr
            .contains("from an earlier run that this run did not write")
            && r.stderr.contains("normals.png")
            && !r.stderr.contains("report.json,"),
        "{}",
        r.stderr
    );
}

/// `cache clear` without a graph or `--cache-dir` lists the caches it would clear and clears
/// nothing (issue 58: it wiped every cache here and one folder down without asking); `--all`
/// clears them.
#[test]
fn cache_clear_without_a_graph_asks_for_all() {
    let s = Scratch::new();
    let g = s.write(
        "a/g.json",
        r#"{"mesoflow": 1, "nodes": {"s": {"kind": "heightfield.procedural", "params": {"size": 16}}}}"#,
    );
    let r = mesoflow(
        &["run", g.to_str().unwrap(), "--quiet", "--out-dir", "out"],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    std::fs::create_dir_all(s.path("a/.mesoflow/cache")).unwrap();
    let marker = s.write("a/.mesoflow/cache/keep.txt", "a file clear must not reach");
    let r = mesoflow(&["cache", "clear"], s.dir.path());
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("--all") && r.stderr.contains("a/.mesoflow/cache"),
        "{}",
        r.stderr
    );
    assert!(marker.exists());
    let r = mesoflow(&["cache", "clear", "--all"], s.dir.path());
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stdout.contains("a/.mesoflow/cache: removed"),
        "{}",
        r.stdout
    );
}

/// `mesoflow nodes` and `nodes KIND` keep their columns: names as wide as the longest, text
/// wrapped to 100 columns under its own column (issue 58: long names pushed columns out of line
/// and wrapped lines started at column 0).
#[test]
fn nodes_lines_fit_a_hundred_columns_and_wrap_under_their_column() {
    let s = Scratch::new();
    for args in [
        vec!["nodes"],
        vec!["nodes", "render.mesh"],
        vec!["nodes", "sss.render"],
    ] {
        let r = mesoflow(&args, s.dir.path());
        assert_eq!(r.code, 0, "{}", r.stderr);
        for line in r.stdout.lines() {
            let long_word = line.split_whitespace().any(|w| w.chars().count() > 40);
            assert!(
                line.chars().count() <= 100 || long_word,
                "{args:?}: a line of {} columns: {line}",
                line.chars().count()
            );
        }
    }
    // A wrapped kind description starts under the description's column, never at column 0.
    let r = mesoflow(&["nodes"], s.dir.path());
    let col = r.stdout.lines().next().map_or(0, |l| {
        l.find(" v").map_or(0, |i| i + " v".len() + 3 + 1 + 4 + 1)
    });
    for line in r.stdout.lines().filter(|l| l.starts_with(' ')) {
        assert!(
            line.chars().take_while(|c| *c == ' ').count() >= col.min(30),
            "a continuation line out of its column: {line}"
        );
    }
}

#[test]
fn a_prefix_lists_its_kinds() {
    let s = Scratch::new();
    let r = mesoflow(&["nodes", "btf"], s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let kinds: Vec<&str> = r
        .stdout
        .lines()
        .filter(|l| !l.starts_with(' '))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert!(kinds.len() >= 3, "{}", r.stdout);
    assert!(kinds.iter().all(|k| k.starts_with("btf.")), "{}", r.stdout);
    // A whole kind is still described, and a mistyped one still refused.
    let one = mesoflow(&["nodes", "btf.pca"], s.dir.path());
    assert!(one.stdout.contains("btf.pca"), "{}", one.stdout);
    let bad = mesoflow(&["nodes", "btff"], s.dir.path());
    assert_ne!(bad.code, 0);
    assert!(bad.stderr.contains("unknown node kind"), "{}", bad.stderr);
}
