//! Cost as the work grows, against brute force, in one run: `render.mesh` (a BTF and an MDF on
//! a torus) beside Mitsuba 3 path-tracing the true displaced geometry of the same scene
//! (`mesh.displace`, written as PLY; `benches/mesh_peer.py`, the peer venv's `llvm_ad_rgb`), one
//! axis at a time from the torus (320 × 240, a 64² bumps tile captured at UBO2003's
//! 81 × 81 directions as a raw BTF, its MDF, shadows on at a 2 048² map, 12 × 5 tiles):
//!
//! - `size`: the image from 160 × 120 to 1 280 × 960, the tiles fixed;
//! - `area`: the tiles from 6 × 2 up, the image growing with them so a tile keeps its size in
//!   pixels;
//! - `tiles`: the same tiles at a fixed 640 × 480 (minification);
//! - `plane`: a plane tiled n × n from 2 × 2 to 128 × 128 at a fixed 640 × 480, the relief
//!   keeping its shape, where brute force may also instance one displaced tile (Mitsuba's
//!   `shapegroup` and one `instance` a tile; a curved surface's tiles differ, so the torus
//!   cannot).
//!
//! Per point: ours' CPU frame (`timings.frame_ms`, the mean of `--frames` after the image's
//! frame, every node on the CPU) and its stages, the peak resident set of ours' process and of
//! the brute-force side's (`/usr/bin/time`'s maximum resident set for `mesh.displace`, the
//! Python process's own for Mitsuba), the true geometry's triangles, Mitsuba's scene load (PLY
//! and BVH), first frame (JIT) and frame at `--spp` samples a pixel (median of 5), and the ratio
//! of the two frames. Where `mesh.displace`'s `max_triangles` or the memory budget refuses the
//! true geometry, the row says so and goes on.
//!
//! And at equal error: Mitsuba renders a converged truth of the same scene (`--truth-spp`, 256
//! a pixel, in passes of `--spp`), against which ours, normal mapping (`render.reference` on the
//! smooth mesh with the tile's normals, slopes scaled to the true surface's, 4 samples a pixel)
//! and relief mapping (`render.relief` of the tile's heights, a Lambert map fitted to a flat
//! capture) are measured (relative RMSE over the pixels either image covers, the truth's noise
//! taken out; mean FLIP beside it where `flip_evaluator` is installed), and Mitsuba's own time to
//! the same error (the samples a pixel its measured noise needs, at least one; the frame
//! interpolated between its 1-sample and `--spp` frames); and our own path tracer on the same
//! true geometry (`render.reference`, 4 samples a pixel, its time at ours' error from its own
//! noise; `--no-reference` skips it). Every figure is from the same run.
//! Ours' and the cheaper models' times are their frames (render.mesh's `frame_ms`; the others'
//! node seconds, one frame), Mitsuba's its frame, scene loading (PLY, BVH) and JIT beside it.
//!
//! The rows go to `OUT/scaling.json` and three charts beside it (`scaling_tiles`: both frames
//! against the tiles at a fixed image; `scaling_memory`: peak memory against the tiles;
//! `scaling_pixels`: ours over Mitsuba against the image's pixels), PNG and SVG; `--replot
//! FILE.json` draws the charts again from such a file without running anything.
//!
//! `cargo bench --bench scaling -- [--axis size|area|tiles|all] [--spp 16] [--frames 3]
//! [--max-area-tiles 96] [--max-plane-tiles 128] [--truth-spp 256] [--peer-limit-s 600]
//! [--out target/scaling] [--replot FILE.json]`; needs the peer venv (`target/peer-venv`, as
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

/// The plane's side (world units) and where it is seen from: the `plane` axis tiles it n × n
/// at a fixed image, the relief keeping its shape (the shell a tile's side × 6/64).
const PLANE: f64 = 2.0;
const PLANE_EYE: [f64; 3] = [0.0, -1.7, 1.5];

/// One point of an axis: the surface, its tiles (around and along the torus, or across and up
/// the plane), and the image.
#[derive(Clone, Copy, Debug)]
struct Point {
    plane: bool,
    tiles: [u32; 2],
    resolution: [u32; 2],
}

impl Point {
    /// The world depth of the relief: the torus's fixed shell, or on the plane a tile's side
    /// times the tile's depth over its width in texels (the same bumps at every tile count).
    fn shell(&self) -> f64 {
        if self.plane {
            PLANE / self.tiles[0] as f64 * DEPTH / 64.0
        } else {
            SHELL
        }
    }

