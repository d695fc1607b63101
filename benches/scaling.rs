//! Cost as the work grows, against brute force, in one run: `render.mesh` (a BTF and an MDF on
//! a torus) beside Mitsuba 3 path-tracing the true displaced geometry of the same scene
//! (`mesh.displace`, written as PLY; `benches/mesh_peer.py`, the peer venv's `llvm_ad_rgb`), one
//! axis at a time from the torus (320 × 240, a 64² bumps tile captured at UBO2003's
//! 81 × 81 directions as a raw BTF, its MDF, shadows on at a 2 048² map, 12 × 5 tiles):
//!
//! - `size`: the image from 160 × 120 to 1 280 × 960, the tiles fixed;
//! - `area`: the tiles from 6 × 2 up, the image growing with them so a tile keeps its size in
//!   pixels;
//! - `tiles`: the same tiles at a fixed 640 × 480 (minification).
//!
//! Per point: ours' CPU frame (`timings.frame_ms`, the mean of `--frames` after the image's
//! frame, every node on the CPU) and its stages, the peak resident set of ours' process and of
//! the brute-force side's (`/usr/bin/time`'s maximum resident set for `mesh.displace`, the
//! Python process's own for Mitsuba), the true geometry's triangles, Mitsuba's scene load (PLY
//! and BVH), first frame (JIT) and frame at `--spp` samples a pixel (median of 5), and the ratio
//! of the two frames. Where `mesh.displace`'s `max_triangles` or the memory budget refuses the
//! true geometry, the row says so and goes on.
//!
//! What this measures is frame against frame at a fixed sample count, not time to equal error:
//! the families bench (`--family mesostructure`) measures error against a converged truth.
//!
//! The rows go to `OUT/scaling.json` and three charts beside it (`scaling_tiles`: both frames
//! against the tiles at a fixed image; `scaling_memory`: peak memory against the tiles;
//! `scaling_pixels`: ours over Mitsuba against the image's pixels), PNG and SVG; `--replot
//! FILE.json` draws the charts again from such a file without running anything.
//!
//! `cargo bench --bench scaling -- [--axis size|area|tiles|all] [--spp 16] [--frames 3]
//! [--max-area-tiles 96] [--out target/scaling] [--replot FILE.json]`; needs the peer venv (`target/peer-venv`, as
//! `.ci/run` makes it) and Debian's `libllvm19` for Mitsuba's LLVM variant; without them the
//! Mitsuba columns are absent and the bench says why.

use mesoflow::chart::{self, Chart, Series};
use mesoflow_testkit::args::arg;
use mesoflow_testkit::cli;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The torus seen from the mdf_render graph's camera.
const EYE: [f64; 3] = [0.0, 1.5, 2.7];
const TARGET: [f64; 3] = [0.0, -0.1, 0.0];
const FOV: f64 = 42.0;
const LIGHT: [f64; 3] = [0.6, 0.7, 0.4];
const ALBEDO: [f64; 3] = [0.62, 0.42, 0.22];
/// The tile's relief, texels, and the shell it is mapped onto, world units.
const DEPTH: f64 = 6.0;
const SHELL: f64 = 0.06;

/// One point of an axis: the tiles around and along the torus, and the image.
#[derive(Clone, Copy, Debug)]
struct Point {
    tiles: [u32; 2],
    resolution: [u32; 2],
}

