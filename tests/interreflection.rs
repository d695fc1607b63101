//! `btf.capture`'s interreflections against `render.reference`'s path tracing of the same
//! mesostructure: a plane under 8 × 8 tiles of a height field, displaced into the true surface by
//! `mesh.displace` and seen orthographically. Over whole tiles, the mean radiance of an
//! orthographic view equals the mean over the texels of the BTF's entry for that view and light,
//! so each (view, light) pair gives one number from each side. The two codes share nothing but
//! the reflectance model: the capture casts rays through the bilinear height field and gathers
//! the bounces on its samples, the truth traces triangles through a BVH, one path per sample.

use mesoflow_nodes::btf::capture::{Capture, Params as CaptureParams};
use mesoflow_nodes::mesh::displace::{Displace, Params as DisplaceParams};
use mesoflow_nodes::render::reference::{Params as ReferenceParams, Reference};
use mesoflow_nodes::support::raytrace::camera::Camera;
use mesoflow_nodes::types::{Btf, HeightField, Image, Mesh};
use mesoflow_runtime::Inputs;
use mesoflow_testkit::node::{run, OutputsExt};
use serde_json::json;
use std::sync::Arc;

/// Side of the plane (world units), tiles across it, samples of the tile.
const SIDE: f64 = 2.0;
const TILES: usize = 8;
const N: usize = 16;

/// Square pits: an 8 × 8 floor 6 texels below a rim, stepped walls (3 texels a step). Deep
/// enough that a fifth of the light the pits send up has been reflected inside them.
fn pits() -> HeightField {
    HeightField::from_fn(N, N, |i, j| {
        let edge = |k: usize| (k as f32 - 7.5).abs();
        let e = edge(i).max(edge(j));
        (6.0 * ((e - 3.5) / 2.0).clamp(0.0, 1.0)).round()
    })
}

fn directions(list: &[[f64; 2]]) -> serde_json::Value {
    json!(list)
}

const VIEWS: [[f64; 2]; 3] = [[0.0, 0.0], [35.0, 30.0], [55.0, 200.0]];
const LIGHTS: [[f64; 2]; 2] = [[25.0, 60.0], [50.0, 300.0]];

fn captured(bounces: u32) -> Btf {
    let p: CaptureParams = serde_json::from_value(json!({
        "views": directions(&VIEWS), "lights": directions(&LIGHTS),
        "albedo": [0.8, 0.8, 0.8], "samples": 8, "bounces": bounces, "bounce_rays": 1024
    }))
    .unwrap();
    let out = run(
        &Capture,
        &p,
        &Inputs::new().with("height", Arc::new(pits())),
    )
    .unwrap();
    out.take::<Btf>("btf")
}

/// The displaced plane: one texel of the tile is SIDE / (TILES · N) world units, and so is one
/// texel of height.
fn true_surface() -> Mesh {
    let plane = mesoflow_nodes::mesh::primitive::build(
        &serde_json::from_value(json!({"shape": "plane", "size": SIDE, "segments": [8, 8]}))
            .unwrap(),
    )
    .unwrap();
    let texel = SIDE / (TILES * N) as f64;
    let p: DisplaceParams = serde_json::from_value(json!({
        "tiling": [TILES, TILES], "shell": 6.0 * texel, "density": 3.0
    }))
    .unwrap();
    let inputs = Inputs::new()
        .with("mesh", Arc::new(plane))
        .with("height", Arc::new(pits()));
    run(&Displace, &p, &inputs).unwrap().take::<Mesh>("mesh")
}

fn unit(d: [f64; 2]) -> [f64; 3] {
    let (t, p) = (d[0].to_radians(), d[1].to_radians());
    [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()]
}

/// The orthographic camera looking at the plane's centre from `view`.
fn camera(view: [f64; 2]) -> serde_json::Value {
    let w = unit(view);
    json!({
        "eye": [3.0 * w[0], 3.0 * w[1], 3.0 * w[2]], "target": [0.0, 0.0, 0.0],
        "up": if w[1].abs() > 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] },
        "orthographic": 0.75, "resolution": [160, 160]
    })
}

/// The mean of channel 0 of an image of `channels` channels from `camera(view)` over the pixels
/// whose rays enter the reference plane (z = 0) inside the central 4 × 4 tiles.
fn central_mean(view: [f64; 2], data: &[f32], channels: usize) -> f64 {
    let p: ReferenceParams = serde_json::from_value(json!({"camera": camera(view)})).unwrap();
    let cam = Camera::new(&p.camera).unwrap();
    let [w, h] = p.camera.resolution.map(|v| v as usize);
    let half = 2.0 * SIDE / TILES as f64;
    let (mut sum, mut count) = (0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            let (o, d) = cam.ray_at(x as f64 + 0.5, y as f64 + 0.5);
            let t = -o[2] / d[2];
            let (px, py) = (o[0] + t * d[0], o[1] + t * d[1]);
            if px.abs() < half && py.abs() < half {
                sum += data[(y * w + x) * channels] as f64;
                count += 1;
            }
        }
    }
    assert!(count > 2000, "only {count} pixels over the central tiles");
    sum / count as f64
}

/// `render.reference`'s [`central_mean`] with `bounces`.
fn truth(mesh: &Arc<Mesh>, view: [f64; 2], light: [f64; 2], bounces: u32) -> f64 {
    let p: ReferenceParams = serde_json::from_value(json!({
        "camera": camera(view), "light": {"direction": unit(light), "intensity": 1.0},
        "albedo": [0.8, 0.8, 0.8], "samples": 32, "bounces": bounces
    }))
    .unwrap();
    let out = run(&Reference, &p, &Inputs::new().with("mesh", mesh.clone())).unwrap();
    central_mean(view, &out.value::<Image>("image").data, 3)
}