    fn camera(&self) -> Value {
        let (eye, target) = if self.plane {
            (PLANE_EYE, [0.0, 0.0, 0.0])
        } else {
            (EYE, TARGET)
        };
        json!({ "eye": eye, "target": target, "fov": FOV, "resolution": self.resolution })
    }

    /// The scale of `heightfield.normals`' slopes (texels of height per texel across) that
    /// makes them the true surface's: the shell's world units per texel of height over a
    /// texel's world width (the mean of the torus's two directions at its major radius).
    fn slope_scale(&self) -> f64 {
        let texel = if self.plane {
            PLANE / self.tiles[0] as f64 / 64.0
        } else {
            let u = std::f64::consts::TAU * 0.9 / self.tiles[0] as f64 / 64.0;
            let v = std::f64::consts::TAU * 0.38 / self.tiles[1] as f64 / 64.0;
            0.5 * (u + v)
        };
        self.shell() / DEPTH / texel
    }
}

fn graph(p: Point, frames: u32) -> Value {
    let camera = p.camera();
    let light = json!({ "direction": LIGHT, "intensity": 3.0 });
    let tiling = [p.tiles[0] as f64, p.tiles[1] as f64];
    let shell = p.shell();
    let surface = if p.plane {
        // One cell a tile, so that the true geometry is the instanced tile's triangles repeated.
        json!({ "kind": "mesh.primitive",
                "params": { "shape": "plane", "size": PLANE, "segments": p.tiles } })
    } else {
        json!({ "kind": "mesh.primitive",
                "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [96, 48] } })
    };
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
            "shape": surface,
            "ours": { "kind": "render.mesh",
                      "inputs": { "mesh": "shape.mesh", "btf": "capture.btf", "mdf": "mdf.mdf" },
                      "params": { "camera": camera, "light": light, "tiling": tiling, "shell": shell,
                                  "shadows": true, "shadow_resolution": 2048, "frames": frames } },
            "true_surface": { "kind": "mesh.displace",
                              "inputs": { "mesh": "shape.mesh", "height": "surface.height" },
                              "params": { "tiling": tiling, "shell": shell, "depth": DEPTH } },
            "ply": { "kind": "mesh.write", "inputs": { "mesh": "true_surface.mesh" },
                     "params": { "path": "truth.ply" } },
            // One displaced tile, for Mitsuba's instancing on the plane (a shapegroup and one
            // instance a tile): the same triangles as the plane's true geometry, stored once.
            "tile": { "kind": "mesh.primitive",
                      "params": { "shape": "plane", "size": PLANE / p.tiles[0] as f64, "segments": [1, 1] } },
            "true_tile": { "kind": "mesh.displace",
                           "inputs": { "mesh": "tile.mesh", "height": "surface.height" },
                           "params": { "tiling": [1.0, 1.0], "shell": shell, "depth": DEPTH } },
            "tile_ply": { "kind": "mesh.write", "inputs": { "mesh": "true_tile.mesh" },
                          "params": { "path": "tile.ply" } },
            // The cheaper models a user tries first. Normal mapping: the smooth surface with the
            // tile's normals, slopes scaled to the true surface's, through the path tracer.
            "normals": { "kind": "heightfield.normals", "inputs": { "height": "surface.height" },
                         "params": { "scale": p.slope_scale() } },
            "normal_mapped": { "kind": "render.reference",
                               "inputs": { "mesh": "shape.mesh", "normals": "normals.normals" },
                               "params": { "camera": camera, "light": light, "tiling": tiling,
                                           "albedo": ALBEDO, "samples": 4 } },
            // Relief mapping of the tile's heights with a Lambert material: the flat tile
            // captured at a few directions and fitted (ρs → 0).
            "flat": { "kind": "heightfield.procedural",
                      "params": { "pattern": "bumps", "size": 64, "count": 4, "depth": 0.0 } },
            "flat_capture": { "kind": "btf.capture", "inputs": { "height": "flat.height" },
                              "params": { "views": { "thetas": [0, 30, 60], "phis": [0, 120, 240] },
                                          "lights": { "thetas": [0, 30, 60], "phis": [0, 120, 240] },
                                          "brdf": "lambert", "albedo": ALBEDO } },
            "fit": { "kind": "brdf.fit_ward", "inputs": { "btf": "flat_capture.btf" },
                     "params": { "clusters": 1 } },
            "relief": { "kind": "render.relief",
                        "inputs": { "mesh": "shape.mesh", "height": "surface.height", "maps": "fit.maps" },
                        "params": { "camera": camera, "light": light, "tiling": tiling, "shell": shell } },
            "save_ours": { "kind": "npy.write", "inputs": { "value": "ours.image" }, "params": { "path": "ours.npy" } },
            "save_ours_mask": { "kind": "npy.write", "inputs": { "value": "ours.mask" }, "params": { "path": "ours_mask.npy" } },
            "save_normal_mapped": { "kind": "npy.write", "inputs": { "value": "normal_mapped.image" }, "params": { "path": "normal_mapped.npy" } },
            "save_normal_mapped_mask": { "kind": "npy.write", "inputs": { "value": "normal_mapped.coverage" }, "params": { "path": "normal_mapped_mask.npy" } },
            "save_relief": { "kind": "npy.write", "inputs": { "value": "relief.image" }, "params": { "path": "relief.npy" } },
            "save_relief_mask": { "kind": "npy.write", "inputs": { "value": "relief.mask" }, "params": { "path": "relief_mask.npy" } },
            // Our own path tracer on the same true geometry (brute force beside Mitsuba), at 4
            // samples a pixel: its noise from its own two halves sets its time at ours' error.
            "reference": { "kind": "render.reference", "inputs": { "mesh": "true_surface.mesh" },
                           "params": { "camera": camera, "light": light, "albedo": ALBEDO, "samples": 4 } },
            "save_reference": { "kind": "npy.write", "inputs": { "value": "reference.image" }, "params": { "path": "reference.npy" } },
            "save_reference_mask": { "kind": "npy.write", "inputs": { "value": "reference.coverage" }, "params": { "path": "reference_mask.npy" } }
        }
    })
}

