//! `mesoflow plan` end to end on `graphs/plan_verify.json` at a small size: the planned graph
//! runs and renders from the same camera; budget 0 reproduces the full model exactly (FLIP 0);
//! an enormous budget picks the cheapest model (never nothing); far views drop the MDF;
//! translucency becomes a BRDF when scattering is sub-pixel; a camera inside the object and bad
//! arguments are clear errors. The measured model alone (`--probe-budget 0`): the probe that
//! proves a plan on the view is tests/plan_probe.rs's.

use crate::common::{mesoflow, metric, report, Run, Scratch};
use serde_json::Value;
use std::path::{Path, PathBuf};

const DIRS: &str = r#"{"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#;

/// The verify graph at test size, with every view's camera at `eye`.
fn sets(eye: [f64; 3]) -> Vec<String> {
    let mut v = vec![
        "surface.size=16".to_string(),
        format!("capture.views={DIRS}"),
        format!("capture.lights={DIRS}"),
        format!("mdf.views={DIRS}"),
        "torus.segments=[32,16]".into(),
        "sphere.segments=[32,16]".into(),
    ];
    for id in ["btf_full", "btf_view", "sss_full", "sss_view"] {
        v.push(format!(
            "{id}.camera.eye=[{},{},{}]",
            eye[0], eye[1], eye[2]
        ));
        v.push(format!("{id}.camera.resolution=[48,36]"));
        v.push(format!("{id}.shadow_resolution=128"));
    }
    for id in ["sss_full", "sss_view"] {
        v.push(format!("{id}.max_points=2000"));
    }
    v
}

fn graph() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/plan_verify.json")
}

struct Planned {
    run: Run,
    dir: PathBuf,
}

impl Planned {
    fn graph(&self) -> Value {
        serde_json::from_str(&std::fs::read_to_string(self.dir.join("planned.json")).unwrap())
            .unwrap()
    }
    fn plan(&self) -> Value {
        serde_json::from_str(&std::fs::read_to_string(self.dir.join("planned.plan.json")).unwrap())
            .unwrap()
    }
}

fn plan(
    s: &Scratch,
    name: &str,
    graph: &Path,
    render: &str,
    budget: &str,
    sets: &[String],
) -> Planned {
    plan_with(s, name, graph, render, budget, sets, &[])
}

