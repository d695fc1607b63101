//! Where measured appearance must win, in one run: `render.mesh` under a directional light, the
//! procedural sky and the procedural studio, from BTFs captured with 0 and 4 bounces of
//! interreflection at albedos 0.3, 0.6 and 0.9, beside Mitsuba 3's `path` integrator on the
//! true displaced geometry of the same torus under the same light (`max_depth` = bounces + 2,
//! no Russian roulette, the environment written by `export.mitsuba` and hidden from the camera
//! as mesoflow's background is not the environment).
//!
//! Per point: ours' CPU frame (`frame_ms`, the mean of `--frames` after the image's frame) and
//! the environment's one-off integration (`environment_ms`: the BTF's transfer and the mesh's
//! lighting); Mitsuba's converged truth (`--truth-spp` a pixel, in passes of `--spp`), ours'
//! relative RMSE against it (the truth's noise taken out; `benches/mesh_peer.py`), and
//! Mitsuba's time to the same error (the samples a pixel its measured noise needs, its frame
//! interpolated between the 1-sample and `--spp` frames). The ratio is ours' frame over that
//! time: below 1 ours is faster at equal error. Every figure is from the same run.
//!
//! The rows go to `OUT/environment.json` with two charts beside it (`environment_albedo`: the
//! ratio against albedo, a series per light and bounces; `environment_light`: the ratio per
//! light at 4 bounces); `--replot FILE.json` draws them again without running anything.
//!
//! `cargo bench --bench environment -- [--lights sun,sky,studio] [--bounces 0,4]
//! [--albedos 0.3,0.6,0.9] [--resolution 640x480] [--spp 4] [--truth-spp 64] [--frames 3]
//! [--out target/environment] [--replot FILE.json]`; needs the peer venv (`target/peer-venv`,
//! as `.ci/run` makes it) and Debian's `libllvm19` for Mitsuba's LLVM variant; without them
//! the Mitsuba columns are absent and the bench says why.

use mesoflow::chart::{self, Chart, Series};
use mesoflow_testkit::args::arg;
use mesoflow_testkit::cli;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

const EYE: [f64; 3] = [0.0, 1.5, 2.7];
const TARGET: [f64; 3] = [0.0, -0.1, 0.0];
const FOV: f64 = 42.0;
const SUN: [f64; 3] = [0.5, 0.6, 0.6];

fn light(name: &str) -> Value {
    match name {
        "sun" => json!({ "direction": SUN, "intensity": 3.0 }),
        "sky" => json!({ "sky": {}, "intensity": 3.0 }),
        "studio" => json!({ "studio": {}, "intensity": 3.0 }),
        other => panic!("--lights: {other} is not sun, sky or studio"),
    }
}

