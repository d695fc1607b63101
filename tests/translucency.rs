//! Translucency against the truth: `graphs/sss_truth.json` as the guide measures it
//! (graphs/sss_render.json's torus at 20 mm per unit, 160 × 120, η = 1) rendered by
//! `sss.render`, and the render Jensen & Buhler describe (planar gather, no bounces, the graph
//! sss_render.json's dipole with single scattering), against volumetric path tracing
//! (`render.reference` with a medium, 1024 samples a pixel; its own noise is taken out of the
//! comparison). The truths take minutes each, so they are committed fixtures
//! (`tests/fixtures/sss_truths/`, made by `make.py` there, one regenerated and compared by the
//! slow tier); our renders are made here on every run. Everything is seeded, so the numbers do
//! not move between runs.
//!
//! The issue asks for a relative RMSE of at most 0.12 (marble) and 0.15 (skin1) and the dimmer
//! half's bias within ±15%: both materials meet both with the graph's one configuration (the
//! guide's translucency page), on the torus and on a back-lit ball. The bounds here are what is
//! reached, with a margin, no looser than the issue's, so that a change that loses accuracy
//! fails, and the gain over Jensen & Buhler's render is held too.

use crate::common::{mesoflow, read_npy, report, Scratch};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The committed truths: `truths.json` names each one's node of `graphs/sss_truth.json` and
/// its `--set`s, and holds its noise estimate; `<name>.npy` is its image. `make.py` beside
/// them renders them (about 15 minutes here); `a_regenerated_truth_matches_its_fixture`
/// renders one again and compares, so a change to the truth renderer cannot go unnoticed.
const FIXTURES: &str = "tests/fixtures/sss_truths";

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(FIXTURES)
}

fn truth_spec() -> Value {
    let path = fixtures().join("truths.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).expect("truths.json is JSON")
}

/// A volumetric truth: its image and its own noise estimate (relative RMSE of its Monte Carlo
/// noise, from `render.reference`'s report when it was made).
struct Truth {
    image: Vec<f32>,
    noise: f64,
}

fn truth(name: &str) -> Truth {
    let spec = truth_spec();
    let entry = &spec["truths"][name];
    let noise = entry["noise"]
        .as_f64()
        .unwrap_or_else(|| panic!("truth {name} has no noise: run {FIXTURES}/make.py {name}"));
    let (_, image) = read_npy(&fixtures().join(format!("{name}.npy")));
    Truth { image, noise }
}

struct Measured {
    /// Relative RMSE over the object's pixels, the truth's own noise taken out in quadrature.
    rel: f64,
    /// The same with the truth's noise left in.
    raw: f64,
    /// Bias over the object, and over its dimmer half: the pixels below the median of a second
    /// truth rendered with another seed. Chosen by the compared truth itself, the half would
    /// take the pixels its noise made dark, and read ours too bright: at 256 samples a pixel
    /// on the translucency guide's sphere, +178% where the independent choice gives +46%.
    bias: f64,
    dim: f64,
}

/// `ours` against `truth`, the dimmer half chosen by `chooser`.
fn measure(ours: &[f32], truth: &Truth, chooser: &Truth) -> Measured {
    let (truth, noise, chooser) = (&truth.image, truth.noise, &chooser.image);
    assert_eq!(
        ours.len(),
        truth.len(),
        "our image and the truth differ in size"
    );
    let lum = |v: &[f32], i: usize| (v[3 * i] + v[3 * i + 1] + v[3 * i + 2]) as f64;
    let n = truth.len() / 3;
    // The object is where ours is lit at all: the camera's view of the mesh, the same for
    // every truth. Taken as the truth's nonzero pixels it would drop exactly those its noise
    // left black, and lift its sum in the dim parts: on the translucency guide's sphere at 256 samples a
    // pixel they are 11% of the object, and leaving them out read marble's dimmer half +18%
    // where counting them reads +32% (+34% against a 2048-sample truth). A pixel the chooser
    // left black is among the dimmest, so it joins the dimmer half.
    let object: Vec<usize> = (0..n).filter(|&i| lum(ours, i) > 0.0).collect();
    let mut sorted: Vec<f64> = object.iter().map(|&i| lum(chooser, i)).collect();
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
        let (o, t) = (lum(ours, i), lum(truth, i));
        sum_o += o;
        sum_t += t;
        if lum(chooser, i) < median {
            dim_o += o;
            dim_t += t;
        }
    }
    let raw = (d2 / t2).sqrt();
    Measured {
        rel: (raw * raw - noise * noise).max(0.0).sqrt(),
        raw,
        bias: sum_o / sum_t - 1.0,
        dim: dim_o / dim_t - 1.0,
    }
}