fn btf_mean(b: &Btf, pair: usize) -> f64 {
    let plane = b.width * b.height;
    b.data[pair * 3 * plane..pair * 3 * plane + plane]
        .iter()
        .map(|&v| v as f64)
        .sum::<f64>()
        / plane as f64
}

#[test]
fn the_captures_interreflections_match_path_tracing_of_the_true_surface() {
    let mesh = Arc::new(true_surface());
    let (direct, bounced) = (captured(0), captured(3));
    let (mut worst_total, mut worst_gain) = ((0.0f64, String::new()), (0.0f64, String::new()));
    for (v, view) in VIEWS.iter().enumerate() {
        for (l, light) in LIGHTS.iter().enumerate() {
            let pair = v * LIGHTS.len() + l;
            let (t0, t3) = (
                truth(&mesh, *view, *light, 0),
                truth(&mesh, *view, *light, 3),
            );
            let (c0, c3) = (btf_mean(&direct, pair), btf_mean(&bounced, pair));
            eprintln!(
                "view {view:?} light {light:?}: direct {c0:.5} vs {t0:.5}, 3 bounces {c3:.5} vs {t3:.5} (gain {:.3} vs {:.3})",
                c3 / c0,
                t3 / t0
            );
            let at = format!("view {view:?} light {light:?}");
            let total = (c3 / t3 - 1.0).abs();
            let gain = (c3 / c0 / (t3 / t0) - 1.0).abs();
            if total > worst_total.0 {
                worst_total = (total, at.clone());
            }
            if gain > worst_gain.0 {
                worst_gain = (gain, at.clone());
            }
            // The pits hold light: three bounces add a tenth or more in both renders.
            assert!(t3 > 1.1 * t0 && c3 > 1.1 * c0, "{at}: {t0} {t3} {c0} {c3}");
            // What the bounces add agrees within 2% of the whole (measured at most 0.8%; 20%
            // of the indirect light was missing on the height field's own grid, which the
            // capture now refines 3 times here). The whole within 5% (measured at most 3.3%):
            // the direct light's own difference, 1.1–3.2% here, the capture's surface against
            // its tessellation at 3 vertices a texel where the walls rise 3 texels in one.
            assert!(gain < 0.02, "{at}: the bounces' gain {gain}");
            assert!(total < 0.05, "{at}: {c3} against the truth's {t3}");
        }
    }
    eprintln!(
        "worst whole: {:.4} at {}; worst gain: {:.4} at {}",
        worst_total.0, worst_total.1, worst_gain.0, worst_gain.1
    );
}

/// The same pairs against Mitsuba 3's `path` integrator at `max_depth` 5 (three bounces after
/// the direct one) on the same triangles, written as PLY: the capture's whole against an
/// independent path tracer. Measured: at most 3.3% apart (the direct light's own difference
/// against the tessellation, as above), the bounces' gain at most 0.9% apart; Mitsuba's means
/// and `render.reference`'s agree to 0.05% on every pair.
#[test]
#[ignore = "slow: Mitsuba renders the pits 12 times, 19 s here"]
fn the_captures_interreflections_match_mitsuba_s_path_tracer() {
    let Some(python) = crate::common::peer_python("mitsuba, numpy") else {
        return;
    };
    let s = crate::common::Scratch::new();
    let ply = s.path("pits.ply");
    std::fs::write(&ply, mesoflow_nodes::mesh::write::ply(&true_surface())).unwrap();
    let (direct, bounced) = (captured(0), captured(3));
    for (v, view) in VIEWS.iter().enumerate() {
        for (l, light) in LIGHTS.iter().enumerate() {
            let pair = v * LIGHTS.len() + l;
            let mut theirs = [0.0; 2];
            for (k, depth) in [2, 5].into_iter().enumerate() {
                let scene = s.write(
                    &format!("mitsuba{pair}_{depth}.json"),
                    &json!({ "mesh": ply, "camera": camera(*view),
                             "light": {"direction": unit(*light), "intensity": 1.0},
                             "albedo": [0.8, 0.8, 0.8], "samples": 64, "max_depth": depth })
                    .to_string(),
                );
                let npy = s.path(&format!("mitsuba{pair}_{depth}.npy"));
                crate::common::run_peer(&python, "mitsuba_reference.py", &[&scene, &npy]);
                theirs[k] = central_mean(*view, &crate::common::read_npy(&npy).1, 4);
            }
            let (c0, c3) = (btf_mean(&direct, pair), btf_mean(&bounced, pair));
            let at = format!("view {view:?} light {light:?}");
            let gain = (c3 / c0 / (theirs[1] / theirs[0]) - 1.0).abs();
            eprintln!(
                "{at}: direct {c0:.5} vs Mitsuba {:.5}, 3 bounces {c3:.5} vs {:.5} (gain {:.3} vs {:.3})",
                theirs[0],
                theirs[1],
                c3 / c0,
                theirs[1] / theirs[0]
            );
            assert!(gain < 0.02, "{at}: the bounces' gain {gain}");
            assert!(
                (c3 / theirs[1] - 1.0).abs() < 0.05,
                "{at}: {c3} against {}",
                theirs[1]
            );
        }
    }
}