fn graph(p: Point, frames: u32) -> Value {
    let camera = json!({ "eye": EYE, "target": TARGET, "fov": FOV, "resolution": p.resolution });
    let light = json!({ "direction": LIGHT, "intensity": 3.0 });
    let tiling = [p.tiles[0] as f64, p.tiles[1] as f64];
    json!({
        "mesoflow": 1,
        "description": "benches/scaling.rs: render.mesh on a torus beside its true displaced geometry for Mitsuba 3",
        "nodes": {
            "surface": { "kind": "heightfield.procedural",
                         "params": { "pattern": "bumps", "size": 64, "count": 4, "depth": DEPTH } },
            "capture": { "kind": "btf.capture", "inputs": { "height": "surface.height" },
                         "params": { "views": "ubo81", "lights": "ubo81", "brdf": "lambert", "albedo": ALBEDO } },
            "mdf": { "kind": "mdf.tabulate", "inputs": { "height": "surface.height" },
                     "params": { "depth": DEPTH } },
            "torus": { "kind": "mesh.primitive",
                       "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [96, 48] } },
            "ours": { "kind": "render.mesh",
                      "inputs": { "mesh": "torus.mesh", "btf": "capture.btf", "mdf": "mdf.mdf" },
                      "params": { "camera": camera, "light": light, "tiling": tiling, "shell": SHELL,
                                  "shadows": true, "shadow_resolution": 2048, "frames": frames } },
            "true_surface": { "kind": "mesh.displace",
                              "inputs": { "mesh": "torus.mesh", "height": "surface.height" },
                              "params": { "tiling": tiling, "shell": SHELL, "depth": DEPTH } },
            "ply": { "kind": "mesh.write", "inputs": { "mesh": "true_surface.mesh" },
                     "params": { "path": "truth.ply" } }
        }
    })
}

/// Runs `mesoflow run GRAPH --output WHAT` on the CPU under `/usr/bin/time` where it exists:
/// the report, or the error's last line; and the process's peak resident set, MiB.
fn run(dir: &Path, cache: &Path, what: &str) -> (Result<Value, String>, Option<f64>) {
    let out = dir.join(format!("out-{}", what.replace('.', "-")));
    let mut args: Vec<String> = vec!["run".into(), dir.join("graph.json").display().to_string()];
    args.extend(
        [
            "--output",
            what,
            "--quiet",
            "--device",
            "cpu",
            "--cache-dir",
        ]
        .map(String::from),
    );
    args.push(cache.display().to_string());
    args.push("--out-dir".into());
    args.push(out.display().to_string());
    let timed = Path::new("/usr/bin/time").exists();
    let output = if timed {
        Command::new("/usr/bin/time")
            .arg("-f")
            .arg("peak_rss_kib %M")
            .arg(cli::bin())
            .args(&args)
            .output()
    } else {
        Command::new(cli::bin()).args(&args).output()
    }
    .expect("run mesoflow");
    let stderr = String::from_utf8_lossy(&output.stderr).to_string();
    let rss = stderr
        .lines()
        .filter_map(|l| l.strip_prefix("peak_rss_kib "))
        .filter_map(|v| v.trim().parse::<f64>().ok())
        .next_back()
        .map(|k| k / 1024.0);
    if !output.status.success() {
        let why = stderr
            .lines()
            .rfind(|l| {
                !l.starts_with("peak_rss_kib")
                    && !l.starts_with("Command exited")
                    && !l.trim().is_empty()
            })
            .unwrap_or("failed")
            .to_string();
        return (Err(why), rss);
    }
    let report: Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("the run's report"))
            .expect("a report");
    (Ok(report), rss)
}

/// Mitsuba on the PLY: its JSON line, or why not.
fn peer(dir: &Path, p: Point, spp: u32) -> Result<Value, String> {
    let python = cli::repo().join("target/peer-venv/bin/python");
    if !python.exists() {
        return Err("no peer venv (target/peer-venv; .ci/run makes it)".into());
    }
    let ply = dir.join("out-ply-file").join("truth.ply");
    let scene = json!({
        "mesh": ply.display().to_string(),
        "camera": { "eye": EYE, "target": TARGET, "up": [0.0, 1.0, 0.0], "fov": FOV, "resolution": p.resolution },
        "light": { "direction": LIGHT, "intensity": 3.0 },
        "albedo": ALBEDO,
        "samples": spp,
        "repeats": 5,
        "variant": "llvm_ad_rgb",
    });
    let path = dir.join("mitsuba.json");
    std::fs::write(&path, scene.to_string()).expect("write the peer's scene");
    let out = Command::new(&python)
        .arg(cli::repo().join("benches/mesh_peer.py"))
        .arg(&path)
        .output()
        .map_err(|e| e.to_string())?;
    let _ = std::fs::remove_file(&ply);
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(err.lines().last().unwrap_or("failed").to_string());
    }
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().unwrap_or("")).map_err(|e| e.to_string())
}