/// `graphs/sss_truth.json` without its truths: every `render.reference` node and what depends
/// on one taken out, every `sss.render` node written to `<id>.npy`. The truths come from the
/// fixtures instead.
fn graph_without_truths(s: &Scratch) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/sss_truth.json");
    let mut graph: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let nodes = graph["nodes"].as_object_mut().unwrap();
    let mut removed: Vec<String> = nodes
        .iter()
        .filter(|(_, n)| n["kind"] == "render.reference")
        .map(|(id, _)| id.clone())
        .collect();
    loop {
        let reads_removed = |n: &Value| {
            n["inputs"].as_object().is_some_and(|inputs| {
                inputs.values().any(|v| {
                    let from = v.as_str().unwrap_or("").split('.').next().unwrap_or("");
                    removed.iter().any(|r| r == from)
                })
            })
        };
        let more: Vec<String> = nodes
            .iter()
            .filter(|(id, n)| !removed.contains(id) && reads_removed(n))
            .map(|(id, _)| id.clone())
            .collect();
        if more.is_empty() {
            break;
        }
        removed.extend(more);
    }
    nodes.retain(|id, _| !removed.contains(id));
    let renders: Vec<String> = nodes
        .iter()
        .filter(|(_, n)| n["kind"] == "sss.render")
        .map(|(id, _)| id.clone())
        .collect();
    for id in renders {
        nodes.insert(
            format!("{id}_npy"),
            serde_json::json!({"kind": "npy.write", "params": {"path": format!("{id}.npy")},
                               "inputs": {"value": format!("{id}.image")}}),
        );
    }
    let out = s.path("sss_ours.json");
    std::fs::write(&out, serde_json::to_string_pretty(&graph).unwrap()).unwrap();
    out
}

/// Our renders `ids` of `graphs/sss_truth.json` (its truths taken out) on the CPU with these
/// `--set`s (those of the truth nodes dropped), its cache in the scratch folder; the output
/// folder `name`. Only the renders asked for run: brute force is minutes.
fn run_ours(s: &Scratch, name: &str, sets: &[&str], ids: &[&str]) -> PathBuf {
    let graph = graph_without_truths(s);
    let (cache, out) = (s.path("cache"), s.path(name));
    let mut args = vec!["run", graph.to_str().unwrap(), "--quiet", "--device", "cpu"];
    args.extend(["--cache-dir", cache.to_str().unwrap()]);
    args.extend(["--out-dir", out.to_str().unwrap()]);
    for set in sets.iter().filter(|s| !s.contains("_truth.")) {
        args.extend(["--set", set]);
    }
    let outputs: Vec<String> = ids.iter().map(|id| format!("{id}_npy.files")).collect();
    for o in &outputs {
        args.extend(["--output", o]);
    }
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    out
}

/// The image our render `id` wrote into `out`.
fn ours(out: &Path, id: &str) -> Vec<f32> {
    read_npy(&out.join(format!("{id}.npy"))).1
}