/// [`plan`] with further arguments.
fn plan_with(
    s: &Scratch,
    name: &str,
    graph: &Path,
    render: &str,
    budget: &str,
    sets: &[String],
    extra: &[&str],
) -> Planned {
    let dir = s.path(name);
    let out = dir.join("planned.json");
    let cache = s.path("cache");
    let mut args: Vec<String> = vec![
        "plan".into(),
        graph.display().to_string(),
        "--render".into(),
        render.into(),
        "--budget".into(),
        budget.into(),
        "-o".into(),
        out.display().to_string(),
        "--quiet".into(),
        "--cache-dir".into(),
        cache.display().to_string(),
        // The measured model's rules alone: proving plans on a probe of the view is
        // tests/plan_probe.rs's (at this test's 48 × 36 a probe would be 24 × 18 pixels).
        "--probe-budget".into(),
        "0".into(),
    ];
    for kv in sets {
        args.push("--set".into());
        args.push(kv.clone());
    }
    args.extend(extra.iter().map(|a| a.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    Planned {
        run: mesoflow(&args, s.dir.path()),
        dir,
    }
}

fn run_planned(s: &Scratch, p: &Planned) -> Value {
    let out = p.dir.join("out");
    let r = mesoflow(
        &[
            "run",
            p.dir.join("planned.json").to_str().unwrap(),
            "--quiet",
            "--out-dir",
            out.to_str().unwrap(),
            "--cache-dir",
            s.path("cache").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    report(&out)
}

fn decision<'a>(plan: &'a Value, stage: &str) -> &'a Value {
    plan["decisions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["stage"] == stage)
        .unwrap_or_else(|| panic!("no {stage} decision in {plan}"))
}

#[test]
fn budget_zero_plans_the_full_model_and_reproduces_it_exactly() {
    let s = Scratch::new();
    let near = sets([0.0, 1.5, 2.7]);
    let b = plan(&s, "btf", &graph(), "btf_view", "flip=0", &near);
    assert_eq!(b.run.code, 0, "{}", b.run.stderr);
    let both = plan(
        &s,
        "both",
        &b.dir.join("planned.json"),
        "sss_view",
        "flip=0",
        &[],
    );
    assert_eq!(both.run.code, 0, "{}", both.run.stderr);
    assert_eq!(decision(&b.plan(), "btf")["choice"]["model"], "raw");
    assert_eq!(decision(&b.plan(), "mdf")["choice"]["use_mdf"], true);
    // Budget 0 is the graph as given (issue 41), here the full model both views are written
    // with (a brute-force gather of PBD).
    let g = both.graph();
    assert_eq!(g["nodes"]["sss_view"]["params"]["threshold"], 0.0);
    assert!(g["nodes"]["sss_view"]["params"].get("mode").is_none());
    assert_eq!(g["nodes"]["skin_profile"]["params"]["model"], "pbd");
    // The planned views are the full model: identical renders, FLIP exactly 0 (the same
    // keys, so the same cached values).
    let rep = run_planned(&s, &both);
    assert_eq!(metric(&rep, "btf_flip", "mean"), 0.0);
    assert_eq!(metric(&rep, "sss_flip", "mean"), 0.0);
    // Plans carry reasons; the full model's choices are predicted at exactly 0.
    for d in b.plan()["decisions"].as_array().unwrap() {
        assert!(!d["reason"].as_str().unwrap().is_empty());
        assert_eq!(d["predicted_error"], 0.0);
    }
    assert_eq!(b.plan()["predicted_error"], 0.0);
}

#[test]
fn far_views_drop_the_mdf_and_an_enormous_budget_is_the_cheapest() {
    let s = Scratch::new();
    // 40 units away the 48-pixel view shows the torus a few pixels wide: the 0.1-unit shell is
    // far under half a pixel, and a pixel covers many texels.
    let far = sets([0.0, 22.0, 40.0]);
    let p = plan(&s, "far", &graph(), "btf_view", "flip=0.05", &far);
    assert_eq!(p.run.code, 0, "{}", p.run.stderr);
    let plan_doc = p.plan();
    assert_eq!(decision(&plan_doc, "mdf")["choice"]["use_mdf"], false);
    // The BTF: the raw model, or a basis predicted within the stage's half of the budget.
    let btf = decision(&plan_doc, "btf");
    assert!(
        btf["choice"]["model"] == "raw" || btf["predicted_error"].as_f64().unwrap() <= 0.025,
        "{btf}"
    );
    let g = p.graph();
    assert!(g["nodes"]["btf_view"]["inputs"].get("mdf").is_none());
    assert!(plan_doc["scene"]["shell_pixels"].as_f64().unwrap() < 0.5);
    let rep = run_planned(&s, &p);
    // The planned view renders from the same camera as the full one.
    assert_eq!(
        metric(&rep, "btf_view", "pixel_footprint_mm"),
        metric(&rep, "btf_full", "pixel_footprint_mm")
    );

    let near = sets([0.0, 1.5, 2.7]);
    let cheap = plan(&s, "cheap", &graph(), "btf_view", "flip=1e9", &near);
    assert_eq!(cheap.run.code, 0, "{}", cheap.run.stderr);
    let cheap_plan = cheap.plan();
    let d = decision(&cheap_plan, "btf");
    // A 16-texel tile: level 4 is one texel, the average BRDF, at rank 1.
    assert_eq!(d["choice"]["level"], 4.0);
    assert_eq!(d["choice"]["rank"], 1);
    let sss = plan(&s, "cheap_sss", &graph(), "sss_view", "flip=1e9", &near);
    assert_eq!(sss.run.code, 0, "{}", sss.run.stderr);
    assert_eq!(sss.graph()["nodes"]["sss_view"]["params"]["mode"], "brdf");
    let rep = run_planned(&s, &sss);
    assert!(metric(&rep, "sss_flip", "mean").is_finite());
}

#[test]
fn low_albedo_scattering_far_away_becomes_a_brdf_and_grazing_views_plan() {
    let s = Scratch::new();
    // Ketchup: its longest effective mean free path (red, σa 0.061 mm⁻¹) is about 5 mm; 45
    // units away (900 mm at 20 mm per unit) a pixel of the 48-pixel view covers about 20 mm.
    let mut far = sets([0.0, 22.0, 40.0]);
    far.push("skin.preset=ketchup".into());
    let p = plan(&s, "ketchup", &graph(), "sss_view", "flip=0.05", &far);
    assert_eq!(p.run.code, 0, "{}", p.run.stderr);
    assert_eq!(decision(&p.plan(), "sss")["choice"]["mode"], "brdf");
    assert!(p.plan()["scene"]["mfp_pixels"].as_f64().unwrap() < 0.5);
    run_planned(&s, &p);
    // Grazing: the camera in the torus's plane, just above it.
    let grazing = sets([0.0, 0.05, 3.0]);
    let g = plan(&s, "grazing", &graph(), "btf_view", "flip=0.05", &grazing);
    assert_eq!(g.run.code, 0, "{}", g.run.stderr);
    run_planned(&s, &g);
}

#[test]
fn a_camera_inside_and_bad_arguments_are_clear_errors() {
    let s = Scratch::new();
    // Inside the sphere (radius 0.8): everything visible is seen from behind.
    let inside = sets([0.0, 0.1, 0.2]);
    let p = plan(&s, "inside", &graph(), "sss_view", "flip=0.05", &inside);
    assert_eq!(p.run.code, 1, "{}", p.run.stderr);
    assert!(p.run.stderr.contains("inside"), "{}", p.run.stderr);
    let small = sets([0.0, 1.5, 2.7]);
    for (render, budget, code, text) in [
        ("btf_veiw", "flip=0.05", 2, "btf_view"),
        ("btf_flip", "flip=0.05", 2, "render.mesh"),
        ("btf_view", "psnr=30", 2, "flip"),
        ("btf_view", "flip=-1", 2, "≥ 0"),
        ("btf_view", "flip=x", 2, "number"),
    ] {
        let r = plan(&s, "bad", &graph(), render, budget, &small);
        assert_eq!(r.run.code, code, "{render} {budget}: {}", r.run.stderr);
        assert!(
            r.run.stderr.contains(text),
            "{render} {budget}: {}",
            r.run.stderr
        );
    }
}

#[test]
fn a_viewer_sets_the_pixels_per_degree_the_plan_is_read_at() {
    let s = Scratch::new();
    let near = sets([0.0, 1.5, 2.7]);
    let p = plan_with(
        &s,
        "ppd30",
        &graph(),
        "btf_view",
        "flip=0.05",
        &near,
        &["--ppd", "30"],
    );
    assert_eq!(p.run.code, 0, "{}", p.run.stderr);
    let doc = p.plan();
    assert_eq!(doc["budget"]["ppd"], 30.0);
    assert_eq!(doc["calibrated_ppd"], 30.0);
    assert!(doc.get("ppd_note").is_none(), "{doc}");
    // Half a metre from a half-metre-wide image 48 pixels across: 48·π/180 ≈ 0.84 pixels per
    // degree (image.flip's formula), below the sparsest calibrated 30: said so.
    let v = plan_with(
        &s,
        "viewer",
        &graph(),
        "btf_view",
        "flip=0.05",
        &near,
        &["--viewer", "0.5,0.5"],
    );
    assert_eq!(v.run.code, 0, "{}", v.run.stderr);
    let doc = v.plan();
    let ppd = doc["budget"]["ppd"].as_f64().unwrap();
    assert!(
        (ppd - 48.0 * std::f64::consts::PI / 180.0).abs() < 1e-9,
        "{ppd}"
    );
    assert_eq!(doc["calibrated_ppd"], 30.0);
    assert!(
        doc["ppd_note"].as_str().unwrap().contains("may be low"),
        "{doc}"
    );
    for (extra, text) in [
        (&["--ppd", "0.1"][..], "0.5"),
        (&["--viewer", "1"][..], "DIST_M,WIDTH_M"),
        (&["--viewer", "1,-2"][..], "positive"),
        (
            &["--ppd", "30", "--viewer", "1,1"][..],
            "cannot be used with",
        ),
    ] {
        let r = plan_with(
            &s,
            "bad_viewer",
            &graph(),
            "btf_view",
            "flip=0.05",
            &near,
            extra,
        );
        assert_eq!(r.run.code, 2, "{extra:?}: {}", r.run.stderr);
        assert!(r.run.stderr.contains(text), "{extra:?}: {}", r.run.stderr);
    }
}

/// graphs/plan_qh.json at test size, both renders' cameras at `eye`.
fn qh_sets(eye: [f64; 3]) -> Vec<String> {
    let mut v = vec![
        "surface.size=32".to_string(),
        format!("lrf.views={DIRS}"),
        format!("lrf.lights={DIRS}"),
        "torus.segments=[32,16]".into(),
        "entrance.width=128".into(),
        "entrance.height=128".into(),
        "entrance.patch_sizes=[8]".into(),
        "entrance.iterations=1".into(),
    ];
    for id in ["qh_full", "qh_view"] {
        v.push(format!(
            "{id}.camera.eye=[{},{},{}]",
            eye[0], eye[1], eye[2]
        ));
        v.push(format!("{id}.camera.resolution=[96,72]"));
        v.push(format!("{id}.shadow_resolution=128"));
        v.push(format!("{id}.max_points=3000"));
    }
    v
}

#[test]
fn a_synthesized_texture_stops_early_only_where_the_view_cannot_show_it() {
    let s = Scratch::new();
    let qh = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/plan_qh.json");
    // Near, the 128² texture (6 × 2 tiles on the torus) has under two texels per pixel: it is
    // synthesized in full.
    let near = plan(
        &s,
        "near",
        &qh,
        "qh_view",
        "flip=0.3",
        &qh_sets([0.0, 0.9, 1.5]),
    );
    assert_eq!(near.run.code, 0, "{}", near.run.stderr);
    let doc = near.plan();
    let tpp = doc["scene"]["textures"]["normals.preview"]["texels_per_pixel"]
        .as_f64()
        .unwrap();
    assert!(4.0 * tpp < 2.0, "{doc}");
    assert_eq!(
        decision(&doc, "synthesis")["choice"]["stop_level"],
        0,
        "{doc}"
    );
    assert_eq!(
        near.graph()["nodes"]["qh_view"]["inputs"]["entrance"],
        "entrance.image"
    );
    // Far, it has several per pixel: the synthesis stops a level early (64², the full run's own
    // coarser result), in a copy only the planned view reads, and the planned view stays within
    // the budget against the full model. The calibration measured stopping a level early at
    // FLIP 0.022–0.042 whatever the distance (the renderer point-samples the texture, so the two
    // textures' texels differ however small they look), so it fits a tenth only of budgets from
    // about 0.22 (0.27 at this view's texels per pixel).
    let far = plan(
        &s,
        "far",
        &qh,
        "qh_view",
        "flip=0.3",
        &qh_sets([0.0, 9.0, 16.0]),
    );
    assert_eq!(far.run.code, 0, "{}", far.run.stderr);
    let doc = far.plan();
    let d = decision(&doc, "synthesis");
    assert_eq!(d["choice"]["stop_level"], 1, "{doc}");
    assert_eq!(d["choice"]["size"], serde_json::json!([64, 64]));
    assert!(d["predicted_error"].as_f64().unwrap() <= 0.03, "{d}");
    let g = far.graph();
    assert_eq!(
        g["nodes"]["qh_view"]["inputs"]["entrance"],
        "plan_entrance.image"
    );
    assert_eq!(
        g["nodes"]["qh_full"]["inputs"]["entrance"],
        "entrance.image"
    );
    assert_eq!(g["nodes"]["plan_entrance"]["params"]["stop_level"], 1);
    let rep = run_planned(&s, &far);
    let flip = metric(&rep, "qh_flip", "mean");
    assert!(flip <= 0.3, "measured FLIP {flip} over the budget 0.3");
}
