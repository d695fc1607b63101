//! Our brute force beside Mitsuba 3's, in one run, on the very same triangles: the bench torus
//! (`graphs/truth.json`'s: a 64² bumps tile displaced on a torus by `mesh.displace`, written as
//! PLY for Mitsuba) at growing triangle counts, 320 × 240, one directional light, a Lambert
//! surface, direct light only, `--spp` samples a pixel (16).
//!
//! Per size: `render.reference`'s BVH build (a fresh cache, so built, not read back) and its
//! trace (`trace_seconds`, the median of `--repeats` renders on other seeds, the BVH read back
//! from the run's cache as a second frame would), its rays a second; Mitsuba's scene load (the
//! PLY and its BVH) and frame (`benches/mesh_peer.py`, `llvm_ad_rgb`'s `direct`, the median of
//! `--repeats` after the JIT's first frame); the ratio of the two frames. At equal samples the
//! two are at equal error: with one directional light, one shadow ray a hit and no bounce,
//! both estimators' only noise is the pixel's sub-pixel positions. The last row path-traces
//! the 1.1 M surface with 4 bounces after the direct one (Mitsuba's `path` at `max_depth` 6, no
//! Russian roulette, as ours): both sample the light at every vertex and the next direction
//! from the surface (ours by the cosine, Mitsuba's by the BSDF: the same for a Lambert
//! surface), so equal samples are again near equal error.
//!
//! `cargo bench --bench brute_force -- [--spp 16] [--repeats 3] [--largest false]
//! [--out target/brute_force]`: `--largest true` adds 16 M triangles (minutes, 3 GiB),
//! `--only-largest true` measures those alone. Needs
//! the peer venv (`target/peer-venv`, as `.ci/run` makes it) and Debian's `libllvm19`; without
//! them the Mitsuba columns are absent and the bench says why. Writes `OUT/brute_force.json`.

use mesoflow_testkit::args::arg;
use mesoflow_testkit::cli;
use serde_json::{json, Value};
use std::path::Path;

const CAMERA: &str = r#"{ "eye": [0.0, 1.5, 2.7], "target": [0.0, -0.1, 0.0], "fov": 42, "resolution": [320, 240] }"#;
const LIGHT: [f64; 3] = [0.5, 0.6, 0.6];
const ALBEDO: [f64; 3] = [0.7, 0.6, 0.5];

