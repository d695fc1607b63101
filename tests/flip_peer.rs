//! `image.flip` against NVIDIA's own FLIP (the `flip-evaluator` Python package): photographs from
//! scikit-image and mesoflow renders, LDR and HDR, mean and 95th percentile within 1e-5 (a
//! hundredth of the 1e-3 asked for; see the bound below).
//!
//! The peer runs from a Python with `flip-evaluator`, `scikit-image` and `scipy`:
//! `MESOFLOW_PEER_PYTHON`, else `target/peer-venv/bin/python` (what `.ci/run` makes). Without one
//! the test says so and passes, unless `MESOFLOW_REQUIRE_PEERS=1` (set by CI), where it fails.

use crate::common::{mesoflow, peer_python, read_npy, report, run_peer, Scratch};
use mesoflow_nodes::image::flip::{evaluate, Mode, Params};
use mesoflow_nodes::types::{srgb_to_linear, Image};
use std::path::{Path, PathBuf};

fn read_image(path: &Path) -> Image {
    let (shape, data) = read_npy(path);
    Image {
        width: shape[1],
        height: shape[0],
        channels: shape[2],
        data,
    }
}

/// Renders from a mesoflow graph: a marble torus by brute force with single scattering, the same
/// by a coarse octree without it, and a skin one, written as linear .npy. The graph also runs `image.flip` on the marble pair so the
/// node itself (not only the library function) meets the peer.
const RENDERS: &str = r#"{
  "mesoflow": 1,
  "nodes": {
    "torus": { "kind": "mesh.primitive", "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [48, 24] } },
    "marble_material": { "kind": "sss.material", "params": { "preset": "marble" } },
    "skin_material": { "kind": "sss.material", "params": { "preset": "skin1" } },
    "marble_profile": { "kind": "sss.profile", "inputs": { "material": "marble_material.material" } },
    "skin_profile": { "kind": "sss.profile", "inputs": { "material": "skin_material.material" } },
    "marble": { "kind": "sss.render",
      "inputs": { "mesh": "torus.mesh", "material": "marble_material.material", "profile": "marble_profile.profile" },
      "params": { "camera": { "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "fov": 40.0, "resolution": [96, 72] },
                  "mm_per_unit": 20.0, "threshold": 2.0, "max_points": 4000, "shadow_resolution": 256 } },
    "marble_reference": { "kind": "sss.render",
      "inputs": { "mesh": "torus.mesh", "material": "marble_material.material", "profile": "marble_profile.profile" },
      "params": { "camera": { "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "fov": 40.0, "resolution": [96, 72] },
                  "mm_per_unit": 20.0, "threshold": 0.0, "single_scattering": true, "max_points": 4000, "shadow_resolution": 256 } },
    "skin": { "kind": "sss.render",
      "inputs": { "mesh": "torus.mesh", "material": "skin_material.material", "profile": "skin_profile.profile" },
      "params": { "camera": { "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "fov": 40.0, "resolution": [96, 72] },
                  "mm_per_unit": 20.0, "threshold": 0.3, "max_points": 4000, "shadow_resolution": 256 } },
    "flip": { "kind": "image.flip", "inputs": { "reference": "marble_reference.image", "test": "marble.image" } },
    "reference_npy": { "kind": "npy.write", "inputs": { "value": "marble_reference.image" }, "params": { "path": "marble_reference.npy" } },
    "marble_npy": { "kind": "npy.write", "inputs": { "value": "marble.image" }, "params": { "path": "marble.npy" } },
    "skin_npy": { "kind": "npy.write", "inputs": { "value": "skin.image" }, "params": { "path": "skin.npy" } }
  }
}"#;

#[test]
fn flip_matches_nvidias_implementation() {
    let Some(python) = peer_python("flip_evaluator, skimage, scipy") else {
        return;
    };
    let s = Scratch::new();
    let graph = s.write("renders.json", RENDERS);
    let out = s.path("out");
    let r = mesoflow(
        &[
            "run",
            graph.to_str().unwrap(),
            "--quiet",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let node_mean = report(&out)["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "flip")
        .unwrap()["metrics"]["mean"]
        .as_f64()
        .unwrap();

    let pairs = s.path("pairs");
    let renders: Vec<PathBuf> = ["marble_reference", "marble", "skin"]
        .iter()
        .map(|n| out.join(format!("{n}.npy")))
        .collect();
    let mut args = vec![pairs.as_path()];
    args.extend(renders.iter().map(|r| r.as_path()));
    run_peer(&python, "flip_pairs.py", &args);
    let listing: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(pairs.join("pairs.json")).unwrap()).unwrap();
    let listing = listing.as_array().unwrap();
    // Eight photographs, two HDR ones, and two from each of the three renders plus the two
    // render-to-render pairs: the 18 the guide names.
    assert_eq!(listing.len(), 18, "{} pairs", listing.len());

    // 1e-5, a hundredth of the 1e-3 asked for: both sides follow the same published algorithm and
    // what remains is f32 (theirs) against f64 (ours) arithmetic; measured at most 2e-6.
    let tol = 1e-5;
    let mut report_lines = Vec::new();
    let mut failures = Vec::new();
    for (k, pair) in listing.iter().enumerate() {
        let name = pair["name"].as_str().unwrap();
        let mode = if pair["mode"] == "ldr" {
            Mode::Ldr
        } else {
            Mode::Hdr
        };
        let load = |which: &str| {
            let mut img = read_image(&pairs.join(format!("{k:02}_{which}.npy")));
            if mode == Mode::Ldr {
                // The peer takes LDR images sRGB-encoded; mesoflow images are linear.
                img.data.iter_mut().for_each(|v| *v = srgb_to_linear(*v));
            }
            img
        };
        let (reference, test) = (load("reference"), load("test"));
        let params = Params {
            ppd: Some(pair["ppd"].as_f64().unwrap()),
            viewer: None,
            mode,
            // The peer has no mask: the whole image, exposures from every pixel.
            object_only: false,
        };
        let e = evaluate(&reference, &test, None, &params, |_, _| {}).unwrap();
        let (mean, p95) = (
            pair["mean"].as_f64().unwrap(),
            pair["p95"].as_f64().unwrap(),
        );
        report_lines.push(format!(
            "{name:24} mean {:.6} vs {mean:.6}  p95 {:.6} vs {p95:.6}",
            e.stats.mean, e.stats.p95
        ));
        if (e.stats.mean - mean).abs() > tol || (e.stats.p95 - p95).abs() > tol {
            failures.push(name.to_string());
        }
        // An HDR pair has exposures on both sides (a side without them fails, not passes);
        // an LDR pair on neither.
        let want = pair["exposures"].as_array();
        assert_eq!(
            e.exposures.is_some(),
            pair["mode"] == "hdr",
            "{name}: ours {:?}",
            e.exposures
        );
        assert_eq!(
            want.is_some(),
            pair["mode"] == "hdr",
            "{name}: the peer's {want:?}"
        );
        if let (Some(ex), Some(want)) = (&e.exposures, want) {
            // Exposure range: f32 on their side, so agreement to 1e-4 stops.
            assert!(
                (ex.start - want[0].as_f64().unwrap()).abs() < 1e-4,
                "{name}: start {ex:?} vs {want:?}"
            );
            assert!(
                (ex.stop - want[1].as_f64().unwrap()).abs() < 1e-4,
                "{name}: stop {ex:?} vs {want:?}"
            );
            assert_eq!(ex.count as i64, want[2].as_i64().unwrap(), "{name}");
        }
        if name == "render0_vs_render1" {
            // The same pair through the graph node.
            assert!(
                (node_mean - mean).abs() <= tol,
                "node {node_mean} vs peer {mean}"
            );
        }
    }
    eprintln!("{}", report_lines.join("\n"));
    assert!(
        failures.is_empty(),
        "beyond {tol}: {failures:?}\n{}",
        report_lines.join("\n")
    );
}