#[test]
#[ignore = "slow: sss.render's accurate configuration, its octree and brute force, Jensen & Buhler's render, at 160 × 120"]
fn translucent_renders_against_the_volumetric_truth() {
    let s = Scratch::new();
    let out = run_ours(&s, "ours", &[], &["marble", "skin1", "marble_brute"]);
    // Jensen & Buhler 2002 as graphs/sss_render.json renders it.
    let jensen = run_ours(
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
        &["marble", "skin1"],
    );
    for (material, rel, bias, dim) in [
        // Measured 0.093 (the truth's noise 0.044 taken out), bias −6.3%, dimmer half −3.7%
        // (Jensen & Buhler: 0.235, −1.8%, −41%); the issue asks for 0.12 and ±15%.
        ("marble", 0.10, 0.08, 0.06),
        // Measured 0.099 (noise 0.033 taken out), bias −4.9%, dimmer half +3.3% (Jensen &
        // Buhler: 0.232, −14%, −67%); the issue asks for 0.15 and ±15%.
        ("skin1", 0.11, 0.08, 0.08),
    ] {
        // The truths with another seed, 256 samples a pixel, only choose the dimmer half.
        let (t, chooser) = (
            truth(&format!("torus_{material}")),
            truth(&format!("torus_{material}_chooser")),
        );
        let m = measure(&ours(&out, material), &t, &chooser);
        let j = measure(&ours(&jensen, material), &t, &chooser);
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
    // The octree (threshold 0.1) at brute force's error: the translucency guide's speed-up is at equal
    // error (the truth's noise left in, common to both).
    let (t, chooser) = (truth("torus_marble"), truth("torus_marble_chooser"));
    let octree = measure(&ours(&out, "marble"), &t, &chooser).raw;
    let brute = measure(&ours(&out, "marble_brute"), &t, &chooser).raw;
    eprintln!("octree {octree:.4}, brute force {brute:.4}, the truth's noise in");
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
#[ignore = "slow: sss.render on four materials and sizes at 160 × 120"]
fn the_configuration_holds_on_thick_materials_and_warns_on_thin_ones() {
    let s = Scratch::new();
    let run = |name: &str, preset: &str, mm: &str, geometry: &str| {
        let sets = [
            format!("marble_material.preset={preset}"),
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
        let out = run_ours(&s, name, &sets, &["marble"]);
        let warned = report(&out)["warnings"].as_array().map(|w| {
            w.iter()
                .filter(|w| w.to_string().contains("mean free paths"))
                .map(|w| w.to_string())
                .collect::<Vec<_>>()
        });
        let m = measure(
            &ours(&out, "marble"),
            &truth(&format!("{preset}_{mm}")),
            &truth(&format!("{preset}_{mm}_chooser")),
        );
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
#[ignore = "slow: sss.render on a ball of two materials, two kinds of sources, at 160 × 120"]
fn a_back_lit_ball_meets_the_bounds_with_the_beams_sources() {
    let s = Scratch::new();
    // Measured: marble 0.107, bias −8.6%, dimmer half +5.9%; skin1 0.122, −9.9%, +5.3%. With
    // `sources: point`: marble 0.099, −6.9%, +32%; skin1 0.195, −20%, +4.7%.
    for (material, rel, dim) in [("marble", 0.12, 0.10), ("skin1", 0.14, 0.10)] {
        let ball = |sources: &str| {
            [
                "torus.shape=sphere".to_string(),
                "torus.size=0.7".into(),
                "torus.segments=[96,48]".into(),
                format!("marble_material.preset={material}"),
                format!("marble.sources={sources}"),
            ]
        };
        let run = |name: &str, sets: &[String]| {
            let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
            ours(
                &run_ours(&s, &format!("{material}_{name}"), &sets, &["marble"]),
                "marble",
            )
        };
        let (t, chooser) = (
            truth(&format!("ball_{material}")),
            truth(&format!("ball_{material}_chooser")),
        );
        let m = measure(&run("beam", &ball("beam")), &t, &chooser);
        let p = measure(&run("point", &ball("point")), &t, &chooser);
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

/// Each fixture's recorded noise is held by the images themselves: a truth and its chooser (the
/// same scene on another seed) differ by their two noises in quadrature, so the relative RMSE
/// between them over √(n₁² + n₂² · |chooser|²/|truth|²) is 1 where the recorded noises are
/// right (measured 0.972–1.001 over the seven pairs). An inflated noise, which the accuracy
/// tests above would subtract and so pass a worse render, makes the ratio fall below the
/// bound.
#[test]
fn each_fixtures_recorded_noise_is_what_its_pair_of_seeds_shows() {
    let spec = truth_spec();
    let names: Vec<String> = spec["truths"]
        .as_object()
        .unwrap()
        .keys()
        .filter(|k| !k.ends_with("_chooser"))
        .cloned()
        .collect();
    assert!(names.len() >= 7, "{names:?}");
    for name in names {
        let (a, b) = (truth(&name), truth(&format!("{name}_chooser")));
        assert_eq!(a.image.len(), b.image.len(), "{name}");
        let (mut d2, mut a2, mut b2) = (0.0f64, 0.0f64, 0.0f64);
        for (x, y) in a.image.iter().zip(&b.image) {
            let (x, y) = (*x as f64, *y as f64);
            d2 += (x - y).powi(2);
            a2 += x * x;
            b2 += y * y;
        }
        let rel = (d2 / a2).sqrt();
        let expected = (a.noise.powi(2) + b.noise.powi(2) * b2 / a2).sqrt();
        let ratio = rel / expected;
        assert!(
            (0.9..=1.1).contains(&ratio),
            "{name}: the two seeds differ by {rel:.4}, their recorded noises say {expected:.4} ({ratio:.3})"
        );
    }
}

/// The fixtures are what `render.reference` makes today: the cheapest of them (a 256-sample
/// truth) rendered again by `make.py`'s command must give the committed image. The renders are
/// seeded and deterministic at any thread count, so the bits agree; the tolerance, a
/// thousandth of the image's own noise, only admits a platform whose libm rounds a
/// transcendental differently in the last place.
#[test]
#[ignore = "slow: a 256-sample volumetric truth rendered again"]
fn a_regenerated_truth_matches_its_fixture() {
    let s = Scratch::new();
    let spec = truth_spec();
    let name = "torus_marble_chooser";
    let entry = &spec["truths"][name];
    let node = entry["node"].as_str().unwrap();
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join(spec["graph"].as_str().unwrap());
    let (cache, out) = (s.path("cache"), s.path("out"));
    let mut args = vec!["run", graph.to_str().unwrap(), "--quiet", "--device", "cpu"];
    args.extend(["--cache-dir", cache.to_str().unwrap()]);
    args.extend(["--out-dir", out.to_str().unwrap()]);
    let outputs = [format!("{node}_npy.files"), format!("{node}.noise")];
    for o in &outputs {
        args.extend(["--output", o]);
    }
    let sets: Vec<&str> = entry["sets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    for set in &sets {
        args.extend(["--set", set]);
    }
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let fixture = truth(name);
    let (_, again) = read_npy(&out.join(format!("{node}.npy")));
    assert_eq!(again.len(), fixture.image.len());
    let (mut d2, mut t2) = (0.0f64, 0.0f64);
    for (a, f) in again.iter().zip(&fixture.image) {
        d2 += ((a - f) as f64).powi(2);
        t2 += (*f as f64).powi(2);
    }
    let rel = (d2 / t2).sqrt();
    let noise = crate::common::metric(&report(&out), node, "noise");
    eprintln!(
        "{name}: regenerated against the fixture {rel:e}, noise {noise} (fixture {})",
        fixture.noise
    );
    assert!(
        rel <= 1e-3 * fixture.noise && (noise - fixture.noise).abs() <= 1e-6,
        "{name} no longer matches its fixture ({rel}, noise {noise} against {}): run {FIXTURES}/make.py",
        fixture.noise
    );
}
