//! The translucent family: `sss.render` with its defaults against the volumetric truth
//! (`render.reference` with the medium) over seeded translucent scenes (every Jensen preset,
//! spheres and tori, 10–60 mm a unit, lit from the front, the side and behind, η = 1). Per
//! scene: relative RMSE over the truth's coverage with the truth's own noise taken out, bias,
//! the thickness in reduced mean free paths, whether `sss.render` warned that the object is
//! thin, both renders' times (ours' first frame, `sss.lighting` and `sss.render`, and another view
//! of the scene from the cached lighting, `sss.render` alone) and the path tracer's time at ours' error (scaled from its noise,
//! 1/√samples); then the distribution over the thick scenes with the worst five named, and how
//! the thin-object warning sorts the scenes.

use super::{distribution, equal_error_seconds, f3, percent, run, run_for, Options};
use mesoflow_nodes::sss::material::Preset;
use mesoflow_testkit::scenes::{self, translucent::Scene, Kind};
use serde_json::json;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `sss.render` warns under six reduced mean free paths (`sss::render::thickness`).
const THIN: f64 = 6.0;

struct Row {
    scene: Scene,
    paths: f64,
    rel: Option<f64>,
    bias: Option<f64>,
    noise: Option<f64>,
    warned: bool,
    /// The first frame: `sss.lighting` and `sss.render`.
    ours_s: f64,
    /// Another view of the same scene: `sss.render` from the cached lighting.
    view_s: f64,
    truth_s: f64,
    /// The truth's samples a pixel.
    samples: u32,
    /// The `mesoflow run` line that renders this scene.
    command: String,
    /// Its truth | ours | difference picture.
    picture: PathBuf,
}

impl Row {
    fn equal_error_s(&self) -> Option<f64> {
        equal_error_seconds(self.truth_s, self.samples, self.noise, self.rel)
    }
}