/// The charts of a run's rows (`scaling.json`), written beside it.
fn charts(rows: &[Value], out: &Path) {
    let pick =
        |axis: &str, x: &dyn Fn(&Value) -> Option<f64>, y: &dyn Fn(&Value) -> Option<f64>| {
            rows.iter()
                .filter(|r| r["axis"] == axis)
                .filter_map(|r| Some((x(r)?, y(r)?)))
                .collect::<Vec<_>>()
        };
    let tiles = |r: &Value| Some(r["tiles"][0].as_f64()? * r["tiles"][1].as_f64()?);
    let get = |k: &'static str| move |r: &Value| r[k].as_f64();
    let series = |name: &str, points| Series {
        name: name.into(),
        points,
        scatter: false,
    };
    let spp = rows.first().and_then(|r| r["spp"].as_u64()).unwrap_or(16);
    let made = [
        (
            "scaling_tiles",
            Chart {
                title: "Frame at 640 × 480 as the surface grows".into(),
                x_label: "tiles of the 64² mesostructure on the torus",
                y_label: "frame, ms (CPU, 2 cores)",
                series: vec![
                    series(
                        "render.mesh (BTF + MDF, shadows)",
                        pick("tiles", &tiles, &get("ours_ms")),
                    ),
                    series(
                        &format!("Mitsuba 3 llvm, true geometry, {spp} spp"),
                        pick("tiles", &tiles, &get("mitsuba_ms")),
                    ),
                ],
                x_names: None,
            },
        ),
        (
            "scaling_memory",
            Chart {
                title: "Peak memory as the surface grows (640 × 480)".into(),
                x_label: "tiles of the 64² mesostructure on the torus",
                y_label: "peak resident set, MiB",
                series: vec![
                    series(
                        "render.mesh (raw BTF + MDF)",
                        pick("tiles", &tiles, &get("ours_mib")),
                    ),
                    series(
                        "mesh.displace (true geometry)",
                        // A refused run's memory is the refusal's, not the geometry's.
                        pick("tiles", &tiles, &|r: &Value| {
                            r["triangles"].as_f64().and(r["displace_mib"].as_f64())
                        }),
                    ),
                    series(
                        "Mitsuba 3 (load + render)",
                        pick("tiles", &tiles, &get("mitsuba_mib")),
                    ),
                ],
                x_names: None,
            },
        ),
        (
            "scaling_pixels",
            Chart {
                title: "Ours' frame over Mitsuba's as the image grows (60 tiles)".into(),
                x_label: "pixels, millions",
                y_label: "render.mesh frame / Mitsuba frame",
                series: vec![series(
                    &format!("ratio (below 1: ours is faster than {spp} spp)"),
                    pick(
                        "size",
                        &|r: &Value| Some(r["image"][0].as_f64()? * r["image"][1].as_f64()? / 1e6),
                        &|r: &Value| Some(r["ours_ms"].as_f64()? / r["mitsuba_ms"].as_f64()?),
                    ),
                )],
                x_names: None,
            },
        ),
    ];
    for (name, c) in made {
        if c.series.iter().all(|s| s.points.is_empty()) {
            continue;
        }
        match chart::write(&out.join(name), &c) {
            Ok(()) => eprintln!("scaling: {}", out.join(format!("{name}.svg")).display()),
            Err(e) => eprintln!("scaling: no chart {name}: {e}"),
        }
    }
}

/// The machine's peaks, measured in the same run: read bandwidth (a sum over 1 GiB of f64 on
/// every core), the latency of a dependent random read over the same memory (a pointer chase:
/// what a BTF texel read that misses every cache costs), and f64 multiply-adds a second on every
/// core (eight independent chains a thread).
struct Peaks {
    read_gb_s: f64,
    miss_ns: f64,
    gflops: f64,
}

fn peaks() -> Peaks {
    use rayon::prelude::*;
    use std::time::Instant;
    let n = 1usize << 27; // 1 GiB of f64
    let data: Vec<f64> = (0..n).into_par_iter().map(|i| (i & 1023) as f64).collect();
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        let s: f64 = data
            .par_chunks(1 << 16)
            .map(|c| c.iter().sum::<f64>())
            .sum();
        best = best.min(t.elapsed().as_secs_f64());
        assert!(s > 0.0);
    }
    let read_gb_s = (n * 8) as f64 / best / 1e9;
    // A single cycle through all slots in a random order (Sattolo), followed from slot 0.
    let m = n;
    let mut next: Vec<u32> = (0..m as u32).collect();
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    for i in (1..m).rev() {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let j = (x % i as u64) as usize;
        next.swap(i, j);
    }
    drop(data);
    let steps = 1usize << 22;
    let t = Instant::now();
    let mut k = 0usize;
    for _ in 0..steps {
        k = next[k] as usize;
    }
    let miss_ns = t.elapsed().as_secs_f64() * 1e9 / steps as f64;
    assert!(k < m);
    let iters = 1u64 << 26;
    let t = Instant::now();
    let total: f64 = (0..rayon::current_num_threads())
        .into_par_iter()
        .map(|th| {
            let mut a = [1.0 + th as f64 * 1e-9; 8];
            for _ in 0..iters {
                for v in a.iter_mut() {
                    *v = *v * 0.999_999_9 + 1e-9;
                }
            }
            a.iter().sum::<f64>()
        })
        .sum();
    let gflops = (2 * 8 * iters * rayon::current_num_threads() as u64) as f64
        / t.elapsed().as_secs_f64()
        / 1e9;
    assert!(total.is_finite());
    Peaks {
        read_gb_s,
        miss_ns,
        gflops,
    }
}

