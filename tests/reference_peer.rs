//! `render.reference` (the ground truth) against Mitsuba 3 (the `mitsuba` Python package,
//! `scalar_rgb`), run side by side on the same true mesostructure: a torus displaced by a bumps
//! tile with `mesh.displace`, written as PLY by `mesh.write` and read by both; the same camera,
//! directional light and Lambertian albedo, direct light only, a box filter. The issue's bounds:
//! relative RMSE within 3% and the same coverage.
//!
//! The peer runs from a Python with `mitsuba` and `numpy` (see `common::peer_python`; `.ci/run`
//! installs it).

use crate::common::{compare_to_peer, peer_python, read_npy, run_beside, run_peer, Scratch};
use serde_json::json;

const SAMPLES: u32 = 1024;

fn graph(camera: &serde_json::Value, light: &serde_json::Value) -> String {
    graph_with(camera, light, 0, SAMPLES)
}

/// The torus graph, its truth rendered with `bounces` at `samples` a pixel.
fn graph_with(
    camera: &serde_json::Value,
    light: &serde_json::Value,
    bounces: u32,
    samples: u32,
) -> String {
    json!({
        "mesoflow": 1,
        "nodes": {
            "surface": { "kind": "heightfield.procedural", "params": { "pattern": "bumps", "size": 32, "count": 4, "depth": 5.0 } },
            "torus": { "kind": "mesh.primitive", "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [48, 24] } },
            "truth": { "kind": "mesh.displace", "inputs": { "mesh": "torus.mesh", "height": "surface.height" },
                       "params": { "tiling": [6, 3], "shell": 0.06 } },
            "ply": { "kind": "mesh.write", "inputs": { "mesh": "truth.mesh" }, "params": { "path": "truth.ply" } },
            "render": { "kind": "render.reference", "inputs": { "mesh": "truth.mesh" },
                        "params": { "camera": camera, "light": light, "albedo": [0.7, 0.5, 0.3], "samples": samples, "bounces": bounces } },
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
    let (out, rep) = run_beside(&s, &file);
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
    run_peer(&python, "mitsuba_reference.py", &[&scene, &theirs_path]);
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

/// Interreflections: the same torus, its bumps lighting each other, path-traced with three
/// bounces after the direct one by `render.reference` and by Mitsuba 3's `path` integrator at
/// `max_depth` 5 (Mitsuba counts the camera segment and the direct bounce), no Russian roulette.
/// Both are unbiased estimates of the same image, so their difference must be their noise: ours
/// from the report's two-halves estimate, Mitsuba's from two seeds. The bounces must matter:
/// they add at least 4% to the image (measured 6.4%: the bumps are 5 texels deep on a tile of
/// 32). Measured: relative RMSE 0.0181 against a combined noise of 0.0212, channel sums within
/// 0.05%; 5 s here.
#[test]
fn the_reference_s_bounces_agree_with_mitsuba_s_path_tracer() {
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    let s = Scratch::new();
    let camera = json!({ "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [96, 72] });
    let light = json!({ "direction": [-0.7, 0.45, 0.35], "intensity": 3.0 });
    let samples = 256;
    let mut images = Vec::new();
    for bounces in [0, 3] {
        let file = s.write(
            &format!("truth{bounces}.json"),
            &graph_with(&camera, &light, bounces, samples),
        );
        let (out, rep) = run_beside(&s, &file);
        let noise = mesoflow_testkit::cli::node(&rep, "render")["metrics"]["noise"]
            .as_f64()
            .expect("the render's noise estimate");
        // Both runs write into one folder: read each image before the next run.
        images.push((out.clone(), read_npy(&out.join("ours.npy")).1, noise));
    }
    let (out, ours, ours_noise) = &images[1];
    let mut theirs = Vec::new();
    for seed in [7, 8] {
        let scene = s.write(
            &format!("mitsuba{seed}.json"),
            &json!({ "mesh": out.join("truth.ply"), "camera": camera, "light": light,
                     "albedo": [0.7, 0.5, 0.3], "samples": samples, "seed": seed, "max_depth": 5 })
            .to_string(),
        );
        let npy = s.path(&format!("mitsuba{seed}.npy"));
        run_peer(&python, "mitsuba_reference.py", &[&scene, &npy]);
        theirs.push(read_npy(&npy).1);
    }
    let direct = &images[0].1;
    let (rel, their_noise, ratio) = compare_to_peer(ours, [&theirs[0], &theirs[1]]);
    let gain =
        ours.iter().map(|&v| v as f64).sum::<f64>() / direct.iter().map(|&v| v as f64).sum::<f64>();
    let combined = (ours_noise * ours_noise + their_noise * their_noise).sqrt();
    eprintln!(
        "relative RMSE {rel:.4} against a combined noise of {combined:.4} (ours {ours_noise:.4}, Mitsuba {their_noise:.4}); channel sums {ratio:?}; the bounces add {:.1}%",
        (gain - 1.0) * 100.0
    );
    assert!(gain > 1.04, "the bounces add only {gain}");
    // The difference is noise: within 1.25× the combined estimate (the estimates are themselves
    // noisy at this size), and no channel's sum off by more than 2%.
    assert!(rel < 1.25 * combined, "{rel} against noise {combined}");
    assert!(ratio.iter().all(|r| (r - 1.0).abs() < 0.02), "{ratio:?}");
}

/// An environment: the same torus under the procedural studio turned 40° about +z, path traced
/// with two bounces by `render.reference` (the studio sampled in proportion to its radiance) and
/// by Mitsuba 3's `path` integrator (`max_depth` 4) with the `envmap` `export.mitsuba` writes
/// (its EXR, turned onto Mitsuba's axes). The two windows light the torus from two sides, so a
/// lat-long image turned or mirrored the wrong way shows; the difference must be the two
/// renders' noise (within 1.25× the combined estimate) and no channel's sum off by 2%.
#[test]
fn the_reference_under_an_environment_agrees_with_mitsuba() {
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    let s = Scratch::new();
    let camera = json!({ "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [96, 72] });
    let light = json!({ "studio": {}, "intensity": 3.0, "rotation": 40.0 });
    let samples = 256;
    let mut graph: serde_json::Value =
        serde_json::from_str(&graph_with(&camera, &light, 2, samples)).unwrap();
    graph["nodes"]["export"] = json!({
        "kind": "export.mitsuba", "inputs": { "mesh": "truth.mesh" },
        "params": { "path": "mitsuba/scene.xml", "camera": camera, "light": light,
                    "albedo": [0.7, 0.5, 0.3], "bounces": 2 }
    });
    let file = s.write("environment.json", &graph.to_string());
    let (out, rep) = run_beside(&s, &file);
    let ours_noise = mesoflow_testkit::cli::node(&rep, "render")["metrics"]["noise"]
        .as_f64()
        .expect("the render's noise estimate");
    let ours = read_npy(&out.join("ours.npy")).1;
    let mut theirs = Vec::new();
    for seed in [7, 8] {
        let scene = s.write(
            &format!("mitsuba{seed}.json"),
            &json!({ "mesh": out.join("truth.ply"), "camera": camera,
                     "light": { "envmap": out.join("mitsuba/scene_environment.exr"), "rotation": 40.0 },
                     "albedo": [0.7, 0.5, 0.3], "samples": samples, "seed": seed, "max_depth": 4 })
            .to_string(),
        );
        let npy = s.path(&format!("mitsuba{seed}.npy"));
        run_peer(&python, "mitsuba_reference.py", &[&scene, &npy]);
        theirs.push(read_npy(&npy).1);
    }
    let (rel, their_noise, ratio) = compare_to_peer(&ours, [&theirs[0], &theirs[1]]);
    let combined = (ours_noise * ours_noise + their_noise * their_noise).sqrt();
    eprintln!(
        "relative RMSE {rel:.4} against a combined noise of {combined:.4} (ours {ours_noise:.4}, Mitsuba {their_noise:.4}); channel sums {ratio:?}"
    );
    assert!(rel < 1.25 * combined, "{rel} against noise {combined}");
    assert!(ratio.iter().all(|r| (r - 1.0).abs() < 0.02), "{ratio:?}");
}

/// A translucent torus (20 mm per unit, the acceptance scene of `graphs/sss_render.json` at a
/// small size) rendered by `render.reference` with a medium and by Mitsuba 3's `volpathmis`
/// (spectral MIS; its `volpath` draws one channel's density only and is several times noisier
/// in colour) without Russian roulette (see the script), index-matched boundary, HG phase (g = 0
/// and 0.5). Both are unbiased Monte Carlo estimates of the same image, so their difference must
/// be their noise: ours from the report's two-halves estimate, Mitsuba's from two seeds.
/// Measured: relative RMSE 0.051 against a combined noise of 0.052 (marble), 0.044 against 0.046
/// (skin1); channel sums within 1.4%.
#[test]
#[ignore = "slow: two materials at 1024 samples a pixel and Mitsuba at 2 × 2048, 145 s here"]
fn the_volumetric_reference_agrees_with_mitsuba() {
    volumes_against_mitsuba(
        &[
            ("marble", 0.0, [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
            ("skin1", 0.5, [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
        ],
        TORUS,
        None,
        1024,
        &sun(),
    );
}

/// The index-matched torus under the procedural sky: every next-event sample drawn by the
/// sky's radiance against Mitsuba's `volpathmis` with the `envmap` `export.mitsuba` writes
/// (which also meets the sky by the phase function's samples, weighted by MIS), the sky hidden
/// from both cameras. skin1 only (marble's paths double the time); the same bounds as under
/// one light. Measured: relative RMSE 0.054 against a combined noise of 0.054; channel sums
/// within 0.3%.
#[test]
#[ignore = "slow: skin1 at 1024 samples a pixel under the sky and Mitsuba at 2 × 2048, 101 s here"]
fn the_volumetric_reference_under_the_sky_agrees_with_mitsuba() {
    volumes_against_mitsuba(
        &[("skin1", 0.5, [0.74, 0.88, 1.01], [0.032, 0.17, 0.48])],
        TORUS,
        None,
        1024,
        &json!({ "sky": {}, "intensity": 2.0 }),
    );
}

/// The directional light of the volumetric comparisons.
fn sun() -> serde_json::Value {
    json!({ "direction": [0.5, 0.5, -1.0], "intensity": 5.0 })
}

/// The same on the sphere 28 mm across that the translucency guide renders back-lit
/// (most of what the camera sees is lit only through the material), isotropic as the truth
/// graph's materials are: the far side's light, which no diffusion render gets right there, is
/// the peer's too. Measured: relative RMSE 0.047 against a combined noise of 0.047 (marble),
/// 0.041 against 0.038 (skin1); channel sums within 0.9% (marble) and 0.9–1.7% above Mitsuba's
/// (skin1, as much inside the disc as on its silhouette; under the 2% the test allows, and
/// under half the combined noise of a pixel). The default tier holds the same comparison at a
/// small size through `export.mitsuba` (`tests/export.rs`: skin1 on this sphere, lit from behind,
/// 256 samples a pixel).
#[test]
#[ignore = "slow: two materials at 1024 samples a pixel and Mitsuba at 2 × 2048, 77 s here"]
fn the_volumetric_reference_agrees_with_mitsuba_on_a_back_lit_sphere() {
    volumes_against_mitsuba(
        &[
            ("marble", 0.0, [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
            ("skin1", 0.0, [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
        ],
        SPHERE,
        None,
        1024,
        &sun(),
    );
}

/// `mesh.primitive` parameters: `graphs/sss_render.json`'s torus, and the translucency guide's sphere.
const TORUS: &str = r#"{ "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [64, 32] }"#;
const SPHERE: &str = r#"{ "shape": "sphere", "size": 0.7, "segments": [96, 48] }"#;

/// The same at η = 1.3 behind a rough dielectric boundary (GGX, α = 0.3: Mitsuba's
/// `roughdielectric`), skin1 only (marble's long paths would double the test's time): the
/// refraction, the Fresnel split, the glossy reflection and next-event estimation through the
/// boundary's BTDF, against Mitsuba's own, both on the triangles' own normals. Ours takes 8192
/// samples a pixel (3.5 s per 1024 here; Mitsuba about 30 s per 2048): through the boundary
/// its paths are heavy-tailed, at 1024 the channel sums of three seeds spread ±1.5% around a
/// Mitsuba render of 8192. Measured: relative RMSE 0.105 against a combined noise of 0.107;
/// channel sums within 0.7%.
#[test]
#[ignore = "slow: 8192 samples a pixel through a rough boundary and Mitsuba at 2 × 2048, 124 s here"]
fn the_rough_dielectric_reference_agrees_with_mitsuba() {
    volumes_against_mitsuba(
        &[("skin1", 0.5, [0.74, 0.88, 1.01], [0.032, 0.17, 0.48])],
        TORUS,
        Some((1.3, 0.3)),
        8192,
        &sun(),
    );
}

/// Jensen et al. 2001's coefficients (mm⁻¹), typed in each case rather than read from
/// sss.material: (preset, g, σs′, σa).
type Case = (&'static str, f64, [f64; 3], [f64; 3]);

/// Renders each case on the primitive `shape` with both renderers and holds their difference to
/// their noise; the boundary is index-matched, or `(η, GGX α)`; under `light` (an environment
/// reaches Mitsuba as the EXR `export.mitsuba` writes).
fn volumes_against_mitsuba(
    cases: &[Case],
    shape: &str,
    boundary: Option<(f64, f64)>,
    samples: u32,
    light: &serde_json::Value,
) {
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    let s = Scratch::new();
    let camera = json!({ "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [48, 36] });
    let environment = light.get("sky").is_some();
    let (eta, roughness) = match boundary {
        Some((eta, alpha)) => (eta, Some(alpha)),
        None => (1.0, None),
    };
    let mut nodes = serde_json::Map::new();
    let shape: serde_json::Value = serde_json::from_str(shape).unwrap();
    nodes.insert(
        "shape".into(),
        json!({ "kind": "mesh.primitive", "params": shape }),
    );
    nodes.insert("ply".into(), json!({ "kind": "mesh.write", "inputs": { "mesh": "shape.mesh" }, "params": { "path": "shape.ply" } }));
    for (name, g, ..) in cases {
        nodes.insert(
            format!("{name}_material"),
            json!({ "kind": "sss.material", "params": { "preset": name, "eta": eta, "g": g } }),
        );
        let mut params =
            json!({ "camera": camera, "light": light, "mm_per_unit": 20.0, "samples": samples });
        if let Some(alpha) = roughness {
            params["boundary_roughness"] = json!(alpha);
        }
        nodes.insert(
            name.to_string(),
            json!({ "kind": "render.reference",
            "inputs": { "mesh": "shape.mesh", "medium": format!("{name}_material.material") },
            "params": params }),
        );
        if environment {
            nodes.insert(
                "export".into(),
                json!({ "kind": "export.mitsuba",
                "inputs": { "mesh": "shape.mesh", "medium": format!("{name}_material.material") },
                "params": { "path": "mitsuba/scene.xml", "camera": camera, "light": light, "mm_per_unit": 20.0 } }),
            );
        }
        nodes.insert(format!("{name}_npy"), json!({ "kind": "npy.write", "inputs": { "value": format!("{name}.image") }, "params": { "path": format!("{name}.npy") } }));
    }
    let file = s.write(
        "volume.json",
        &json!({ "mesoflow": 1, "nodes": nodes }).to_string(),
    );
    let (out, rep) = run_beside(&s, &file);
    for &(name, g, sigma_s_prime, sigma_a) in cases {
        let node = rep["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["id"] == name)
            .unwrap();
        let our_noise = node["metrics"]["noise"].as_f64().unwrap();
        assert_eq!(node["metrics"]["lost"].as_f64(), Some(0.0), "{node}");
        // World units: 20 mm per unit.
        let sigma_s = sigma_s_prime.map(|s| s / (1.0 - g) * 20.0);
        let sigma_t: Vec<f64> = (0..3).map(|c| sigma_s[c] + sigma_a[c] * 20.0).collect();
        let albedo: Vec<f64> = (0..3).map(|c| sigma_s[c] / sigma_t[c]).collect();
        let mut medium =
            json!({ "sigma_t": sigma_t, "albedo": albedo, "g": g, "integrator": "volpathmis" });
        if let Some((eta, alpha)) = boundary {
            medium["eta"] = json!(eta);
            medium["alpha"] = json!(alpha);
        }
        let theirs: Vec<Vec<f32>> = [7, 8]
            .iter()
            .map(|seed| {
                let peer_light = if environment {
                    json!({ "envmap": out.join("mitsuba/scene_environment.exr"), "rotation": 0.0 })
                } else {
                    light.clone()
                };
                let scene = s.write(
                    &format!("{name}_{seed}.json"),
                    &json!({ "mesh": out.join("shape.ply"), "camera": camera, "light": peer_light,
                             "albedo": [0.0, 0.0, 0.0], "samples": 2048, "seed": seed,
                             "medium": medium })
                    .to_string(),
                );
                let npy = s.path(&format!("{name}_{seed}.npy"));
                run_peer(&python, "mitsuba_reference.py", &[&scene, &npy]);
                let (shape, v) = read_npy(&npy);
                assert_eq!(shape, [36, 48, 4]);
                v
            })
            .collect();
        let (shape, ours) = read_npy(&out.join(format!("{name}.npy")));
        assert_eq!(shape, [36, 48, 3]);
        let (rel, their_noise, ratio) = compare_to_peer(&ours, [&theirs[0], &theirs[1]]);
        let expected = (our_noise * our_noise + their_noise * their_noise).sqrt();
        eprintln!(
            "{name}: relative RMSE {rel:.4} against Mitsuba; noise {our_noise:.4} (ours) and {their_noise:.4} (Mitsuba), together {expected:.4}; sums ours/theirs {ratio:.4?}"
        );
        // Within the noise: independent estimates differ by √(n₁² + n₂²) in expectation; 1.3
        // of it allows the estimates' own error (over 5000 values each, a few per cent).
        assert!(
            rel < 1.3 * expected,
            "{name}: {rel} against noise {expected}"
        );
        // No bias in the mean per channel beyond 2% (measured at most 1.4% on the torus, 1.7%
        // on the sphere).
        for r in &ratio {
            assert!((r - 1.0).abs() < 0.02, "{name}: {ratio:?}");
        }
    }
}