pub fn bench(options: &Options) {
    println!(
        "| seed | scene | mean free paths | relative RMSE | bias | truth noise | thin warning | ours, s | a view from the cache, s | truth, s | truth at ours' error, s |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let mut rows = Vec::new();
    for seed in options.first..options.first + options.count {
        let scenes::Scene::Translucent(scene) = scenes::family(Kind::Translucent, seed) else {
            unreachable!("the translucent family draws translucent scenes")
        };
        // Its thickness as the `--set`s make it (the albedo and size axes set the preset and the
        // scale).
        let set = as_set(&scene, options);
        let preset: Preset =
            serde_json::from_value(Value::from(set.preset)).expect("a preset name");
        let paths = scenes::translucent::mean_free_paths(&set, preset.coefficients());
        let r = run(&scenes::Scene::Translucent(scene.clone()), options);
        // Both of ours' nodes' times, also where the render came from the cache whole.
        let times = run_for(
            &scenes::Scene::Translucent(scene.clone()),
            options,
            &["lighting.points", "ours.image"],
            "times",
        );
        let row = Row {
            paths,
            rel: r.relative_rmse(),
            bias: r.metric("error", "bias"),
            noise: r.metric("truth", "noise"),
            warned: r.warned("lighting", "diffusion needs"),
            ours_s: times.seconds("lighting").unwrap_or(f64::NAN)
                + times.seconds("ours").unwrap_or(f64::NAN),
            view_s: times.seconds("ours").unwrap_or(f64::NAN),
            truth_s: r.seconds("truth").unwrap_or(f64::NAN),
            samples: options.samples,
            command: r.command,
            picture: r.picture,
            scene,
        };
        println!(
            "| {seed} | {} | {:.1} | {} | {} | {} | {} | {:.1} | {:.2} | {:.1} | {} |",
            as_set(&row.scene, options).name(),
            row.paths,
            f3(row.rel),
            percent(row.bias),
            f3(row.noise),
            if row.warned { "yes" } else { "no" },
            row.ours_s,
            row.view_s,
            row.truth_s,
            row.equal_error_s()
                .map_or("absent".into(), |t| format!("{t:.2}"))
        );
        rows.push(row);
    }
    summary(&rows);
    if !options.widths.is_empty() {
        larger(&rows, options);
    }
}

/// The path tracer's samples a pixel in [`larger`]'s runs: enough to measure its noise.
const LARGER_SAMPLES: u32 = 16;

/// Each scene again at `options.widths`: ours' first frame and a view from the cached lighting,
/// beside the path tracer's time at ours' error there. Ours' error is the one measured at the
/// family's size (a model's bias, not noise, and the gather through the samples leaves it
/// within 0.004 of the per-pixel gather's there); the path tracer's noise and time are measured
/// at each size at [`LARGER_SAMPLES`] a pixel and scaled to ours' error (1/√samples, no clamp).
fn larger(rows: &[Row], options: &Options) {
    println!(
        "\nlarger images: ours against the path tracer at ours' error (its noise and time measured at {LARGER_SAMPLES} samples a pixel, scaled)\n"
    );
    println!("| seed | scene | image | ours' error | covered pixels | gathers | ours' first frame, s | a view from the cache, s | its gather, s | path tracer {LARGER_SAMPLES} spp, s | its noise | path tracer at ours' error, s | its time / ours' first frame | / a view | Mitsuba {LARGER_SAMPLES} spp, s (noise) | Mitsuba at ours' error, s | its time / ours' first frame |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut ratios: Vec<(u32, f64, f64)> = Vec::new();
    let mut peer_ratios: Vec<(u32, f64)> = Vec::new();
    for row in rows {
        let scene = as_set(&row.scene, options);
        for &w in &options.widths {
            let mut o = options.clone();
            o.resolution = [w, w * options.resolution[1] / options.resolution[0].max(1)];
            o.samples = LARGER_SAMPLES;
            o.out = options.out.join(format!("width-{w}"));
            let r = run_for(
                &scenes::Scene::Translucent(row.scene.clone()),
                &o,
                &["lighting.points", "ours.image", "truth.image"],
                "times",
            );
            let timing = |name: &str| {
                mesoflow_testkit::cli::node(&r.report, "ours")["timings"][name].as_f64()
            };
            let view = r.seconds("ours").unwrap_or(f64::NAN);
            let first = r.seconds("lighting").unwrap_or(f64::NAN) + view;
            let pt = r.seconds("truth").unwrap_or(f64::NAN);
            let noise = r.metric("truth", "noise");
            let at_ours = match (noise, row.rel) {
                (Some(n), Some(e)) if e > 0.0 => Some(pt * (n / e).powi(2)),
                _ => None,
            };
            if let Some(t) = at_ours {
                ratios.push((w, t / first, t / view));
            }
            let peer = mitsuba(&scene, o.resolution, &o.out);
            let peer_at_ours = match (&peer, row.rel) {
                (Ok((t, n)), Some(e)) if e > 0.0 => Some(t * (n / e).powi(2)),
                _ => None,
            };
            if let Some(t) = peer_at_ours {
                peer_ratios.push((w, t / first));
            }
            println!(
                "| {} | {} | {} × {} | {} | {} | {} | {first:.2} | {view:.2} | {} | {pt:.2} | {} | {} | {} | {} | {} | {} | {} |",
                scene.seed,
                scene.name(),
                o.resolution[0],
                o.resolution[1],
                f3(row.rel),
                timing("covered_pixels").map_or("absent".into(), |v| format!("{v:.0}")),
                timing("gathers").map_or("absent".into(), |v| format!("{v:.0}")),
                timing("gather_seconds").map_or("absent".into(), |v| format!("{v:.2}")),
                f3(noise),
                at_ours.map_or("absent".into(), |t| format!("{t:.1}")),
                at_ours.map_or("absent".into(), |t| format!("{:.2}×", t / first)),
                at_ours.map_or("absent".into(), |t| format!("{:.2}×", t / view)),
                match &peer {
                    Ok((t, n)) => format!("{t:.2} ({n:.3})"),
                    Err(why) => format!("absent: {why}"),
                },
                peer_at_ours.map_or("absent".into(), |t| format!("{t:.1}")),
                peer_at_ours.map_or("absent".into(), |t| format!("{:.2}×", t / first)),
            );
        }
    }
    for &w in &options.widths {
        let firsts: Vec<f64> = ratios.iter().filter(|r| r.0 == w).map(|r| r.1).collect();
        let views: Vec<f64> = ratios.iter().filter(|r| r.0 == w).map(|r| r.2).collect();
        distribution(
            &format!("width {w}: the path tracer's time at ours' error over ours' first frame"),
            &firsts,
        );
        distribution(
            &format!("width {w}: the same over a view from the cache"),
            &views,
        );
        let peers: Vec<f64> = peer_ratios
            .iter()
            .filter(|r| r.0 == w)
            .map(|r| r.1)
            .collect();
        distribution(
            &format!("width {w}: Mitsuba's time at ours' error over ours' first frame"),
            &peers,
        );
    }
}

/// The scene as `options.extra` sets it (`material.preset`, `lighting.mm_per_unit`: the albedo
/// and size axes of the bench's `--set`s), for the peer, which reads the scene, not the graph.
fn as_set(scene: &Scene, options: &Options) -> Scene {
    let mut scene = scene.clone();
    for set in &options.extra {
        match set.split_once('=') {
            Some(("material.preset", v)) => {
                // A handful of names a bench run: leaking them is the simplest `&'static str`.
                scene.preset = Box::leak(v.trim_matches('"').to_string().into_boxed_str());
            }
            Some(("lighting.mm_per_unit", v)) => {
                if let Ok(mm) = v.parse() {
                    scene.mm_per_unit = mm;
                }
            }
            _ => {}
        }
    }
    scene
}

/// Mitsuba 3's `volpathmis` (`benches/sss_peer.py`, the peer venv's `llvm_ad_rgb`) on the same
/// scene at `resolution` and [`LARGER_SAMPLES`] a pixel: its frame (the median after a first
/// that compiles), s, and its noise; why not where the peer is missing or fails.
fn mitsuba(scene: &Scene, resolution: [u32; 2], dir: &Path) -> Result<(f64, f64), String> {
    let python = mesoflow_testkit::cli::repo().join("target/peer-venv/bin/python");
    if !python.exists() {
        return Err("no peer venv (target/peer-venv; .ci/run makes it)".into());
    }
    let dir = dir.join(format!("seed-{}", scene.seed)).join("mitsuba");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    // The family's mesh (its template's segments) as PLY.
    let graph = json!({ "mesoflow": 1, "nodes": {
        "mesh": { "kind": "mesh.primitive",
                  "params": { "shape": scene.shape, "size": scene.size, "minor": scene.minor, "segments": [96, 48] } },
        "ply": { "kind": "mesh.write", "inputs": { "mesh": "mesh.mesh" }, "params": { "path": "mesh.ply" } } } });
    let file = dir.join("mesh.json");
    std::fs::write(&file, graph.to_string()).map_err(|e| e.to_string())?;
    let out = dir.join("out");
    mesoflow_testkit::cli::mesoflow(&[
        "run",
        &file.display().to_string(),
        "--quiet",
        "--out-dir",
        &out.display().to_string(),
    ]);
    // The preset's coefficients (mm⁻¹, g = 0 as the family's materials) in world units.
    let preset: Preset =
        serde_json::from_value(Value::from(scene.preset)).map_err(|e| e.to_string())?;
    let (sigma_s, sigma_a) = preset.coefficients();
    let sigma_t: Vec<f64> = (0..3)
        .map(|c| (sigma_s[c] + sigma_a[c]) * scene.mm_per_unit)
        .collect();
    let albedo: Vec<f64> = (0..3)
        .map(|c| sigma_s[c] * scene.mm_per_unit / sigma_t[c])
        .collect();
    let (eye, direction) = scene.view();
    let cfg = json!({
        "mesh": out.join("mesh.ply"),
        "camera": { "eye": eye, "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": resolution },
        "light": { "direction": direction, "intensity": 5.0 },
        "albedo": [0.0, 0.0, 0.0],
        "samples": LARGER_SAMPLES,
        "medium": { "sigma_t": sigma_t, "albedo": albedo, "g": 0.0, "integrator": "volpathmis" },
    });
    let path = dir.join(format!("scene-{}.json", resolution[0]));
    std::fs::write(&path, cfg.to_string()).map_err(|e| e.to_string())?;
    let run = mesoflow_testkit::cli::output_or_last_error(
        Command::new(&python)
            .arg(mesoflow_testkit::cli::repo().join("benches/sss_peer.py"))
            .arg(&path),
    )?;
    let v: Value = serde_json::from_slice(
        String::from_utf8_lossy(&run.stdout)
            .lines()
            .last()
            .unwrap_or("")
            .as_bytes(),
    )
    .map_err(|e| e.to_string())?;
    match (v["frame_s"].as_f64(), v["noise"].as_f64()) {
        (Some(t), Some(n)) => Ok((t, n)),
        _ => Err(format!("the peer printed {v}")),
    }
}

fn summary(rows: &[Row]) {
    let mut thick: Vec<&Row> = rows.iter().filter(|r| r.paths >= THIN).collect();
    thick.sort_by(|a, b| {
        b.rel
            .unwrap_or(f64::INFINITY)
            .total_cmp(&a.rel.unwrap_or(f64::INFINITY))
    });
    println!(
        "\nthick scenes (at least {THIN} reduced mean free paths): {}",
        thick.len()
    );
    let rel: Vec<f64> = thick.iter().filter_map(|r| r.rel).collect();
    if distribution("relative RMSE", &rel).is_some() {
        let worst_bias =
            thick
                .iter()
                .filter_map(|r| r.bias)
                .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
        println!("largest bias {}", percent(Some(worst_bias)));
        println!("the worst five:");
        for r in thick.iter().take(5) {
            println!(
                "  {}, bias {}: {}",
                f3(r.rel),
                percent(r.bias),
                r.scene.name()
            );
            println!("    {}", r.command);
            println!("    picture: {}", r.picture.display());
        }
    }
    let (faster, slower): (Vec<&Row>, Vec<&Row>) = rows
        .iter()
        .filter(|r| r.equal_error_s().is_some())
        .partition(|r| r.equal_error_s().is_some_and(|t| r.ours_s < t));
    println!(
        "ours faster than the path tracer at ours' error: {} scenes; slower: {} (the path tracer on the same CPU, its time scaled from its noise)",
        faster.len(),
        slower.len()
    );
    let (faster, slower): (Vec<&Row>, Vec<&Row>) = rows
        .iter()
        .filter(|r| r.equal_error_s().is_some())
        .partition(|r| r.equal_error_s().is_some_and(|t| r.view_s < t));
    println!(
        "another view from the cached lighting faster than the path tracer at ours' error: {} scenes; slower: {}",
        faster.len(),
        slower.len()
    );
    let shares: Vec<f64> = rows.iter().map(|r| r.view_s / r.ours_s).collect();
    distribution("a view from the cache over the first frame", &shares);
    let noisiest = rows.iter().filter_map(|r| r.noise).fold(0.0f64, f64::max);
    println!(
        "the truths' largest noise estimate: {noisiest:.3} (a third of the 0.15 bound is 0.05)"
    );
    let thin = rows.len() - thick.len();
    let thin_warned = rows.iter().filter(|r| r.paths < THIN && r.warned).count();
    let thick_warned = thick.iter().filter(|r| r.warned).count();
    println!(
        "thin scenes: {thin}, warned {thin_warned}; thick scenes warned: {thick_warned} of {}",
        thick.len()
    );
}
