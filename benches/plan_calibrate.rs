//! The planner's measured error model. On a calibration scene that is not the verification
//! scene (a sphere with a bumps mesostructure, a marble and a ketchup torus, seen from the side), for camera
//! distances from near to far, renders every candidate model of each stage beside the full
//! model and records its FLIP (over the object's pixels) against what the view shows:
//! - BTF: PCA rank r (YCbCr, chroma r/4) at level λ, against texels per pixel;
//! - MDF left out, against the shell's thickness in pixels, with the fraction of the object's
//!   pixels on a silhouette (the only pixels the MDF changes);
//! - the MDF tabulated 2, 4 and 8 times coarser than its height field, against the full
//!   table's texels per pixel (the same silhouette band);
//! - a synthesized texture (`qh.render`'s entrance function on the marble torus) stopped 1 or 2
//!   pyramid levels before its finest, against the full texture's texels per pixel;
//! - shadow maps at each density the planner chooses among (1, 2 and 4 texels per pixel the
//!   object spans), for both renderers, on the torus under a low light (it shadows itself),
//!   against the object's size in pixels;
//! - subsurface scattering as a BRDF, or gathered (brute force) with samples k pixel
//!   footprints apart (never closer than the profile's default), or gathered as the full model
//!   is with the classical dipole's profile instead of PBD's, or (on the CPU, where the gather
//!   is an octree) at octree thresholds 0.01–0.3, against the longest mean free path in pixels.
//!
//! Each FLIP is measured at 67 pixels per degree (FLIP's default) and at 30 and 120.
//! Each candidate's render time is recorded too: the node's seconds, and for `render.mesh` a
//! frame's milliseconds (what the planner's time curves use where present). Writes `calibration.json` (what
//! `plan/plan_calibration.json` holds) to the output folder.
//!
//! `cargo bench --bench plan_calibrate -- [--out DIR] [--width W]`

use mesoflow_testkit::{args, cli};

use cli::{mesoflow, node};
use mesoflow_nodes::support::raytrace::footprint::{shadow_resolution, SHADOW_TEXELS_PER_PIXEL};
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};

/// From where the sphere still shows its silhouette (nearer, it fills the view and the MDF
/// changes nothing) to where it is a few dozen pixels across.
const DISTANCES: [f64; 10] = [2.2, 3.2, 4.6, 6.8, 10.0, 15.0, 22.0, 32.0, 45.0, 64.0];
const RANKS: [u32; 5] = [2, 4, 8, 16, 32];
const LEVELS: [u32; 6] = [0, 1, 2, 3, 4, 5];
/// Sample spacings of the gathered candidates, in pixel footprints (never finer than the
/// profile's default, a quarter of the shortest effective mean free path).
const SPACINGS: [f64; 4] = [0.5, 1.0, 2.0, 4.0];
/// Viewing conditions besides FLIP's default (67 pixels per degree) at which every candidate's
/// FLIP is measured too: a farther or smaller display, and a nearer or larger one.
const OTHER_PPDS: [u32; 2] = [30, 120];
/// Octree thresholds (ΔA/d²) of the CPU path's gather.
const THRESHOLDS: [f64; 4] = [0.01, 0.03, 0.1, 0.3];
/// How many times coarser than its height field the MDF is tabulated.
const MDF_FACTORS: [u32; 3] = [2, 4, 8];
/// Pyramid levels a synthesis stops before its finest.
const SYNTH_STOPS: [u32; 2] = [1, 2];
/// The synthesized entrance function's size (its exemplar is 64²) and the tiling it is laid
/// with on the torus.
const SYNTH_SIZE: u32 = 256;
const QH_TILING: [f64; 2] = [6.0, 2.0];