/// Runs `mesoflow run GRAPH --output WHAT` (several outputs: comma-separated) on the CPU under
/// `/usr/bin/time` where it exists: the report, or the error's last line; and the process's
/// peak resident set, MiB. Its output folder is `out-WHAT` in `dir`.
fn run(dir: &Path, cache: &Path, what: &str) -> (Result<Value, String>, Option<f64>) {
    let out = out_dir(dir, what);
    let mut args: Vec<String> = vec!["run".into(), dir.join("graph.json").display().to_string()];
    for w in what.split(',') {
        args.push("--output".into());
        args.push(w.into());
    }
    args.extend(["--quiet", "--device", "cpu", "--cache-dir"].map(String::from));
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

fn out_dir(dir: &Path, what: &str) -> PathBuf {
    dir.join(format!("out-{}", what.replace(['.', ','], "-")))
}

/// Runs `what` (one render's image) so that it is computed in this process: an entry an earlier
/// bench left in the cache is removed first, so its time and memory are this run's (the
/// material and MDF stay cached: they are made once per material).
fn fresh(dir: &Path, cache: &Path, what: &str) -> (Result<Value, String>, Option<f64>) {
    let id = what.split('.').next().unwrap_or(what);
    let (r, rss) = run(dir, cache, what);
    let key = r.as_ref().ok().and_then(|r| {
        let n = cli::node(r, id);
        (n["status"] != "computed").then(|| n["key"].as_str().map(String::from))?
    });
    match key {
        Some(k) => {
            let _ = std::fs::remove_file(cache.join(&k[..2]).join(format!("{k}.mfc")));
            run(dir, cache, what)
        }
        None => (r, rss),
    }
}

/// What Mitsuba is given: the true geometry whole (`mesh`), or on the plane one displaced tile
/// instanced once a tile (`instances`); with `compare`, the other renderers' images to measure
/// against its converged truth.
enum Geometry<'a> {
    Whole(&'a Path),
    Instanced(&'a Path),
}

/// Mitsuba on the true geometry: its JSON line, or why not.
fn peer(
    dir: &Path,
    p: Point,
    spp: u32,
    geometry: Geometry,
    compare: Option<(&Value, u32)>,
    limit_s: f64,
) -> Result<Value, String> {
    let python = cli::repo().join("target/peer-venv/bin/python");
    if !python.exists() {
        return Err("no peer venv (target/peer-venv; .ci/run makes it)".into());
    }
    let camera = p.camera();
    let mut scene = json!({
        "camera": { "eye": camera["eye"], "target": camera["target"], "up": [0.0, 1.0, 0.0], "fov": FOV, "resolution": p.resolution },
        "light": { "direction": LIGHT, "intensity": 3.0 },
        "albedo": ALBEDO,
        "samples": spp,
        "repeats": 5,
        "variant": "llvm_ad_rgb",
    });
    let ply = match geometry {
        Geometry::Whole(ply) => ply,
        Geometry::Instanced(ply) => {
            let n = p.tiles[0];
            let side = PLANE / n as f64;
            let offsets: Vec<[f64; 3]> = (0..n)
                .flat_map(|j| {
                    (0..n).map(move |i| {
                        [
                            (i as f64 + 0.5) * side - 0.5 * PLANE,
                            (j as f64 + 0.5) * side - 0.5 * PLANE,
                            0.0,
                        ]
                    })
                })
                .collect();
            scene["instances"] = json!(offsets);
            ply
        }
    };
    scene["mesh"] = json!(ply.display().to_string());
    if let Some((images, truth_spp)) = compare {
        scene["compare"] = images.clone();
        scene["truth_samples"] = json!(truth_spp);
        scene["truth_out"] = json!(dir.join("truth.npy").display().to_string());
    }
    let path = dir.join("mitsuba.json");
    std::fs::write(&path, scene.to_string()).expect("write the peer's scene");
    // The peer writes to files (a pipe left unread could fill and stall it) and is stopped
    // past `limit`: Mitsuba's LLVM variant traced a plane of 1 024 instances for over 13
    // minutes without finishing a frame's repeats, so a point may not hold the run up.
    let (stdout, stderr) = (dir.join("mitsuba.out"), dir.join("mitsuba.err"));
    let mut child = Command::new(&python)
        .arg(cli::repo().join("benches/mesh_peer.py"))
        .arg(&path)
        .stdout(std::fs::File::create(&stdout).map_err(|e| e.to_string())?)
        .stderr(std::fs::File::create(&stderr).map_err(|e| e.to_string())?)
        .spawn()
        .map_err(|e| e.to_string())?;
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break status;
        }
        if start.elapsed().as_secs_f64() > limit_s {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!(
                "stopped after {limit_s:.0} s (--peer-limit-s) without finishing"
            ));
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    if !status.success() {
        let err = std::fs::read_to_string(&stderr).unwrap_or_default();
        return Err(err.lines().last().unwrap_or("failed").to_string());
    }
    let text = std::fs::read_to_string(&stdout).map_err(|e| e.to_string())?;
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
        (
            "scaling_equal",
            Chart {
                title: "Ours' frame over Mitsuba's at ours' error".into(),
                x_label: "tiles of the 64² mesostructure (torus at 640 × 480; plane at 640 × 480)",
                y_label: "frame / Mitsuba's time to the same error",
                series: vec![
                    series(
                        "render.mesh, torus",
                        pick("tiles", &tiles, &get("equal_ratio")),
                    ),
                    series(
                        "render.mesh, plane",
                        pick("plane", &tiles, &get("equal_ratio")),
                    ),
                    series(
                        "render.relief, plane",
                        pick("plane", &tiles, &get("relief_equal_ratio")),
                    ),
                    series(
                        "normal mapping, plane",
                        pick("plane", &tiles, &get("normal_mapped_equal_ratio")),
                    ),
                ],
                x_names: None,
            },
        ),
        (
            "scaling_plane_memory",
            Chart {
                title: "Peak memory on the plane (640 × 480)".into(),
                x_label: "tiles of the 64² mesostructure on the plane",
                y_label: "peak resident set, MiB",
                series: vec![
                    series(
                        "render.mesh (raw BTF + MDF)",
                        pick("plane", &tiles, &get("ours_mib")),
                    ),
                    series(
                        "Mitsuba 3, whole true geometry",
                        pick("plane", &tiles, &get("mitsuba_mib")),
                    ),
                    series(
                        "Mitsuba 3, one tile instanced",
                        pick("plane", &tiles, &get("instanced_mib")),
                    ),
                ],
                x_names: None,
            },
        ),
    ];
    // The translucent albedo axis (measured by the families bench, its rows added to the file
    // with that bench's command): each material's ratio at equal error, in the order given.
    let albedo: Vec<&Value> = rows.iter().filter(|r| r["axis"] == "albedo").collect();
    let ratio_of = |k: &str| -> Vec<(f64, f64)> {
        albedo
            .iter()
            .enumerate()
            .filter_map(|(i, r)| Some((i as f64, r[k].as_f64()?)))
            .collect()
    };
    let albedo_chart = (
        "scaling_albedo",
        Chart {
            title: "Translucency at 640 × 480: the path tracers' time at ours' error over ours'"
                .into(),
            x_label: "material (Jensen's presets, low to high albedo)",
            y_label: "path tracer's time at ours' error / ours' first frame",
            series: vec![
                series("Mitsuba 3 volpathmis", ratio_of("mitsuba_ratio")),
                series("render.reference", ratio_of("reference_ratio")),
            ],
            x_names: Some(
                albedo
                    .iter()
                    .map(|r| r["material"].as_str().unwrap_or("?").to_string())
                    .collect(),
            ),
        },
    );
    let made = made.into_iter().chain([albedo_chart]);
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
    let max_plane: u32 = arg("--max-plane-tiles", 128);
    let truth_spp: u32 = arg("--truth-spp", 256);
    let limit_s: f64 = arg("--peer-limit-s", 600.0);
    // Our own path tracer beside Mitsuba (slow on millions of triangles; `--no-reference` skips it).
    let with_reference = !std::env::args().any(|a| a == "--no-reference");
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
        plane: false,
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
            points.push((
                name,
                Point {
                    plane: false,
                    tiles,
                    resolution,
                },
            ));
            k *= 2;
        }
    }
    // The plane tiled n × n from 2 × 2 to 128 × 128 at a fixed 640 × 480: brute force may
    // instance one tile there (measured beside the whole geometry).
    if axis == "plane" || axis == "all" {
        let mut n = 2;
        while n <= max_plane {
            points.push((
                "plane",
                Point {
                    plane: true,
                    tiles: [n, n],
                    resolution: [640, 480],
                },
            ));
            n *= 4;
        }
    }
    let mut rows: Vec<Value> = Vec::new();
    let mut equal: Vec<String> = Vec::new();
    println!(
        "| axis | tiles | image | ours' frame, ms | BTF-read limit, ms | layers / shade, ms | shadow texels | ours' peak, MiB | true triangles | displace peak, MiB | Mitsuba load, s | Mitsuba first frame, s | Mitsuba {spp} spp, ms | Mitsuba peak, MiB | ours / Mitsuba | instanced Mitsuba {spp} spp, ms | instanced peak, MiB |"
    );
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (name, p) in points {
        let dir = out.join(format!(
            "{name}-{}x{}-{}x{}",
            p.tiles[0], p.tiles[1], p.resolution[0], p.resolution[1]
        ));
        std::fs::create_dir_all(&dir).expect("the point's folder");
        std::fs::write(dir.join("graph.json"), graph(p, frames).to_string())
            .expect("write the graph");
        let (ours, ours_rss) = fresh(&dir, &cache, "ours.image");
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
        // The cheaper models, each timed as a whole node (one frame, computed in this run).
        let cheap = |id: &str| -> Option<f64> {
            match fresh(&dir, &cache, &format!("{id}.image")) {
                (Ok(r), _) => cli::node(&r, id)["seconds"].as_f64(),
                (Err(e), _) => {
                    eprintln!("scaling: {name} {p:?}: {id}: {e}");
                    None
                }
            }
        };
        let (normal_s, relief_s) = (cheap("normal_mapped"), cheap("relief"));
        // The true geometry (where mesh.displace makes it), and our path tracer on it.
        let (truth, displace_rss) = run(&dir, &cache, "ply.file");
        let (reference_s, reference_noise) = if truth.is_ok() && with_reference {
            match fresh(&dir, &cache, "reference.image") {
                (Ok(r), _) => {
                    let n = cli::node(&r, "reference");
                    (n["seconds"].as_f64(), n["metrics"]["noise"].as_f64())
                }
                (Err(e), _) => {
                    eprintln!("scaling: {name} {p:?}: reference: {e}");
                    (None, None)
                }
            }
        } else {
            (None, None)
        };
        // Every image and mask as .npy for the peer's comparison (all cached by now).
        let mut saves = "save_ours.files,save_ours_mask.files,save_normal_mapped.files,save_normal_mapped_mask.files,save_relief.files,save_relief_mask.files".to_string();
        if reference_s.is_some() {
            saves.push_str(",save_reference.files,save_reference_mask.files");
        }
        let saves = saves.as_str();
        let saved = out_dir(&dir, saves);
        let compare = match run(&dir, &cache, saves).0 {
            Ok(_) => {
                let entry = |name: &str, seconds: Option<f64>| {
                    json!({ "image": saved.join(format!("{name}.npy")),
                            "mask": saved.join(format!("{name}_mask.npy")), "seconds": seconds })
                };
                let mut c = json!({
                    "ours": entry("ours", frame.map(|f| f / 1e3)),
                    "normal_mapped": entry("normal_mapped", normal_s),
                    "relief": entry("relief", relief_s),
                });
                if reference_s.is_some() {
                    c["reference"] = entry("reference", reference_s);
                }
                Some(c)
            }
            Err(e) => {
                eprintln!("scaling: {name} {p:?}: no images to compare: {e}");
                None
            }
        };
        let compare = compare.as_ref().map(|c| (c, truth_spp));
        let whole_ply = out_dir(&dir, "ply.file").join("truth.ply");
        // The truth from the whole geometry where mesh.displace makes it; on the plane one
        // displaced tile instanced is timed beside it (the same triangles), and is the truth's
        // scene where the whole geometry is refused.
        let (triangles, mitsuba) = match truth {
            Ok(_) => {
                let m = peer(&dir, p, spp, Geometry::Whole(&whole_ply), compare, limit_s);
                let _ = std::fs::remove_file(&whole_ply);
                match m {
                    Ok(m) => (m["triangles"].as_f64(), Ok(m)),
                    Err(e) => (None, Err(e)),
                }
            }
            Err(e) => (None, Err(format!("mesh.displace refused: {e}"))),
        };
        let instanced = p.plane.then(|| {
            let tile = run(&dir, &cache, "tile_ply.file,true_tile.subdivision").0;
            let tile_ply = out_dir(&dir, "tile_ply.file,true_tile.subdivision").join("tile.ply");
            let judge = if mitsuba.is_ok() { None } else { compare };
            let r = tile
                .and_then(|_| peer(&dir, p, spp, Geometry::Instanced(&tile_ply), judge, limit_s));
            let _ = std::fs::remove_file(&tile_ply);
            r
        });
        let m = mitsuba.as_ref().ok();
        let inst = instanced.as_ref().and_then(|r| r.as_ref().ok());
        let judged = m
            .filter(|m| m.get("compared").is_some())
            .or(inst.filter(|m| m.get("compared").is_some()));
        let cmp = |who: &str, k: &str| judged.and_then(|j| j["compared"][who][k].as_f64());
        // render.reference's time at ours' error: its 4-sample time × (its noise / ours' error)²,
        // at least one sample a pixel (the families bench's rule).
        let reference_equal_ms = match (reference_s, reference_noise, cmp("ours", "rel")) {
            (Some(t), Some(n), Some(e)) if e > 0.0 => {
                Some(t * 1e3 * (n / e).powi(2).clamp(0.25, f64::INFINITY))
            }
            _ => None,
        };
        let row = json!({
            "axis": name, "plane": p.plane, "tiles": p.tiles, "image": p.resolution, "spp": spp,
            "ours_ms": frame, "btf_limit_ms": limit, "layers_ms": t["layers_ms"], "shade_ms": t["shade_ms"],
            "shadow_texels": t["shadow_texels"], "ours_mib": ours_rss,
            "triangles": triangles, "displace_mib": displace_rss,
            "mitsuba_load_s": m.map(|m| &m["load_s"]), "mitsuba_first_s": m.map(|m| &m["first_s"]),
            "mitsuba_ms": m.and_then(|m| m["frame_s"].as_f64()).map(|s| s * 1e3),
            "mitsuba_mib": m.map(|m| &m["peak_rss_mib"]),
            "refused": mitsuba.as_ref().err(),
            "instanced_load_s": inst.map(|m| &m["load_s"]),
            "instanced_ms": inst.and_then(|m| m["frame_s"].as_f64()).map(|s| s * 1e3),
            "instanced_mib": inst.map(|m| &m["peak_rss_mib"]),
            "truth_samples": judged.map(|j| &j["truth_samples"]),
            "mitsuba_noise": judged.map(|j| &j["noise"]),
            "mitsuba_1spp_ms": judged.and_then(|j| j["frame1_s"].as_f64()).map(|s| s * 1e3),
            "ours_rel": cmp("ours", "rel"), "ours_flip": cmp("ours", "flip"),
            "equal_spp": cmp("ours", "equal_spp"),
            "equal_ms": cmp("ours", "equal_s").map(|s| s * 1e3),
            "equal_ratio": cmp("ours", "equal_ratio"),
            "normal_mapped_ms": normal_s.map(|s| s * 1e3), "normal_mapped_rel": cmp("normal_mapped", "rel"),
            "normal_mapped_flip": cmp("normal_mapped", "flip"), "normal_mapped_equal_ratio": cmp("normal_mapped", "equal_ratio"),
            "relief_ms": relief_s.map(|s| s * 1e3), "relief_rel": cmp("relief", "rel"),
            "relief_flip": cmp("relief", "flip"), "relief_equal_ratio": cmp("relief", "equal_ratio"),
        });
        // Set apart: one json! of every field passes the macro's recursion limit.
        let mut row = row;
        for (k, v) in [
            ("reference_ms", reference_s.map(|s| s * 1e3)),
            ("reference_noise", reference_noise),
            ("reference_rel", cmp("reference", "rel")),
            ("reference_equal_ms", reference_equal_ms),
            (
                "reference_equal_ratio",
                frame.zip(reference_equal_ms).map(|(a, b)| a / b),
            ),
        ] {
            row[k] = json!(v);
        }
        if let Err(e) = &mitsuba {
            eprintln!("scaling: {name} {p:?}: no Mitsuba frame of the whole geometry: {e}");
        }
        if let Some(Err(e)) = &instanced {
            eprintln!("scaling: {name} {p:?}: no instanced Mitsuba frame: {e}");
        }
        let f = |k: &str, d: usize| {
            row[k]
                .as_f64()
                .map_or("absent".into(), |x| format!("{x:.d$}"))
        };
        let ratio = match (frame, row["mitsuba_ms"].as_f64()) {
            (Some(a), Some(b)) => format!("{:.2}×", a / b),
            _ => "absent".into(),
        };
        println!(
            "| {name} | {} × {} | {} × {} | {} | {} | {} / {} | {} | {} | {} | {} | {} | {} | {} | {} | {ratio} | {} | {} |",
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
            f("mitsuba_load_s", 2),
            f("mitsuba_first_s", 2),
            f("mitsuba_ms", 0),
            f("mitsuba_mib", 0),
            f("instanced_ms", 0),
            f("instanced_mib", 0),
        );
        equal.push(format!(
            "| {name} | {} × {} | {} × {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            p.tiles[0],
            p.tiles[1],
            p.resolution[0],
            p.resolution[1],
            f("truth_samples", 0),
            f("ours_rel", 3),
            f("ours_flip", 3),
            ms(frame),
            f("mitsuba_noise", 3),
            f("equal_spp", 1),
            f("equal_ms", 0),
            row["equal_ratio"].as_f64().map_or("absent".into(), |x| format!("{x:.2}×")),
            f("normal_mapped_rel", 3),
            f("normal_mapped_ms", 0),
            row["normal_mapped_equal_ratio"].as_f64().map_or("absent".into(), |x| format!("{x:.2}×")),
            f("relief_rel", 3),
            f("relief_ms", 0),
            row["relief_equal_ratio"].as_f64().map_or("absent".into(), |x| format!("{x:.2}×")),
            f("reference_noise", 3),
            f("reference_rel", 3),
            f("reference_equal_ms", 0),
            row["reference_equal_ratio"].as_f64().map_or("absent".into(), |x| format!("{x:.2}×")),
        ));
        rows.push(row);
    }
    println!();
    println!("At equal error (each image against Mitsuba's converged truth, the truth's noise taken out; Mitsuba's time at the samples a pixel its noise needs to match):");
    println!();
    println!("| axis | tiles | image | truth spp | ours' relative RMSE | ours' FLIP | ours' frame, ms | Mitsuba noise at {spp} spp | Mitsuba spp at ours' error | Mitsuba at ours' error, ms | ours / Mitsuba | normal mapping: error | ms | / Mitsuba at its error | relief: error | ms | / Mitsuba at its error | render.reference: noise at 4 spp | its error | at ours' error, ms | ours / it |");
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for l in &equal {
        println!("{l}");
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
