//! Translucency against the truth, held in CI: `graphs/sss_truth.json` as the README measures it
//! (graphs/sss_render.json's torus at 20 mm per unit, 160 × 120, η = 1) rendered by
//! `sss.render` and by volumetric path tracing (`render.reference` with a medium, 1024 samples
//! a pixel; its own noise is reported and taken out of the comparison), and the render Jensen
//! & Buhler describe (planar gather, no bounces, the graph sss_render.json's dipole with single
//! scattering) on the same truth. The renders are deterministic (seeded samples and paths), so
//! the numbers do not move between runs.
//!
//! The issue asks for a relative RMSE of at most 0.12 (marble) and 0.15 (skin1) and the dimmer
//! half's bias within ±15%: both materials meet both with the graph's one configuration (the
//! README's translucency section), on the torus and on a back-lit ball. The bounds here are
//! what is reached, with a margin, no looser than the issue's, so that a change that loses
//! accuracy fails, and the gain over Jensen & Buhler's render is held too.

use crate::common::{mesoflow, metric, read_npy, report, Scratch};
use std::path::{Path, PathBuf};

struct Measured {
    /// Relative RMSE over the object's pixels, the truth's own noise taken out in quadrature.
    rel: f64,
    /// Bias over the object, and over its dimmer half: the pixels below the median of a second
    /// truth rendered with another seed. Chosen by the compared truth itself, the half would
    /// take the pixels its noise made dark, and read ours too bright: at 256 samples a pixel
    /// on the README's sphere, +178% where the independent choice gives +46%.
    bias: f64,
    dim: f64,
}

/// `ours` against the truth in `out`, the dimmer half chosen by the truth in `selection`.
fn measure(out: &Path, selection: &Path, material: &str) -> Measured {
    let noise = metric(&report(out), &format!("{material}_truth"), "noise");
    let (_, truth) = read_npy(&out.join(format!("{material}_truth.npy")));
    let (_, chooser) = read_npy(&selection.join(format!("{material}_truth.npy")));
    let (_, ours) = read_npy(&out.join(format!("{material}.npy")));
    let lum = |v: &[f32], i: usize| (v[3 * i] + v[3 * i + 1] + v[3 * i + 2]) as f64;
    let n = truth.len() / 3;
    // The object is where ours is lit at all: the camera's view of the mesh, the same for
    // every truth. Taken as the truth's nonzero pixels it would drop exactly those its noise
    // left black, and lift its sum in the dim parts: on the README's sphere at 256 samples a
    // pixel they are 11% of the object, and leaving them out read marble's dimmer half +18%
    // where counting them reads +32% (+34% against a 2048-sample truth). A pixel the chooser
    // left black is among the dimmest, so it joins the dimmer half.
    let object: Vec<usize> = (0..n).filter(|&i| lum(&ours, i) > 0.0).collect();
    let mut sorted: Vec<f64> = object.iter().map(|&i| lum(&chooser, i)).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let (mut d2, mut t2) = (0.0, 0.0);
    let (mut sum_o, mut sum_t, mut dim_o, mut dim_t) = (0.0, 0.0, 0.0, 0.0);
    for &i in &object {
        for k in 0..3 {
            let (o, t) = (ours[3 * i + k] as f64, truth[3 * i + k] as f64);
            d2 += (o - t) * (o - t);
            t2 += t * t;
        }
        let (o, t) = (lum(&ours, i), lum(&truth, i));
        sum_o += o;
        sum_t += t;
        if lum(&chooser, i) < median {
            dim_o += o;
            dim_t += t;
        }
    }
    let raw = (d2 / t2).sqrt();
    Measured {
        rel: (raw * raw - noise * noise).max(0.0).sqrt(),
        bias: sum_o / sum_t - 1.0,
        dim: dim_o / dim_t - 1.0,
    }
}

/// `graphs/sss_truth.json` on the CPU with these `--set`s and `--output`s (all sinks when
/// none), its cache in the scratch folder; the output folder `name`.
fn run_truth_graph(s: &Scratch, name: &str, sets: &[&str], outputs: &[&str]) -> PathBuf {
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/sss_truth.json");
    let (cache, out) = (s.path("cache"), s.path(name));
    let mut args = vec!["run", graph.to_str().unwrap(), "--quiet", "--device", "cpu"];
    args.extend(["--cache-dir", cache.to_str().unwrap()]);
    args.extend(["--out-dir", out.to_str().unwrap()]);
    for set in sets {
        args.extend(["--set", set]);
    }
    for output in outputs {
        args.extend(["--output", output]);
    }
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    out
}

