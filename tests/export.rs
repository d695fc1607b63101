//! `export.mitsuba` and `export.pbrt` (issue 44): each exported scene is the one
//! `render.reference` renders from the same parameters. Mitsuba 3 (the peers' `mitsuba`,
//! `scalar_rgb`) opens each exported XML file as a user would (`mi.load_file`) and renders it
//! beside the reference: where the mapping is exact (Lambert, a texture, both cameras, both
//! lights, a medium) the two agree within their noise; where Mitsuba's closest BSDF differs
//! (Ward as a Beckmann microfacet lobe, GGX with exact Fresnel and separable masking) the
//! difference is measured and held. pbrt-v4 is not installable here (no package, no wheel): its
//! files are checked against pbrt-v4's scene-file grammar and plugin parameters by
//! `mesoflow_testkit::pbrt`, and their numbers against the scene's.

use crate::common::{
    compare_to_peer, mesoflow, peer_python, read_npy, run_beside, run_peer, Scratch,
};
use mesoflow_testkit::pbrt;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

const W: u32 = 64;
const H: u32 = 48;
const SAMPLES: u32 = 256;

fn camera() -> Value {
    json!({ "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [W, H] })
}

/// The surface cases: (name, render.reference's parameters, whether the albedo map is
/// connected).
fn surface_cases() -> Vec<(&'static str, Value, bool)> {
    let sun = json!({ "direction": [-0.7, 0.45, 0.35], "intensity": 3.0 });
    let lamp =
        json!({ "direction": [0.0, 1.0, 0.0], "position": [1.2, 1.5, 1.4], "intensity": 8.0 });
    let mut ortho = camera();
    ortho["orthographic"] = json!(1.2);
    vec![
        (
            "lambert_map",
            json!({ "camera": camera(), "light": sun, "tiling": [6, 3], "samples": SAMPLES }),
            true,
        ),
        (
            "lambert_ortho_point",
            json!({ "camera": ortho, "light": lamp, "albedo": [0.6, 0.5, 0.4], "samples": SAMPLES }),
            false,
        ),
        (
            "ward",
            json!({ "camera": camera(), "light": sun, "brdf": "ward", "albedo": [0.5, 0.4, 0.3],
                    "specular": 0.2, "roughness": 0.25, "samples": SAMPLES }),
            false,
        ),
        (
            "ggx",
            json!({ "camera": camera(), "light": lamp, "brdf": "ggx", "albedo": [0.5, 0.4, 0.3],
                    "specular": 0.5, "roughness": 0.3, "samples": SAMPLES }),
            false,
        ),
    ]
}

/// A displaced torus (the truth's mesostructure at a small size), an albedo map (a ramp at 60°
/// between two colours: flipped in u or v it would not match), and per case the reference
/// render, its image as NPY and both exports.
fn surface_graph() -> Value {
    let mut nodes = serde_json::Map::new();
    let fixed = json!({
        "surface": { "kind": "heightfield.procedural", "params": { "pattern": "bumps", "size": 32, "count": 4, "depth": 5.0 } },
        "torus": { "kind": "mesh.primitive", "params": { "shape": "torus", "size": 0.9, "minor": 0.38, "segments": [48, 24] } },
        "truth": { "kind": "mesh.displace", "inputs": { "mesh": "torus.mesh", "height": "surface.height" },
                   "params": { "tiling": [6, 3], "shell": 0.06 } },
        "ramp": { "kind": "image.ramp", "params": { "width": 64, "height": 64, "angle": 60.0 } },
        "albedo": { "kind": "image.colorize", "inputs": { "image": "ramp.image" },
                    "params": { "low": [0.7, 0.25, 0.1], "high": [0.1, 0.35, 0.7] } }
    });
    nodes.extend(fixed.as_object().unwrap().clone());
    for (name, params, mapped) in surface_cases() {
        let mut inputs = json!({ "mesh": "truth.mesh" });
        if mapped {
            inputs["albedo"] = json!("albedo.image");
        }
        nodes.insert(
            name.into(),
            json!({ "kind": "render.reference", "inputs": inputs, "params": params }),
        );
        nodes.insert(format!("{name}_npy"), json!({ "kind": "npy.write", "inputs": { "value": format!("{name}.image") }, "params": { "path": format!("{name}.npy") } }));
        for (kind, file) in [
            ("export.mitsuba", "scene.xml"),
            ("export.pbrt", "scene.pbrt"),
        ] {
            let mut p = params.clone();
            p["path"] = json!(format!("{name}/{file}"));
            nodes.insert(
                format!("{name}_{}", &kind[7..]),
                json!({ "kind": kind, "inputs": inputs, "params": p }),
            );
        }
    }
    json!({ "mesoflow": 1, "nodes": nodes })
}

/// The medium cases on the translucency guide's sphere, 20 mm per unit: (name, sss.material's
/// parameters, render.reference's extra parameters).
fn medium_cases() -> Vec<(&'static str, Value, Value)> {
    vec![
        (
            "skin",
            json!({ "preset": "skin1", "eta": 1.0, "g": 0.0 }),
            json!({}),
        ),
        (
            "skin_rough",
            json!({ "preset": "skin1", "eta": 1.3, "g": 0.5 }),
            json!({ "boundary_roughness": 0.3 }),
        ),
    ]
}

/// The media graph; the rough boundary's render at `rough_samples` a pixel.
fn medium_graph(rough_samples: u32) -> Value {
    let mut nodes = serde_json::Map::new();
    nodes.insert("sphere".into(), json!({ "kind": "mesh.primitive", "params": { "shape": "sphere", "size": 0.7, "segments": [64, 32] } }));
    let camera = json!({ "eye": [0.0, 1.6, 2.9], "target": [0.0, -0.1, 0.0], "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [48, 36] });
    for (name, material, extra) in medium_cases() {
        nodes.insert(
            format!("{name}_material"),
            json!({ "kind": "sss.material", "params": material }),
        );
        let samples = if name == "skin_rough" {
            rough_samples
        } else {
            SAMPLES
        };
        let mut params = json!({ "camera": camera, "light": { "direction": [0.5, 0.5, -1.0], "intensity": 5.0 },
                                 "mm_per_unit": 20.0, "samples": samples });
        for (k, v) in extra.as_object().unwrap() {
            params[k] = v.clone();
        }
        let inputs =
            json!({ "mesh": "sphere.mesh", "medium": format!("{name}_material.material") });
        nodes.insert(
            name.into(),
            json!({ "kind": "render.reference", "inputs": inputs, "params": params }),
        );
        nodes.insert(format!("{name}_npy"), json!({ "kind": "npy.write", "inputs": { "value": format!("{name}.image") }, "params": { "path": format!("{name}.npy") } }));
        let mut m = params.clone();
        m["path"] = json!(format!("{name}/scene.xml"));
        nodes.insert(
            format!("{name}_mitsuba"),
            json!({ "kind": "export.mitsuba", "inputs": inputs, "params": m }),
        );
        for mode in ["volume", "subsurface"] {
            let mut p = params.clone();
            p["path"] = json!(format!("{name}/{mode}.pbrt"));
            p["translucency"] = json!(mode);
            nodes.insert(
                format!("{name}_pbrt_{mode}"),
                json!({ "kind": "export.pbrt", "inputs": inputs, "params": p }),
            );
        }
    }
    json!({ "mesoflow": 1, "nodes": nodes })
}

fn run(s: &Scratch, name: &str, graph: &Value) -> (PathBuf, Value) {
    run_beside(s, &s.write(name, &graph.to_string()))
}

/// Renders each scene file with Mitsuba at two seeds: per file, the two RGBA images.
fn mitsuba(python: &Path, s: &Scratch, scenes: &[(String, PathBuf, u32)]) -> Vec<[Vec<f32>; 2]> {
    let mut jobs = Vec::new();
    for (name, xml, spp) in scenes {
        for seed in [7, 8] {
            jobs.push(json!({ "scene": xml, "out": s.path(&format!("{name}_{seed}.npy")), "spp": spp, "seed": seed }));
        }
    }
    let list = s.write("jobs.json", &Value::Array(jobs).to_string());
    run_peer(python, "mitsuba_file.py", &[&list]);
    scenes
        .iter()
        .map(|(name, ..)| [7, 8].map(|seed| read_npy(&s.path(&format!("{name}_{seed}.npy"))).1))
        .collect()
}

fn noise(rep: &Value, id: &str) -> f64 {
    rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == id)
        .and_then(|n| n["metrics"]["noise"].as_f64())
        .unwrap_or_else(|| panic!("{id}: no noise estimate"))
}

#[test]
fn mitsuba_renders_the_exported_surfaces_as_the_reference_does() {
    let s = Scratch::new();
    let (out, rep) = run(&s, "surfaces.json", &surface_graph());
    check_pbrt_files(
        &out,
        &surface_cases().iter().map(|c| c.0).collect::<Vec<_>>(),
    );
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    let scenes: Vec<(String, PathBuf, u32)> = surface_cases()
        .iter()
        .map(|(name, ..)| (name.to_string(), out.join(name).join("scene.xml"), SAMPLES))
        .collect();
    let theirs = mitsuba(&python, &s, &scenes);
    let mut table = String::new();
    let mut results = Vec::new();
    for ((name, ..), theirs) in surface_cases().iter().zip(&theirs) {
        let (shape, ours) = read_npy(&out.join(format!("{name}.npy")));
        assert_eq!(shape, [H as usize, W as usize, 3]);
        assert_eq!(theirs[0].len(), (W * H * 4) as usize);
        let (rel, their_noise, ratio) = compare_to_peer(&ours, [&theirs[0], &theirs[1]]);
        let ours_noise = noise(&rep, name);
        let expected = (ours_noise * ours_noise + their_noise * their_noise).sqrt();
        table.push_str(&format!(
            "{name}: relative RMSE {rel:.4} against Mitsuba; noise {ours_noise:.4} (ours), {their_noise:.4} (Mitsuba), together {expected:.4}; sums ours/theirs {ratio:.4?}\n"
        ));
        results.push((*name, rel, expected, ratio));
    }
    eprintln!("{table}");
    for (name, rel, expected, ratio) in results {
        match name {
            // Exact equivalents (and GGX, whose differences, exact Fresnel for Schlick's and
            // separable masking for the height-correlated, are below the noise here: measured
            // 0.0094 against 0.0150): the difference is the two renderers' noise. 1.3 × the
            // combined noise allows the noise estimates' own error, as the reference's peer test.
            "lambert_map" | "lambert_ortho_point" | "ggx" => {
                assert!(
                    rel < 1.3 * expected,
                    "{name}: {rel} against noise {expected}\n{table}"
                );
                for r in ratio {
                    assert!((r - 1.0).abs() < 0.02, "{name}: sums {ratio:?}\n{table}");
                }
            }
            // Ward as Mitsuba's Beckmann microfacet lobe: the same peak, more light at grazing
            // angles (Ward's 1/√(cosθi cosθo) against Beckmann's G/(cos⁴θh cosθi cosθo)).
            // Measured 2026-12-07: relative RMSE 0.0995 against a noise of 0.027, Mitsuba's
            // image 5.3–7.8 % brighter per channel. Held at twice the RMSE and 12 %.
            _ => {
                assert!(rel < 0.2, "{name}: {rel}\n{table}");
                for r in ratio {
                    assert!((0.88..1.0).contains(&r), "{name}: sums {ratio:?}\n{table}");
                }
            }
        }
    }
}

#[test]
fn mitsuba_renders_the_exported_media_as_the_reference_does() {
    let s = Scratch::new();
    let (out, rep) = run(&s, "media.json", &medium_graph(SAMPLES));
    for (name, ..) in medium_cases() {
        for mode in ["volume", "subsurface"] {
            let scene = out.join(name).join(format!("{mode}.pbrt"));
            let checked =
                pbrt::check_file(&scene).unwrap_or_else(|e| panic!("{}: {e}", scene.display()));
            assert_eq!(checked.first("Integrator").unwrap().args[0], "volpath");
        }
    }
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    // The index-matched medium is rendered and compared; the rough boundary (the peer test
    // of the reference's own at 8192 samples is slow) is loaded and rendered at one sample, so
    // the file is one Mitsuba reads.
    let scenes = vec![
        ("skin".to_string(), out.join("skin/scene.xml"), SAMPLES),
        (
            "skin_rough".to_string(),
            out.join("skin_rough/scene.xml"),
            1,
        ),
    ];
    let theirs = mitsuba(&python, &s, &scenes);
    medium_within_noise(&out, &rep, "skin", &theirs[0]);
    assert!(theirs[1][0].iter().all(|v| v.is_finite()));
}

/// A medium's render `id` against Mitsuba's two: within 1.3 × their combined noise (as the
/// surfaces), channel sums within 3 % (a medium's image is noisier per channel).
fn medium_within_noise(out: &Path, rep: &Value, id: &str, theirs: &[Vec<f32>; 2]) {
    let (_, ours) = read_npy(&out.join(format!("{id}.npy")));
    let (rel, their_noise, ratio) = compare_to_peer(&ours, [&theirs[0], &theirs[1]]);
    let ours_noise = noise(rep, id);
    let expected = (ours_noise * ours_noise + their_noise * their_noise).sqrt();
    eprintln!(
        "{id}: relative RMSE {rel:.4} against Mitsuba; noise {ours_noise:.4} (ours), {their_noise:.4} (Mitsuba), together {expected:.4}; sums ours/theirs {ratio:.4?}"
    );
    assert!(rel < 1.3 * expected, "{id}: {rel} against noise {expected}");
    for r in ratio {
        assert!((r - 1.0).abs() < 0.03, "{id}: sums {ratio:?}");
    }
}

/// The rough dielectric boundary's export (η = 1.3, GGX α = 0.3, skin1 with g = 0.5) rendered
/// by Mitsuba and compared as the index-matched one is. Through the boundary both renderers'
/// paths are heavy-tailed (`tests/reference_peer.rs` says how), so this takes thousands of
/// samples a pixel: the slow tier.
#[test]
#[ignore = "slow: a rough boundary at 2048 samples a pixel and Mitsuba at 2 × 1024"]
fn mitsuba_renders_the_exported_rough_boundary_as_the_reference_does() {
    let s = Scratch::new();
    let (out, rep) = run(&s, "media.json", &medium_graph(2048));
    let Some(python) = peer_python("mitsuba, numpy") else {
        return;
    };
    let scenes = vec![(
        "skin_rough".to_string(),
        out.join("skin_rough/scene.xml"),
        1024,
    )];
    let theirs = mitsuba(&python, &s, &scenes);
    medium_within_noise(&out, &rep, "skin_rough", &theirs[0]);
}

/// Every surface case's pbrt file follows the grammar, names files that are there and carries
/// the scene's numbers: the mirror, the camera, the samples.
fn check_pbrt_files(out: &Path, names: &[&str]) {
    for name in names {
        let scene = out.join(name).join("scene.pbrt");
        let c = pbrt::check_file(&scene).unwrap_or_else(|e| panic!("{}: {e}", scene.display()));
        let scale = c.first("Scale").expect("the handedness mirror");
        assert_eq!(scale.args, ["-1", "1", "1"]);
        let cam = c.first("Camera").unwrap();
        if *name == "lambert_ortho_point" {
            assert_eq!(cam.args[0], "orthographic");
            // Half-height 1.2 on a 4:3 image.
            let sw: Vec<f64> = cam
                .param("screenwindow")
                .unwrap()
                .values
                .iter()
                .map(|v| v.parse().unwrap())
                .collect();
            for (a, b) in sw.iter().zip([-1.6, 1.6, -1.2, 1.2]) {
                assert!((a - b).abs() < 1e-12, "{sw:?}");
            }
            assert_eq!(c.first("LightSource").unwrap().args[0], "point");
        } else {
            // Wider than tall: pbrt's fov (the shorter axis's) is the vertical one.
            assert_eq!(cam.number("fov"), Some(40.0));
        }
        assert_eq!(
            c.first("Sampler").unwrap().number("pixelsamples"),
            Some(SAMPLES as f64)
        );
        let film = c.first("Film").unwrap();
        assert_eq!(film.number("xresolution"), Some(W as f64));
        assert!(c.files.iter().any(|f| f.ends_with("scene.ply")));
        if *name == "lambert_map" {
            assert!(c.files.iter().any(|f| f.ends_with("scene_albedo.exr")));
        }
        if *name == "ward" || *name == "ggx" {
            assert!(c
                .statements
                .iter()
                .any(|s| s.param("type").is_some_and(|t| t.values == ["mix"])));
        }
    }
}

/// What cannot be exported is refused with the parameter or port and the numbers: a background
/// (light in the renderers), reflectances whose sum exceeds 1.
#[test]
fn what_a_renderer_cannot_take_is_refused_by_name() {
    let s = Scratch::new();
    let graph = |params: Value| {
        json!({ "mesoflow": 1, "nodes": {
            "m": { "kind": "mesh.primitive", "params": { "shape": "sphere", "size": 0.5, "segments": [8, 4] } },
            "x": { "kind": "export.mitsuba", "inputs": { "mesh": "m.mesh" }, "params": params }
        } })
        .to_string()
    };
    let file = s.write(
        "bg.json",
        &graph(json!({ "path": "a.xml", "background": [0.1, 0.1, 0.1] })),
    );
    let r = mesoflow(&["validate", file.to_str().unwrap()], s.dir.path());
    assert_ne!(r.code, 0);
    assert!(r.stderr.contains("background"), "{}", r.stderr);
    let file = s.write(
        "typo.json",
        &graph(json!({ "path": "a.xml", "sampels": 4 })),
    );
    let r = mesoflow(&["validate", file.to_str().unwrap()], s.dir.path());
    assert_ne!(r.code, 0);
    assert!(r.stderr.contains("sampels"), "{}", r.stderr);
    let file = s.write(
        "sum.json",
        &graph(
            json!({ "path": "a.xml", "brdf": "ward", "albedo": [0.9, 0.5, 0.5], "specular": 0.2 }),
        ),
    );
    let r = mesoflow(&["run", file.to_str().unwrap(), "--quiet"], s.dir.path());
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("albedo") && r.stderr.contains("1.1"),
        "{}",
        r.stderr
    );
}