fn scene(width: u32, eye: [f64; 3]) -> Map<String, Value> {
    let height = width * 3 / 4;
    let camera =
        json!({ "eye": eye, "target": [0.0, 0.0, 0.0], "fov": 40, "resolution": [width, height] });
    let views =
        json!({ "thetas": [0, 20, 40, 60, 80], "phis": [0, 45, 90, 135, 180, 225, 270, 315] });
    let mut n = Map::new();
    n.insert("surface".into(), json!({ "kind": "heightfield.procedural", "params": { "pattern": "bumps", "size": 64, "count": 4, "depth": 5.0 } }));
    n.insert("capture".into(), json!({ "kind": "btf.capture", "inputs": { "height": "surface.height" },
        "params": { "views": views, "lights": views, "brdf": "ward", "albedo": [0.3, 0.5, 0.7], "specular": 0.12, "roughness": 0.2 } }));
    n.insert("mdf".into(), json!({ "kind": "mdf.tabulate", "inputs": { "height": "surface.height" },
        "params": { "views": { "thetas": [0, 15, 30, 45, 60, 70, 80, 85, 88], "phis": [0, 30, 60, 90, 120, 150, 180, 210, 240, 270, 300, 330] } } }));
    n.insert("ball".into(), json!({ "kind": "mesh.primitive", "params": { "shape": "sphere", "size": 1.0, "segments": [96, 48] } }));
    let render = |btf: &str, mdf: bool| {
        let mut inputs = json!({ "mesh": "ball.mesh", "btf": btf });
        if mdf {
            inputs["mdf"] = json!("mdf.mdf");
        }
        json!({ "kind": "render.mesh", "inputs": inputs, "params": {
            "camera": camera, "light": { "direction": [-0.4, 0.8, 0.6], "intensity": 3.0 },
            "tiling": [8, 4], "shell": 0.06, "mm_per_unit": 25.0, "use_mdf": mdf, "shadows": true, "shadow_resolution": 512 } })
    };
    n.insert("btf_full".into(), render("capture.btf", true));
    n.insert(
        "btf_scene".into(),
        json!({ "kind": "scene.footprint", "inputs": { "mesh": "ball.mesh", "btf": "capture.btf" },
        "params": { "camera": camera, "tiling": [8, 4], "shell": 0.06, "mm_per_unit": 25.0 } }),
    );
    let flip = |a: &str, b: &str| json!({ "kind": "image.flip", "inputs": { "reference": format!("{a}.image"), "test": format!("{b}.image") }, "params": { "object_only": true } });
    for r in RANKS {
        n.insert(
            format!("pca_{r}"),
            json!({ "kind": "btf.pca", "inputs": { "btf": "capture.btf" },
            "params": { "color": "ycbcr", "rank": r, "chroma_rank": (r / 4).max(1) } }),
        );
        for l in LEVELS {
            n.insert(format!("lod_{r}_{l}"), json!({ "kind": "btf.lod", "inputs": { "basis": format!("pca_{r}.basis") }, "params": { "level": l } }));
            n.insert(
                format!("btf_{r}_{l}"),
                render(&format!("lod_{r}_{l}.basis"), true),
            );
            n.insert(
                format!("flip_btf_{r}_{l}"),
                flip("btf_full", &format!("btf_{r}_{l}")),
            );
        }
    }
    n.insert("btf_nomdf".into(), render("capture.btf", false));
    n.insert("flip_nomdf".into(), flip("btf_full", "btf_nomdf"));
    for f in MDF_FACTORS {
        let mut m = n["mdf"].clone();
        m["params"]["resolution"] = json!(64 / f);
        n.insert(format!("mdf_r{f}"), m);
        let mut r = render("capture.btf", true);
        r["inputs"]["mdf"] = json!(format!("mdf_r{f}.mdf"));
        n.insert(format!("btf_mdf{f}"), r);
        n.insert(
            format!("flip_mdf{f}"),
            flip("btf_full", &format!("btf_mdf{f}")),
        );
    }

    n.insert("ring".into(), json!({ "kind": "mesh.primitive", "params": { "shape": "torus", "size": 0.9, "minor": 0.35, "segments": [64, 32] } }));
    // Two media on the torus: marble scatters far (its longest mean free path ~8.5 mm), ketchup
    // near (~4.8 mm, and far less in green and blue), so the views cover scattering from a few
    // pixels to hundreds.
    for (p, preset) in MEDIA {
        n.insert(
            format!("{p}_material"),
            json!({ "kind": "sss.material", "params": { "preset": preset } }),
        );
        n.insert(format!("{p}_profile"), json!({ "kind": "sss.profile", "inputs": { "material": format!("{p}_material.material") }, "params": { "model": "pbd" } }));
        n.insert(format!("{p}_full"), sss_render(p, &camera, json!({})));
        n.insert(format!("{p}_scene"), json!({ "kind": "scene.footprint", "inputs": { "mesh": "ring.mesh", "profile": format!("{p}_profile.profile") },
            "params": { "camera": camera, "mm_per_unit": 20.0 } }));
        n.insert(
            format!("{p}_brdf"),
            sss_render(p, &camera, json!({ "mode": "brdf" })),
        );
        n.insert(
            format!("flip_{p}_brdf"),
            flip(&format!("{p}_full"), &format!("{p}_brdf")),
        );
        // The classical dipole instead of PBD, gathered as the full model is.
        n.insert(format!("{p}_dipole_profile"), json!({ "kind": "sss.profile", "inputs": { "material": format!("{p}_material.material") }, "params": { "model": "dipole" } }));
        let mut dipole = sss_render(p, &camera, json!({}));
        dipole["inputs"]["profile"] = json!(format!("{p}_dipole_profile.profile"));
        n.insert(format!("{p}_dipole"), dipole);
        n.insert(
            format!("flip_{p}_dipole"),
            flip(&format!("{p}_full"), &format!("{p}_dipole")),
        );
    }
    // Shadow maps need a scene that casts shadows (a convex sphere casts none, and the torus
    // lit from above hardly any): the torus under a low light, with the BTF and with marble.
    let low = json!({ "direction": [0.2, 0.35, 0.9], "intensity": 5.0 });
    n.insert("shadow_btf_full".into(), json!({ "kind": "render.mesh", "inputs": { "mesh": "ring.mesh", "btf": "capture.btf", "mdf": "mdf.mdf" }, "params": {
        "camera": camera, "light": low, "tiling": [12, 5], "shell": 0.06, "mm_per_unit": 20.0, "use_mdf": true, "shadows": true, "shadow_resolution": 512 } }));
    n.insert(
        "shadow_sss_full".into(),
        sss_render("sss", &camera, json!({ "light": low })),
    );
    // A synthesized entrance function (from the bumps' normal map, an RGB texture with detail
    // at every scale) on a quasi-homogeneous marble torus, full and stopped early.
    n.insert(
        "normals".into(),
        json!({ "kind": "heightfield.normals", "inputs": { "height": "surface.height" } }),
    );
    let synth = |stop: u32| {
        json!({ "kind": "synthesis.texture", "inputs": { "exemplar": "normals.preview" }, "params": {
        "width": SYNTH_SIZE, "height": SYNTH_SIZE, "levels": 3, "stop_level": stop, "patch_sizes": [16, 8],
        "iterations": 2, "periodic": true, "seed": 3 } })
    };
    let qh = |stop: u32| {
        json!({ "kind": "qh.render", "inputs": { "mesh": "ring.mesh", "lrf": "capture.btf", "material": "sss_material.material",
        "profile": "sss_profile.profile", "entrance": format!("synth_{stop}.image") }, "params": {
        "camera": camera, "light": { "direction": [-0.4, 0.8, 0.6], "intensity": 5.0 }, "tiling": QH_TILING,
        "mm_per_unit": 20.0, "threshold": 0.0, "max_points": 20000, "shadow_resolution": 512 } })
    };
    n.insert("synth_0".into(), synth(0));
    n.insert("qh_0".into(), qh(0));
    n.insert("qh_scene".into(), json!({ "kind": "scene.footprint", "inputs": { "mesh": "ring.mesh", "texture": "synth_0.image" },
        "params": { "camera": camera, "tiling": QH_TILING, "mm_per_unit": 20.0 } }));
    for k in SYNTH_STOPS {
        n.insert(format!("synth_{k}"), synth(k));
        n.insert(format!("qh_{k}"), qh(k));
        n.insert(format!("flip_qh_{k}"), flip("qh_0", &format!("qh_{k}")));
    }
    n
}