fn graph(light_name: &str, bounces: u32, albedo: f64, res: [u32; 2], frames: u32) -> Value {
    let light = light(light_name);
    let camera = json!({ "eye": EYE, "target": TARGET, "fov": FOV, "resolution": res });
    let rho = [albedo; 3];
    json!({
        "mesoflow": 1,
        "description": "benches/environment.rs: render.mesh under a light, beside its true displaced geometry for Mitsuba 3",
        "nodes": {
            "surface": { "kind": "heightfield.procedural",
                         "params": { "pattern": "bumps", "size": 64, "count": 8, "width": 0.8, "depth": 6.0 } },
            "capture": { "kind": "btf.capture", "inputs": { "height": "surface.height" },
                         "params": { "views": "ubo81", "lights": "ubo81", "brdf": "lambert",
                                     "albedo": rho, "samples": 2, "bounces": bounces } },
            "mdf": { "kind": "mdf.tabulate", "inputs": { "height": "surface.height" } },
            "torus": { "kind": "mesh.primitive",
                       "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [96, 48] } },
            "true_surface": { "kind": "mesh.displace",
                              "inputs": { "mesh": "torus.mesh", "height": "surface.height" },
                              "params": { "tiling": [12, 5], "shell": 0.0444, "density": 2.0 } },
            "ours": { "kind": "render.mesh",
                      "inputs": { "mesh": "torus.mesh", "btf": "capture.btf", "mdf": "mdf.mdf" },
                      "params": { "camera": camera, "light": light, "tiling": [12, 5], "shell": 0.0444,
                                  "mm_per_unit": 20.0, "shadows": true, "shadow_resolution": 1024,
                                  "frames": frames } },
            "save_ours": { "kind": "npy.write", "inputs": { "value": "ours.image" }, "params": { "path": "ours.npy" } },
            "save_ours_mask": { "kind": "npy.write", "inputs": { "value": "ours.mask" }, "params": { "path": "ours_mask.npy" } },
            // The same scene for Mitsuba: the true geometry as PLY and the environment as EXR.
            "export": { "kind": "export.mitsuba", "inputs": { "mesh": "true_surface.mesh" },
                        "params": { "path": "mitsuba/scene.xml", "camera": camera, "light": light,
                                    "albedo": rho, "bounces": bounces } }
        }
    })
}

/// `mesoflow run GRAPH --output save_ours,save_ours_mask,export` on the CPU: the report or why not.
fn run(dir: &Path) -> Result<Value, String> {
    let out = dir.join("out");
    cli::output_or_last_error(
        Command::new(cli::bin())
            .args(["run"])
            .arg(dir.join("graph.json"))
            .args([
                "--output",
                "save_ours.files",
                "--output",
                "save_ours_mask.files",
                "--output",
                "export.files",
            ])
            .args(["--quiet", "--no-cache", "--device", "cpu", "--out-dir"])
            .arg(&out),
    )?;
    serde_json::from_slice(&std::fs::read(out.join("report.json")).map_err(|e| e.to_string())?)
        .map_err(|e| e.to_string())
}

/// Mitsuba's truth and its time at ours' error: `benches/mesh_peer.py`'s JSON line, or why not.
fn peer(
    dir: &Path,
    p: &Point,
    res: [u32; 2],
    spp: u32,
    truth_spp: u32,
    ours_s: f64,
) -> Result<Value, String> {
    let out = dir.join("out");
    let light = match p.light.as_str() {
        "sun" => json!({ "direction": SUN, "intensity": 3.0 }),
        _ => json!({ "envmap": out.join("mitsuba/scene_environment.exr"), "rotation": 0.0 }),
    };
    let rho = [p.albedo; 3];
    let scene = json!({
        "mesh": out.join("mitsuba/scene.ply"),
        "camera": { "eye": EYE, "target": TARGET, "up": [0.0, 1.0, 0.0], "fov": FOV, "resolution": res },
        "light": light, "albedo": rho, "samples": spp, "repeats": 3,
        "max_depth": p.bounces + 2, "variant": "llvm_ad_rgb",
        "truth_samples": truth_spp,
        "compare": { "ours": { "image": out.join("ours.npy"), "mask": out.join("ours_mask.npy"), "seconds": ours_s } },
    });
    cli::mesh_peer(dir, &scene)
}

struct Point {
    light: String,
    bounces: u32,
    albedo: f64,
}

fn charts(rows: &[Value], out: &Path) {
    let ratio = |r: &Value| r["ratio"].as_f64();
    let mut by_albedo = Vec::new();
    for light in ["sun", "sky", "studio"] {
        for bounces in [0u64, 4] {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r["light"] == light && r["bounces"].as_u64() == Some(bounces))
                .filter_map(|r| Some((r["albedo"].as_f64()?, ratio(r)?)))
                .collect();
            if !points.is_empty() {
                by_albedo.push(Series {
                    name: format!("{light}, {bounces} bounces"),
                    points,
                    scatter: false,
                });
            }
        }
    }
    let lights = ["sun", "sky", "studio"];
    let by_light: Vec<Series> = [0.3, 0.6, 0.9]
        .iter()
        .map(|&a| Series {
            name: format!("albedo {a}, 4 bounces"),
            points: lights
                .iter()
                .enumerate()
                .filter_map(|(i, l)| {
                    let r = rows.iter().find(|r| {
                        r["light"] == *l
                            && r["bounces"].as_u64() == Some(4)
                            && r["albedo"].as_f64().is_some_and(|x| (x - a).abs() < 1e-9)
                    })?;
                    Some((i as f64, ratio(r)?))
                })
                .collect(),
            scatter: true,
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    let names: Vec<String> = lights.iter().map(|s| s.to_string()).collect();
    for (name, c) in [
        (
            "environment_albedo",
            Chart {
                title: "Ours' frame over Mitsuba's path tracer at equal error".into(),
                x_label: "albedo of the mesostructure",
                y_label: "render.mesh frame / Mitsuba at ours' error",
                series: by_albedo,
                x_names: None,
            },
        ),
        (
            "environment_light",
            Chart {
                title: "By light, 4 bounces".into(),
                x_label: "light",
                y_label: "render.mesh frame / Mitsuba at ours' error",
                series: by_light,
                x_names: Some(names.clone()),
            },
        ),
    ] {
        if let Err(e) = chart::write(&out.join(name), &c) {
            eprintln!("chart {name}: {e}");
        }
    }
}

fn list<T: std::str::FromStr>(name: &str, default: &str) -> Vec<T> {
    let s: String = arg(name, default.to_string());
    s.split(',').filter_map(|v| v.trim().parse().ok()).collect()
}

fn main() {
    let out: PathBuf = arg("--out", PathBuf::from("target/environment"));
    std::fs::create_dir_all(&out).expect("the output folder");
    let replot: String = arg("--replot", String::new());
    if !replot.is_empty() {
        let rows: Vec<Value> =
            serde_json::from_slice(&std::fs::read(&replot).expect("--replot FILE")).expect("rows");
        charts(&rows, &out);
        return;
    }
    let lights: Vec<String> = list("--lights", "sun,sky,studio");
    let bounces: Vec<u32> = list("--bounces", "0,4");
    let albedos: Vec<f64> = list("--albedos", "0.3,0.6,0.9");
    let res: String = arg("--resolution", "640x480".to_string());
    let res: Vec<u32> = res.split('x').filter_map(|v| v.parse().ok()).collect();
    let res = [res[0], res[1]];
    let (spp, truth_spp, frames): (u32, u32, u32) =
        (arg("--spp", 4), arg("--truth-spp", 64), arg("--frames", 3));
    let mut rows = Vec::new();
    println!("| light | bounces | albedo | ours' frame, ms | environment once, ms | ours' relative RMSE | Mitsuba spp at ours' error | Mitsuba at ours' error, ms | ours / Mitsuba |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for l in &lights {
        for &b in &bounces {
            for &a in &albedos {
                let p = Point {
                    light: l.clone(),
                    bounces: b,
                    albedo: a,
                };
                let dir = out.join(format!("{l}_{b}_{a}"));
                std::fs::create_dir_all(&dir).expect("a point's folder");
                std::fs::write(
                    dir.join("graph.json"),
                    graph(l, b, a, res, frames).to_string(),
                )
                .expect("the graph");
                let report = run(&dir);
                let ours = report.as_ref().ok().map(|r| cli::node(r, "ours").clone());
                let frame_ms = ours
                    .as_ref()
                    .and_then(|o| o["timings"]["frame_ms"].as_f64());
                let env_ms = ours
                    .as_ref()
                    .and_then(|o| o["timings"]["environment_ms"].as_f64());
                let theirs = match frame_ms {
                    Some(ms) => peer(&dir, &p, res, spp, truth_spp, ms / 1e3),
                    None => Err(report.clone().err().unwrap_or_else(|| "no frame".into())),
                };
                let c = theirs.as_ref().ok().map(|t| t["compared"]["ours"].clone());
                let get = |k: &str| c.as_ref().and_then(|c| c[k].as_f64());
                let row = json!({
                    "light": l, "bounces": b, "albedo": a, "image": res, "spp": spp, "truth_spp": truth_spp,
                    "ours_ms": frame_ms, "environment_ms": env_ms,
                    "rel": get("rel"), "flip": get("flip"), "equal_spp": get("equal_spp"),
                    "equal_ms": get("equal_s").map(|s| s * 1e3), "ratio": get("equal_ratio"),
                    "mitsuba_noise": theirs.as_ref().ok().and_then(|t| t["noise"].as_f64()),
                    "mitsuba_1spp_ms": theirs.as_ref().ok().and_then(|t| t["frame1_s"].as_f64()).map(|s| s * 1e3),
                    "error": theirs.as_ref().err(),
                });
                let f = |k: &str, d: usize| {
                    row[k]
                        .as_f64()
                        .map_or("—".to_string(), |v| format!("{v:.d$}"))
                };
                println!(
                    "| {l} | {b} | {a} | {} | {} | {} | {} | {} | {} |{}",
                    f("ours_ms", 0),
                    f("environment_ms", 0),
                    f("rel", 3),
                    f("equal_spp", 1),
                    f("equal_ms", 0),
                    f("ratio", 3),
                    theirs
                        .as_ref()
                        .err()
                        .map(|e| format!(" {e}"))
                        .unwrap_or_default()
                );
                rows.push(row);
                std::fs::write(
                    out.join("environment.json"),
                    serde_json::to_string_pretty(&rows).unwrap(),
                )
                .expect("the rows");
            }
        }
    }
    charts(&rows, &out);
}
