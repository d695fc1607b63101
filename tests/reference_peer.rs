//! `render.reference` (the ground truth) against Mitsuba 3 (the `mitsuba` Python package,
//! `scalar_rgb`), run side by side on the same true mesostructure: a torus displaced by a bumps
//! tile with `mesh.displace`, written as PLY by `mesh.write` and read by both; the same camera,
//! directional light and Lambertian albedo, direct light only, a box filter. The bounds:
//! relative RMSE within 3% and the same coverage.
//!
//! The peer runs from a Python with `mitsuba` and `numpy` (see `common::peer_python`; `.ci/run`
//! installs it).

mod common;

use common::{mesoflow, peer_python, read_npy, report, Scratch};
use serde_json::json;
use std::path::Path;
use std::process::Command;

const SAMPLES: u32 = 1024;

fn graph(camera: &serde_json::Value, light: &serde_json::Value) -> String {
    json!({
        "mesoflow": 1,
        "nodes": {
            "surface": { "kind": "heightfield.procedural", "params": { "pattern": "bumps", "size": 32, "count": 4, "depth": 5.0 } },
            "torus": { "kind": "mesh.primitive", "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [48, 24] } },
            "truth": { "kind": "mesh.displace", "inputs": { "mesh": "torus.mesh", "height": "surface.height" },
                       "params": { "tiling": [6, 3], "shell": 0.06 } },
            "ply": { "kind": "mesh.write", "inputs": { "mesh": "truth.mesh" }, "params": { "path": "truth.ply" } },
            "render": { "kind": "render.reference", "inputs": { "mesh": "truth.mesh" },
                        "params": { "camera": camera, "light": light, "albedo": [0.7, 0.5, 0.3], "samples": SAMPLES } },
            "image_npy": { "kind": "npy.write", "inputs": { "value": "render.image" }, "params": { "path": "ours.npy" } },
            "coverage_npy": { "kind": "npy.write", "inputs": { "value": "render.coverage" }, "params": { "path": "coverage.npy" } }
        }
    })
    .to_string()
}

#[test]
fn the_reference_renderer_agrees_with_mitsuba() {
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    let s = Scratch::new();
    let camera = json!({ "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [96, 72] });
    // Low and to the side, so that bumps shadow bumps and the ring shadows itself.
    let light = json!({ "direction": [-0.7, 0.45, 0.35], "intensity": 3.0 });
    let file = s.write("truth.json", &graph(&camera, &light));
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
    let n = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "truth")
        .unwrap();
    assert!(n["status"] == "computed", "{n}");

    let scene = s.write(
        "mitsuba.json",
        &json!({ "mesh": out.join("truth.ply"), "camera": camera, "light": light,
                 "albedo": [0.7, 0.5, 0.3], "samples": SAMPLES })
        .to_string(),
    );
    let theirs_path = s.path("mitsuba.npy");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/mitsuba_reference.py");
    let py = Command::new(&python)
        .arg(&script)
        .arg(&scene)
        .arg(&theirs_path)
        .output()
        .unwrap();
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let (shape, ours) = read_npy(&out.join("ours.npy"));
    let (_, coverage) = read_npy(&out.join("coverage.npy"));
    let (their_shape, theirs) = read_npy(&theirs_path);
    assert_eq!(shape, [72, 96, 3]);
    assert_eq!(their_shape, [72, 96, 4]);

    let pixels = 96 * 72;
    let (mut diff2, mut ref2, mut cov_diff) = (0.0, 0.0, 0.0);
    let (mut ours_cov, mut their_cov) = (0.0, 0.0);
    for i in 0..pixels {
        for k in 0..3 {
            let (a, b) = (ours[i * 3 + k] as f64, theirs[i * 4 + k] as f64);
            diff2 += (a - b) * (a - b);
            ref2 += b * b;
        }
        let (ca, cb) = (coverage[i] as f64, theirs[i * 4 + 3] as f64);
        cov_diff += (ca - cb).abs();
        ours_cov += ca;
        their_cov += cb;
    }
    let rel_rmse = (diff2 / ref2).sqrt();
    let (ours_cov, their_cov) = (ours_cov / pixels as f64, their_cov / pixels as f64);
    eprintln!(
        "relative RMSE {rel_rmse:.4}; coverage {ours_cov:.4} (ours) vs {their_cov:.4} (Mitsuba), mean |difference| per pixel {:.4}",
        cov_diff / pixels as f64
    );
    // Both sides trace the same triangles exactly, so what remains is the two renderers' own
    // sampling noise (edges and shadow boundaries): measured 0.0295, 0.0149 and 0.0074 at 64,
    // 256 and 1024 samples a pixel, halving with four times the samples, so no bias shows above
    // it. The bound is twice the measured (the issue asks for 3%).
    assert!(rel_rmse < 0.015, "relative RMSE {rel_rmse} against Mitsuba");
    // The same coverage: the object's share of the image within 0.5% of it, and per pixel on
    // average within 1% (measured 0.0004).
    assert!(
        (ours_cov - their_cov).abs() < 0.005 * their_cov,
        "{ours_cov} vs {their_cov}"
    );
    assert!(cov_diff / (pixels as f64) < 0.01);
}