/// The translucent calibration media: node-id prefix and preset.
const MEDIA: [(&str, &str); 2] = [("sss", "marble"), ("sss2", "ketchup")];

/// A render of medium `p` on the torus, with `extra` parameters.
fn sss_render(p: &str, camera: &Value, extra: Value) -> Value {
    let mut params = json!({ "camera": camera, "light": { "direction": [-0.4, 0.8, 0.6], "intensity": 5.0 },
        "mm_per_unit": 20.0, "threshold": 0.0, "max_points": 20000, "shadow_resolution": 512 });
    for (k, v) in extra.as_object().into_iter().flatten() {
        params[k] = v.clone();
    }
    json!({ "kind": "sss.render", "inputs": { "mesh": "ring.mesh", "material": format!("{p}_material.material"), "profile": format!("{p}_profile.profile") }, "params": params })
}

fn run(graph: &Map<String, Value>, dir: &Path, cache: &Path) -> Value {
    run_on(graph, dir, cache, "auto")
}

/// [`run`] on `device` (`auto`, `cpu` or `gpu`).
fn run_on(graph: &Map<String, Value>, dir: &Path, cache: &Path, device: &str) -> Value {
    std::fs::create_dir_all(dir).unwrap();
    let file = dir.join("graph.json");
    let doc = json!({ "mesoflow": 1, "nodes": graph });
    std::fs::write(&file, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    let out = dir.join("out");
    mesoflow(&[
        "run",
        file.to_str().unwrap(),
        "--quiet",
        "--device",
        device,
        "--out-dir",
        out.to_str().unwrap(),
        "--cache-dir",
        cache.to_str().unwrap(),
    ]);
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

fn metric(report: &Value, id: &str, m: &str) -> Option<f64> {
    node(report, id)["metrics"][m].as_f64()
}

/// The mean FLIP of `id` at each of [`OTHER_PPDS`], keyed by the ppd.
fn at_ppds(report: &Value, id: &str) -> Value {
    OTHER_PPDS
        .iter()
        .map(|p| {
            (
                p.to_string(),
                json!(metric(report, &format!("{id}_p{p}"), "mean")),
            )
        })
        .collect::<Map<String, Value>>()
        .into()
}

fn seconds(report: &Value, id: &str) -> Option<f64> {
    node(report, id)["timings"]["seconds"].as_f64()
}

/// A frame's time without the node's one-off set-up and read-back, where the renderer measures
/// one (`render.mesh`): what the verification judges render time by.
fn frame_ms(report: &Value, id: &str) -> Option<f64> {
    node(report, id)["timings"]["frame_ms"].as_f64()
}

fn main() {
    let out = PathBuf::from(args::arg("--out", "out/plan_calibrate".to_string()));
    let width: u32 = args::arg("--width", 240);
    let cache = out.join("cache");
    let dir = {
        let d = [1.0f64, 0.35, 0.7];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|v| v / l)
    };
    let mut btf: Vec<Value> = Vec::new();
    let mut mdf: Vec<Value> = Vec::new();
    let mut mdf_resolution: Vec<Value> = Vec::new();
    let mut synthesis: Vec<Value> = Vec::new();
    let mut sss: Vec<Value> = Vec::new();
    let mut shadows: Vec<Value> = Vec::new();
    let mut shadow_sizes: Vec<(&str, &str, String, f64, f64, u32)> = Vec::new();
    for &d in &DISTANCES {
        let eye = dir.map(|v| v * d);
        let mut g = scene(width, eye);
        // Spacings are multiples of the default, a quarter of the shortest mean free path.
        let probe = run(
            &{
                let mut p = g.clone();
                p.retain(|k, _| {
                    k == "ring"
                        || MEDIA.iter().any(|(m, _)| {
                            [
                                format!("{m}_material"),
                                format!("{m}_profile"),
                                format!("{m}_scene"),
                            ]
                            .contains(k)
                        })
                });
                p
            },
            &out.join(format!("d{d}/probe")),
            &cache,
        );
        let footprint = metric(&probe, "sss_scene", "pixel_footprint_mm").unwrap_or(f64::NAN);
        // Shadow maps at each density the planner chooses among (texels per pixel the object
        // spans).
        for (base, full, scene_id) in [
            ("btf_shadow", "shadow_btf_full", "sss_scene"),
            ("sss_shadow", "shadow_sss_full", "sss_scene"),
        ] {
            let px = metric(&probe, scene_id, "object_pixels").unwrap_or(f64::NAN);
            for t in SHADOW_TEXELS_PER_PIXEL {
                let id = format!("{base}_{t}");
                let size = shadow_resolution(px, t, 512);
                let mut v = g[full].clone();
                v["params"]["shadow_resolution"] = json!(size);
                g.insert(id.clone(), v);
                g.insert(
                    format!("flip_{id}"),
                    json!({ "kind": "image.flip", "inputs": { "reference": format!("{full}.image"), "test": format!("{id}.image") }, "params": { "object_only": true } }),
                );
                shadow_sizes.push((base, full, id, px, t, size));
            }
        }
        for (p, _) in MEDIA {
            let default_spacing =
                0.25 * metric(&probe, &format!("{p}_scene"), "mfp_min_mm").unwrap_or(f64::NAN);
            for k in SPACINGS {
                let id = format!("{p}_k{}", (k * 10.0) as u32);
                let spacing = (k * footprint).max(default_spacing);
                let mut v = g[&format!("{p}_full")].clone();
                v["params"]["spacing"] = json!(spacing);
                v["params"]["threshold"] = json!(0.0);
                g.insert(id.clone(), v);
                g.insert(format!("flip_{id}"), json!({ "kind": "image.flip", "inputs": { "reference": format!("{p}_full.image"), "test": format!("{id}.image") }, "params": { "object_only": true } }));
            }
        }
        // Every FLIP again at the other calibrated viewing conditions.
        let flips: Vec<String> = g
            .iter()
            .filter(|(_, v)| v["kind"] == "image.flip")
            .map(|(k, _)| k.clone())
            .collect();
        for k in flips {
            for ppd in OTHER_PPDS {
                let mut v = g[&k].clone();
                v["params"]["ppd"] = json!(ppd);
                g.insert(format!("{k}_p{ppd}"), v);
            }
        }
        let rep = run(&g, &out.join(format!("d{d}")), &cache);
        // The CPU path's octree: the full model gathered by brute force and at each threshold,
        // on the CPU (the GPU path always sums every sample), in a cache of its own.
        let mut cpu = Map::new();
        cpu.insert("ring".into(), g["ring"].clone());
        for (p, _) in MEDIA {
            for k in ["material", "profile", "full"] {
                cpu.insert(format!("{p}_{k}"), g[&format!("{p}_{k}")].clone());
            }
            for t in THRESHOLDS {
                let id = format!("{p}_t{}", (t * 1000.0) as u32);
                let mut v = g[&format!("{p}_full")].clone();
                v["params"]["threshold"] = json!(t);
                cpu.insert(id.clone(), v);
                for (suffix, ppd) in [
                    (String::new(), None),
                    ("_p30".into(), Some(30)),
                    ("_p120".into(), Some(120)),
                ] {
                    let mut f = json!({ "kind": "image.flip", "inputs": { "reference": format!("{p}_full.image"), "test": format!("{id}.image") }, "params": { "object_only": true } });
                    if let Some(ppd) = ppd {
                        f["params"]["ppd"] = json!(ppd);
                    }
                    cpu.insert(format!("flip_{id}{suffix}"), f);
                }
            }
        }
        let cpu_rep = run_on(
            &cpu,
            &out.join(format!("d{d}/cpu")),
            &out.join("cpu_cache"),
            "cpu",
        );
        let tpp = metric(&rep, "btf_scene", "texels_per_pixel");
        let shell = metric(&rep, "btf_scene", "shell_pixels");
        let silhouette = metric(&rep, "btf_scene", "silhouette_fraction");
        let mfp = metric(&rep, "sss_scene", "mfp_pixels");
        let full_s = seconds(&rep, "btf_full");
        for r in RANKS {
            for l in LEVELS {
                btf.push(json!({
                    "distance": d, "texels_per_pixel": tpp, "rank": r, "level": l,
                    "flip": metric(&rep, &format!("flip_btf_{r}_{l}"), "mean"),
                    "flip_at_ppd": at_ppds(&rep, &format!("flip_btf_{r}_{l}")),
                    "seconds": seconds(&rep, &format!("btf_{r}_{l}")), "full_seconds": full_s,
                    "frame_ms": frame_ms(&rep, &format!("btf_{r}_{l}")), "full_frame_ms": frame_ms(&rep, "btf_full"),
                }));
            }
        }
        mdf.push(json!({
            "distance": d, "shell_pixels": shell, "silhouette_fraction": silhouette,
            "flip": metric(&rep, "flip_nomdf", "mean"),
            "flip_at_ppd": at_ppds(&rep, "flip_nomdf"),
            "seconds": seconds(&rep, "btf_nomdf"), "full_seconds": full_s,
            "frame_ms": frame_ms(&rep, "btf_nomdf"), "full_frame_ms": frame_ms(&rep, "btf_full"),
        }));
        for f in MDF_FACTORS {
            mdf_resolution.push(json!({
                "distance": d, "texels_per_pixel": tpp, "factor": f,
                "shell_pixels": shell, "silhouette_fraction": silhouette,
                "flip": metric(&rep, &format!("flip_mdf{f}"), "mean"),
                "flip_at_ppd": at_ppds(&rep, &format!("flip_mdf{f}")),
                "seconds": seconds(&rep, &format!("mdf_r{f}")), "full_seconds": seconds(&rep, "mdf"),
            }));
        }
        let synth_tpp = metric(&rep, "qh_scene", "texture_texels_per_pixel");
        for k in SYNTH_STOPS {
            synthesis.push(json!({
                "distance": d, "texels_per_pixel": synth_tpp, "stop_level": k,
                "flip": metric(&rep, &format!("flip_qh_{k}"), "mean"),
                "flip_at_ppd": at_ppds(&rep, &format!("flip_qh_{k}")),
                "seconds": seconds(&rep, &format!("synth_{k}")), "full_seconds": seconds(&rep, "synth_0"),
            }));
        }
        for (base, full, id, px, t, size) in shadow_sizes.drain(..) {
            shadows.push(json!({
                "distance": d, "renderer": if base == "btf_shadow" { "mesh" } else { "sss" },
                "object_pixels": px, "texels_per_pixel": t, "resolution": size, "full_resolution": 512,
                "flip": metric(&rep, &format!("flip_{id}"), "mean"),
                "flip_at_ppd": at_ppds(&rep, &format!("flip_{id}")),
                "seconds": seconds(&rep, &id), "full_seconds": seconds(&rep, full),
                "frame_ms": frame_ms(&rep, &id), "full_frame_ms": frame_ms(&rep, full),
            }));
        }
        for (p, preset) in MEDIA {
            let mfp = metric(&rep, &format!("{p}_scene"), "mfp_pixels");
            let full_s = seconds(&rep, &format!("{p}_full"));
            sss.push(json!({
                "distance": d, "medium": preset, "mfp_pixels": mfp, "option": "brdf",
                "flip": metric(&rep, &format!("flip_{p}_brdf"), "mean"),
                "flip_at_ppd": at_ppds(&rep, &format!("flip_{p}_brdf")),
                "seconds": seconds(&rep, &format!("{p}_brdf")), "full_seconds": full_s,
            }));
            sss.push(json!({
                "distance": d, "medium": preset, "mfp_pixels": mfp, "option": "dipole",
                "flip": metric(&rep, &format!("flip_{p}_dipole"), "mean"),
                "flip_at_ppd": at_ppds(&rep, &format!("flip_{p}_dipole")),
                "seconds": seconds(&rep, &format!("{p}_dipole")), "full_seconds": full_s,
                "profile_seconds": seconds(&rep, &format!("{p}_dipole_profile")),
                "full_profile_seconds": seconds(&rep, &format!("{p}_profile")),
            }));
            for t in THRESHOLDS {
                let id = format!("{p}_t{}", (t * 1000.0) as u32);
                sss.push(json!({
                    "distance": d, "medium": preset, "mfp_pixels": mfp, "option": "octree", "threshold": t,
                    "flip": metric(&cpu_rep, &format!("flip_{id}"), "mean"),
                    "flip_at_ppd": at_ppds(&cpu_rep, &format!("flip_{id}")),
                    "seconds": seconds(&cpu_rep, &id), "full_seconds": seconds(&cpu_rep, &format!("{p}_full")),
                }));
            }
            for k in SPACINGS {
                let id = format!("{p}_k{}", (k * 10.0) as u32);
                sss.push(json!({
                    "distance": d, "medium": preset, "mfp_pixels": mfp, "option": "gather", "spacing_footprints": k,
                    "flip": metric(&rep, &format!("flip_{id}"), "mean"),
                    "flip_at_ppd": at_ppds(&rep, &format!("flip_{id}")),
                    "seconds": seconds(&rep, &id), "full_seconds": full_s,
                }));
            }
        }
        eprintln!("distance {d}: texels/pixel {tpp:?}, shell {shell:?} px, mfp {mfp:?} px");
    }
    let doc = json!({
        "about": "FLIP (mean over the object's pixels, HDR, at 67 ppd in `flip`, at other pixels per degree in `flip_at_ppd`) of each candidate model against the full model on the calibration scene of benches/plan_calibrate.rs (a bumps BTF on a sphere, a marble and a ketchup torus), by camera distance, with what the view shows there. Made by `cargo bench --bench plan_calibrate`; the planner interpolates it.",
        "width": width,
        "btf": btf,
        "mdf_off": mdf,
        "mdf_resolution": mdf_resolution,
        "synthesis": synthesis,
        "sss": sss,
        "shadows": shadows,
    });
    let text = serde_json::to_string_pretty(&doc).unwrap() + "\n";
    std::fs::write(out.join("calibration.json"), &text).unwrap();
    println!("wrote {}", out.join("calibration.json").display());
}