#[test]
#[ignore = "slow: volumetric path-traced truths at 1024 samples"]
fn translucent_renders_against_the_volumetric_truth() {
    let s = Scratch::new();
    let ours = run_truth_graph(&s, "ours", &[], &[]);
    // Jensen & Buhler 2002 as graphs/sss_render.json renders it (the truth comes from the
    // cache; only what is compared, not the brute-force gather again).
    let jensen = run_truth_graph(
        &s,
        "jensen",
        &[
            "marble_profile.model=dipole",
            "skin1_profile.model=dipole",
            "marble.single_scattering=true",
            "marble.bounces=0",
            "skin1.bounces=0",
            "marble.geometry=planar",
            "marble.sources=point",
            "skin1.sources=point",
            "marble.emission=diffuse",
            "skin1.emission=diffuse",
            "skin1.geometry=planar",
            "skin1.single_scattering_shape=half_space",
            "marble.single_scattering_shape=half_space",
        ],
        &[
            "marble_npy.files",
            "skin1_npy.files",
            "marble_truth_npy.files",
            "skin1_truth_npy.files",
            "marble_truth.noise",
            "skin1_truth.noise",
        ],
    );
    // The truths again with another seed, 256 samples a pixel: they only choose the dimmer half.
    let chooser = run_truth_graph(
        &s,
        "chooser",
        &[
            "marble_truth.seed=2",
            "marble_truth.samples=256",
            "skin1_truth.seed=2",
            "skin1_truth.samples=256",
        ],
        &["marble_truth_npy.files", "skin1_truth_npy.files"],
    );
    for (material, rel, bias, dim) in [
        // Measured 0.093 (the truth's noise 0.044 taken out), bias −6.3%, dimmer half −3.7%
        // (Jensen & Buhler: 0.235, −1.8%, −41%); the issue asks for 0.12 and ±15%.
        ("marble", 0.10, 0.08, 0.06),
        // Measured 0.099 (noise 0.033 taken out), bias −4.9%, dimmer half +3.3% (Jensen &
        // Buhler: 0.232, −14%, −67%); the issue asks for 0.15 and ±15%.
        ("skin1", 0.11, 0.08, 0.08),
    ] {
        let m = measure(&ours, &chooser, material);
        let j = measure(&jensen, &chooser, material);
        eprintln!(
            "{material}: relative RMSE {:.3} (Jensen & Buhler {:.3}), bias {:+.3} ({:+.3}), dimmer half {:+.3} ({:+.3})",
            m.rel, j.rel, m.bias, j.bias, m.dim, j.dim
        );
        assert!(m.rel <= rel, "{material}: relative RMSE {}", m.rel);
        assert!(m.bias.abs() <= bias, "{material}: bias {}", m.bias);
        assert!(
            m.dim.abs() <= dim,
            "{material}: dimmer half's bias {}",
            m.dim
        );
        // The bounces and the body geometry bring the dimmer half within 20 points of
        // where Jensen & Buhler's render leaves it (measured −41% and −67%).
        assert!(
            m.dim.abs() + 0.2 < j.dim.abs(),
            "{material}: {} vs {}",
            m.dim,
            j.dim
        );
    }
    // The octree (threshold 0.1) at brute force's error: the README's speed-up is at equal
    // error (measured 0.0923 and 0.0926 with the truth's noise in; the noise is common to both).
    let rep = report(&ours);
    let rel = |id: &str| metric(&rep, id, "relative_rmse");
    let (octree, brute) = (rel("marble_error"), rel("marble_brute_error"));
    assert!(
        (octree - brute).abs() < 0.002,
        "octree {octree} against brute force {brute}"
    );
}