/// The graph: the bumps tile displaced `tiling` times over the torus at `density` vertices a
/// texel, written as PLY, and rendered by `render.reference`.
fn graph(tiling: [u32; 2], density: f64, bounces: u32, spp: u32, seed: u64) -> Value {
    let camera: Value = serde_json::from_str(CAMERA).expect("the camera literal");
    json!({
        "mesoflow": 1,
        "nodes": {
            "surface": { "kind": "heightfield.procedural", "params": { "pattern": "bumps", "size": 64, "count": 8, "width": 0.8, "depth": 6.0 } },
            "torus": { "kind": "mesh.primitive", "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [96, 48] } },
            "true_surface": { "kind": "mesh.displace", "inputs": { "mesh": "torus.mesh", "height": "surface.height" },
                              "params": { "tiling": tiling, "shell": 0.0444, "density": density } },
            "ply": { "kind": "mesh.write", "inputs": { "mesh": "true_surface.mesh" }, "params": { "path": "truth.ply" } },
            "truth": { "kind": "render.reference", "inputs": { "mesh": "true_surface.mesh" },
                       "params": { "camera": camera, "light": { "direction": LIGHT, "intensity": 3.0 },
                                   "brdf": "lambert", "albedo": ALBEDO, "samples": spp, "seed": seed, "bounces": bounces } }
        }
    })
}

/// Runs the graph; the report.
fn run(dir: &Path, g: &Value, cache: &Path) -> Value {
    let path = dir.join("graph.json");
    std::fs::write(&path, g.to_string()).expect("write the graph");
    let out = dir.join("out");
    cli::mesoflow(&[
        "run",
        &path.display().to_string(),
        "--quiet",
        "--out-dir",
        &out.display().to_string(),
        "--cache-dir",
        &cache.display().to_string(),
    ]);
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("a report"))
        .expect("a report's JSON")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Mitsuba's load and frame on the PLY, or why not.
fn mitsuba(dir: &Path, ply: &Path, bounces: u32, spp: u32, repeats: u32) -> Result<Value, String> {
    let camera: Value = serde_json::from_str(CAMERA).expect("the camera literal");
    let mut camera = camera;
    camera["up"] = json!([0.0, 1.0, 0.0]);
    let mut scene = json!({
        "mesh": ply.display().to_string(), "camera": camera,
        "light": { "direction": LIGHT, "intensity": 3.0 }, "albedo": ALBEDO,
        "samples": spp, "repeats": repeats, "variant": "llvm_ad_rgb",
    });
    if bounces > 0 {
        scene["max_depth"] = json!(bounces + 2);
    }
    cli::mesh_peer(dir, &scene)
}

fn main() {
    let spp: u32 = arg("--spp", 16);
    let repeats: u32 = arg("--repeats", 3).max(1);
    let largest: bool = arg("--largest", false);
    let out: std::path::PathBuf = arg("--out", cli::repo().join("target/brute_force"));
    let only_largest: bool = arg("--only-largest", false);
    let mut sizes = vec![([4, 2], 1.0, 0), ([12, 5], 1.0, 0), ([12, 5], 2.0, 0)];
    if largest || only_largest {
        sizes.push(([24, 10], 2.0, 0));
    }
    sizes.push(([12, 5], 1.0, 4));
    if only_largest {
        sizes.retain(|s| s.0 == [24, 10]);
    }
    let mut rows = Vec::new();
    println!("| triangles | bounces | ours' BVH build, s | Mitsuba's load, s | ours' frame, s | Mitsuba's frame, s | ours / Mitsuba | ours' rays a second |");
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (tiling, density, bounces) in sizes {
        let dir = out.join(format!("{}x{}_{density}_{bounces}", tiling[0], tiling[1]));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("the bench's folder");
        let cache = dir.join("cache");
        let mut build = None;
        let (mut traces, mut rates, mut triangles) = (Vec::new(), Vec::new(), 0.0);
        for seed in 0..=repeats as u64 {
            let r = run(
                &dir,
                &graph(tiling, density, bounces, spp, seed + 1),
                &cache,
            );
            let t = &cli::node(&r, "truth")["timings"];
            if seed == 0 {
                build = t["bvh_seconds"].as_f64();
                triangles = cli::node(&r, "true_surface")["bytes"]
                    .as_f64()
                    .unwrap_or(0.0);
                continue;
            }
            traces.push(t["trace_seconds"].as_f64().unwrap_or(f64::NAN));
            rates.push(t["rays_per_second"].as_f64().unwrap_or(f64::NAN));
        }
        let ply = dir.join("out/truth.ply");
        let tris = ply_faces(&ply).unwrap_or(triangles as u64);
        let trace = median(traces);
        let rate = median(rates);
        let peer = mitsuba(&dir, &ply, bounces, spp, repeats);
        let (load, frame) = match &peer {
            Ok(m) => (m["load_s"].as_f64(), m["frame_s"].as_f64()),
            Err(e) => {
                eprintln!("Mitsuba: {e}");
                (None, None)
            }
        };
        let f = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.3}"));
        println!(
            "| {tris} | {bounces} | {} | {} | {trace:.3} | {} | {} | {:.2} M |",
            f(build),
            f(load),
            f(frame),
            frame.map_or("—".into(), |m| format!("{:.2}×", trace / m)),
            rate / 1e6
        );
        rows.push(json!({
            "triangles": tris, "tiling": tiling, "density": density, "bounces": bounces, "spp": spp,
            "bvh_build_s": build, "trace_s": trace, "rays_per_second": rate,
            "mitsuba_load_s": load, "mitsuba_frame_s": frame,
            "mitsuba": peer.as_ref().ok(), "mitsuba_error": peer.as_ref().err(),
        }));
        // The largest sizes' files are gigabytes: keep the numbers, not the triangles.
        let _ = std::fs::remove_dir_all(dir.join("cache"));
        let _ = std::fs::remove_file(&ply);
    }
    std::fs::write(
        out.join("brute_force.json"),
        serde_json::to_string_pretty(&json!({ "rows": rows })).expect("rows"),
    )
    .expect("write brute_force.json");
    println!("wrote {}", out.join("brute_force.json").display());
}

/// The face count in a binary PLY's header.
fn ply_faces(path: &Path) -> Option<u64> {
    use std::io::Read;
    let mut head = vec![0u8; 4096];
    let n = std::fs::File::open(path).ok()?.read(&mut head).ok()?;
    let text = String::from_utf8_lossy(&head[..n]);
    text.lines()
        .find_map(|l| l.strip_prefix("element face "))
        .and_then(|v| v.trim().parse().ok())
}