fn ms(v: Option<f64>) -> String {
    v.map_or("absent".into(), |x| format!("{x:.0}"))
}

fn main() {
    if std::env::args().any(|a| a == "--peaks-only") {
        let p = peaks();
        println!("{} {} {}", p.read_gb_s, p.miss_ns, p.gflops);
        return;
    }
    let replot: String = arg("--replot", String::new());
    if !replot.is_empty() {
        let rows: Vec<Value> =
            serde_json::from_slice(&std::fs::read(&replot).expect("--replot FILE"))
                .expect("a scaling.json");
        charts(&rows, Path::new(&replot).parent().unwrap_or(Path::new(".")));
        return;
    }
    let axis: String = arg("--axis", "size".to_string());
    let spp: u32 = arg("--spp", 16);
    let frames: u32 = arg("--frames", 3);
    let max_tiles: u32 = arg("--max-area-tiles", 96);
    let out: PathBuf = arg("--out", cli::repo().join("target/scaling"));
    let cache = out.join("cache");
    // Measured in a process of its own: a child's peak resident set starts from its parent's
    // (Linux copies the high-water mark at fork), and the peaks allocate 1.5 GiB.
    let pk = {
        let o = Command::new(std::env::current_exe().expect("this bench's path"))
            .arg("--peaks-only")
            .output()
            .expect("run the peaks");
        let text = String::from_utf8_lossy(&o.stdout);
        let v: Vec<f64> = text
            .split_whitespace()
            .filter_map(|w| w.parse().ok())
            .collect();
        assert_eq!(v.len(), 3, "the peaks' line: {text}");
        Peaks {
            read_gb_s: v[0],
            miss_ns: v[1],
            gflops: v[2],
        }
    };
    println!(
        "Machine ({} threads): read bandwidth {:.1} GB/s, a dependent random read {:.0} ns, {:.1} GFLOP/s (f64 multiply-add).",
        rayon::current_num_threads(),
        pk.read_gb_s,
        pk.miss_ns,
        pk.gflops
    );
    println!();
    let base = Point {
        tiles: [12, 5],
        resolution: [320, 240],
    };
    let mut points: Vec<(&str, Point)> = Vec::new();
    if axis == "size" || axis == "all" {
        for r in [[160, 120], [320, 240], [640, 480], [1280, 960]] {
            points.push((
                "size",
                Point {
                    resolution: r,
                    ..base
                },
            ));
        }
    }
    // Tiles doubled each way from 6 × 2.5 (about square tiles on this torus: its tube is 0.42 of
    // its ring); the image grows with their count so a tile keeps about 53 × 48 pixels.
    for (name, grow) in [("area", true), ("tiles", false)] {
        if axis != name && axis != "all" {
            continue;
        }
        let mut k = 1;
        while 6 * k <= max_tiles {
            let tiles = [6 * k, (5 * k).div_ceil(2)];
            let resolution = if grow { [160 * k, 120 * k] } else { [640, 480] };
            points.push((name, Point { tiles, resolution }));
            k *= 2;
        }
    }
    let mut rows: Vec<Value> = Vec::new();
    println!(
        "| axis | tiles | image | ours' frame, ms | BTF-read limit, ms | layers / shade, ms | shadow texels | ours' peak, MiB | true triangles | displace peak, MiB | Mitsuba load, s | Mitsuba first frame, s | Mitsuba {spp} spp, ms | Mitsuba peak, MiB | ours / Mitsuba |"
    );
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (name, p) in points {
        let dir = out.join(format!(
            "{name}-{}x{}-{}x{}",
            p.tiles[0], p.tiles[1], p.resolution[0], p.resolution[1]
        ));
        std::fs::create_dir_all(&dir).expect("the point's folder");
        std::fs::write(dir.join("graph.json"), graph(p, frames).to_string())
            .expect("write the graph");
        let (mut ours, mut ours_rss) = run(&dir, &cache, "ours.image");
        // A frame from an earlier bench's cache is rendered again, so its time and memory are
        // this run's (the material and MDF stay cached: they are made once per material).
        let key = ours.as_ref().ok().and_then(|r| {
            let n = cli::node(r, "ours");
            (n["status"] != "computed").then(|| n["key"].as_str().map(String::from))?
        });
        if let Some(k) = key {
            let _ = std::fs::remove_file(cache.join(&k[..2]).join(format!("{k}.mfc")));
            (ours, ours_rss) = run(&dir, &cache, "ours.image");
        }
        let ours = ours.unwrap_or_else(|e| panic!("render.mesh at {p:?}: {e}"));
        let t = &cli::node(&ours, "ours")["timings"];
        let frame = t["frame_ms"].as_f64();
        // The limit the raw BTF's reads set: a covered pixel blends 4 views × 4 lights at 4
        // bilinear taps (2 rows), 3 channel planes apart: 96 cache lines of 64 bytes, at the
        // measured read bandwidth (a lower bound on the frame: it leaves out the MDF, the
        // shadow texel and all arithmetic).
        let covered = cli::node(&ours, "ours")["metrics"]["coverage"]
            .as_f64()
            .map(|c| c * (p.resolution[0] * p.resolution[1]) as f64);
        let limit = covered.map(|c| c * 96.0 * 64.0 / (pk.read_gb_s * 1e9) * 1e3);
        let (truth, displace_rss) = run(&dir, &cache, "ply.file");
        let (triangles, mitsuba) = match truth {
            Ok(_) => match peer(&dir, p, spp) {
                Ok(m) => (m["triangles"].as_f64(), Ok(m)),
                Err(e) => (None, Err(e)),
            },
            Err(e) => (None, Err(format!("mesh.displace refused: {e}"))),
        };
        let m = mitsuba.as_ref().ok();
        rows.push(json!({
            "axis": name, "tiles": p.tiles, "image": p.resolution, "spp": spp,
            "ours_ms": frame, "btf_limit_ms": limit, "layers_ms": t["layers_ms"], "shade_ms": t["shade_ms"],
            "shadow_texels": t["shadow_texels"], "ours_mib": ours_rss,
            "triangles": triangles, "displace_mib": displace_rss,
            "mitsuba_load_s": m.map(|m| &m["load_s"]), "mitsuba_first_s": m.map(|m| &m["first_s"]),
            "mitsuba_ms": m.and_then(|m| m["frame_s"].as_f64()).map(|s| s * 1e3),
            "mitsuba_mib": m.map(|m| &m["peak_rss_mib"]),
            "refused": mitsuba.as_ref().err(),
        }));
        let (load, first, mframe, mrss, ratio) = match &mitsuba {
            Ok(m) => {
                let f = m["frame_s"].as_f64().map(|s| s * 1e3);
                (
                    m["load_s"]
                        .as_f64()
                        .map_or("absent".into(), |s| format!("{s:.2}")),
                    m["first_s"]
                        .as_f64()
                        .map_or("absent".into(), |s| format!("{s:.2}")),
                    ms(f),
                    ms(m["peak_rss_mib"].as_f64()),
                    match (frame, f) {
                        (Some(a), Some(b)) => format!("{:.2}×", a / b),
                        _ => "absent".into(),
                    },
                )
            }
            Err(e) => {
                eprintln!("scaling: {name} {p:?}: no Mitsuba frame: {e}");
                let a = "absent".to_string();
                (a.clone(), a.clone(), a.clone(), a.clone(), a)
            }
        };
        println!(
            "| {name} | {} × {} | {} × {} | {} | {} | {} / {} | {} | {} | {} | {} | {load} | {first} | {mframe} | {mrss} | {ratio} |",
            p.tiles[0],
            p.tiles[1],
            p.resolution[0],
            p.resolution[1],
            ms(frame),
            limit.map_or("absent".into(), |x| format!("{x:.1}")),
            ms(t["layers_ms"].as_f64()),
            ms(t["shade_ms"].as_f64()),
            t["shadow_texels"].as_f64().map_or("absent".into(), |x| format!("{x:.0}")),
            ms(ours_rss),
            triangles.map_or("absent".into(), |x| format!("{x:.0}")),
            ms(displace_rss),
        );
    }
    let json_path = out.join("scaling.json");
    std::fs::write(
        &json_path,
        serde_json::to_string_pretty(&rows).expect("rows as JSON"),
    )
    .expect("write scaling.json");
    eprintln!("scaling: {}", json_path.display());
    charts(&rows, &out);
}