/// The graph's one configuration on other materials, against 256-sample truths: a thick one
/// (skin2, the tube 17 reduced mean free paths across) meets the bounds as marble and
/// skin1 do; a thin one (chicken1, 2.5 paths) does not, `body` sending far too much light
/// through the tube, and `sss.render` says so with its thin-object warning, which gives
/// `planar`'s error too; `planar` (with the better dipole) meets the bounds there. The same
/// chicken1 torus three times larger (7.5 paths) comes within 0.12 with the graph's
/// configuration and no warning, its dimmer half too bright (+20%): the thickness is the
/// cause of the failure, not the material's colour.
#[test]
#[ignore = "slow: volumetric path-traced truths of five materials"]
fn the_configuration_holds_on_thick_materials_and_warns_on_thin_ones() {
    let s = Scratch::new();
    let run = |name: &str, preset: &str, mm: &str, geometry: &str| {
        let sets = [
            format!("marble_material.preset={preset}"),
            "marble_truth.samples=256".into(),
            format!("marble_truth.mm_per_unit={mm}"),
            format!("marble.mm_per_unit={mm}"),
            format!("marble.geometry={geometry}"),
            // `planar`, the thin object's way out, with Jensen's sources (the beam's need a
            // geometry that follows the shape) and the better dipole: PBD's multiple
            // scattering alone, the graph's, leaves chicken1's planar render too dark (0.192,
            // dimmer half −25%), where the better dipole's excess makes up for it.
            format!(
                "marble.sources={}",
                if geometry == "planar" {
                    "point"
                } else {
                    "beam"
                }
            ),
            format!(
                "marble_profile.model={}",
                if geometry == "planar" {
                    "better_dipole"
                } else {
                    "pbd_multiple"
                }
            ),
        ];
        let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
        let outputs = [
            "marble_truth_npy.files",
            "marble_npy.files",
            "marble_truth.noise",
        ];
        let out = run_truth_graph(&s, name, &sets, &outputs);
        let chooser = run_truth_graph(
            &s,
            &format!("{name}_chooser"),
            &[
                sets[0],
                sets[2],
                "marble_truth.samples=256",
                "marble_truth.seed=2",
            ],
            &["marble_truth_npy.files"],
        );
        let warned = report(&out)["warnings"].as_array().map(|w| {
            w.iter()
                .filter(|w| w.to_string().contains("mean free paths"))
                .map(|w| w.to_string())
                .collect::<Vec<_>>()
        });
        let m = measure(&out, &chooser, "marble");
        eprintln!(
            "{name}: relative RMSE {:.3}, dimmer half {:+.3}, {warned:?}",
            m.rel, m.dim
        );
        (m, warned.unwrap_or_default())
    };
    // Measured: skin2 0.098, dimmer half −0.3%; chicken1 planar 0.133, −9.9%; the issue's
    // bounds for skin1 (0.15, ±15%). chicken1 at 60 mm a unit: 0.103, but its dimmer half
    // +20% misses ±15%, held at ±25% (Jensen's sources and the better dipole: +17.5%).
    for (name, preset, mm, geometry, thin, rel, dim) in [
        ("skin2", "skin2", "20", "body", false, 0.12, 0.06),
        (
            "chicken1_planar",
            "chicken1",
            "20",
            "planar",
            true,
            0.15,
            0.15,
        ),
        ("chicken1_60", "chicken1", "60", "body", false, 0.12, 0.25),
    ] {
        let (m, warned) = run(name, preset, mm, geometry);
        assert!(
            m.rel <= rel && m.dim.abs() <= dim,
            "{name}: {} {}",
            m.rel,
            m.dim
        );
        assert_eq!(!warned.is_empty(), thin, "{name}: {warned:?}");
    }
    // Measured 0.233, dimmer half +63%: the warning's "far too bright" holds.
    let (m, warned) = run("chicken1", "chicken1", "20", "body");
    assert!(
        warned
            .iter()
            .any(|w| w.contains("red 2.5") && w.contains("planar")),
        "chicken1's 15 mm tube is 2.5 reduced mean free paths in red: {warned:?}"
    );
    assert!(m.dim > 0.5, "chicken1's dimmer half {}", m.dim);
}

/// Another shape: a ball 28 mm across in place of the torus, lit from behind, so that most of
/// what the camera sees is lit only through the material, against 2048-sample truths (at 256 a
/// pixel a tenth of its far side is black and its band sums move by 30% between seeds). The
/// graph's configuration meets the bounds here too; with Jensen's sources one reduced
/// mean free path under each sample (`sources: point`) instead of the beam's, marble's unlit
/// front comes out far too bright and skin1's error is half as large again.
#[test]
#[ignore = "slow: volumetric path-traced truths at 2048 samples"]
fn a_back_lit_ball_meets_the_bounds_with_the_beams_sources() {
    let s = Scratch::new();
    let outputs = [
        "marble_truth_npy.files",
        "marble_npy.files",
        "marble_truth.noise",
    ];
    // Measured: marble 0.107, bias −8.6%, dimmer half +5.9%; skin1 0.122, −9.9%, +5.3%. With
    // `sources: point`: marble 0.099, −6.9%, +32%; skin1 0.195, −20%, +4.7%.
    for (material, rel, dim) in [("marble", 0.12, 0.10), ("skin1", 0.14, 0.10)] {
        let ball = |sources: &str, samples: &str, seed: &str| {
            [
                "torus.shape=sphere".to_string(),
                "torus.size=0.7".into(),
                "torus.segments=[96,48]".into(),
                format!("marble_material.preset={material}"),
                format!("marble_truth.samples={samples}"),
                format!("marble_truth.seed={seed}"),
                format!("marble.sources={sources}"),
            ]
        };
        let run = |name: &str, sets: &[String], outputs: &[&str]| {
            let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
            run_truth_graph(&s, &format!("{material}_{name}"), &sets, outputs)
        };
        let beam = run("beam", &ball("beam", "2048", "3"), &outputs);
        let point = run("point", &ball("point", "2048", "3"), &outputs);
        let chooser = run(
            "chooser",
            &ball("beam", "256", "2"),
            &["marble_truth_npy.files"],
        );
        let (m, p) = (
            measure(&beam, &chooser, "marble"),
            measure(&point, &chooser, "marble"),
        );
        eprintln!(
            "{material} ball: relative RMSE {:.3} (point sources {:.3}), bias {:+.3} ({:+.3}), dimmer half {:+.3} ({:+.3})",
            m.rel, p.rel, m.bias, p.bias, m.dim, p.dim
        );
        assert!(m.rel <= rel, "{material}: relative RMSE {}", m.rel);
        assert!(m.dim.abs() <= dim, "{material}: dimmer half {}", m.dim);
        assert!(
            p.dim > 0.25 || p.rel > 0.13,
            "{material}: point sources {} {}",
            p.rel,
            p.dim
        );
    }
}
