//! `mesoflow plan --against truth` (issue 57) on the translucent family's template at test size:
//! the truth probe is made from the graph's own mesh and medium; every candidate, the render as
//! given, its model switches and brute force, is measured against it; the plan is the fastest
//! within the budget. At a budget no model reaches, brute force is planned (a planner that never
//! plans brute force fails here); at a lax one a model is, the fastest that fits (a planner that
//! keeps the graph, or takes the cheapest whatever its error, fails here); the planned graph runs.
//! The same for `render.mesh` whose BTF the graph captures from a height field: the truth is that
//! height field displaced and path traced; brute force is planned with the displaced surface.
//! A render the truth cannot be made for is a clear error.

use crate::common::{mesoflow, run, Scratch};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn graph() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/family_translucent.json")
}

/// Seed 0 of the family (a skim-milk sphere lit from the front) at test size.
const SETS: [&str; 5] = [
    "mesh.segments=[32,16]",
    "ours.camera.resolution=[32,24]",
    "lighting.max_points=2000",
    "lighting.shadow_resolution=128",
    "truth.camera.resolution=[32,24]",
];

fn plan(s: &Scratch, budget: &str) -> (Value, Value) {
    plan_named(s, &graph(), "planned", budget, &SETS)
}

/// `mesoflow plan GRAPH --render ours --against truth --budget BUDGET --probe-share 0.5` with
/// `sets`, into `<stem>-<budget>.json` in the scratch folder: the plan document and the planned
/// graph.
fn plan_named(
    s: &Scratch,
    graph: &Path,
    stem: &str,
    budget: &str,
    sets: &[&str],
) -> (Value, Value) {
    let out = s.path(&format!("{stem}-{budget}.json"));
    let cache = s.path("cache");
    let mut args = vec![
        "plan",
        graph.to_str().unwrap(),
        "--render",
        "ours",
        "--against",
        "truth",
        "--budget",
        budget,
        "--probe-share",
        "0.5",
        "-o",
        out.to_str().unwrap(),
        "--cache-dir",
        cache.to_str().unwrap(),
    ];
    for set in sets {
        args.extend(["--set", set]);
    }
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let doc: Value = serde_json::from_str(
        &std::fs::read_to_string(s.path(&format!("{stem}-{budget}.plan.json"))).unwrap(),
    )
    .unwrap();
    let planned: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    (doc, planned)
}

fn candidates(doc: &Value) -> &Vec<Value> {
    doc["candidates"].as_array().expect("candidates")
}

/// The chosen candidate, asserted to be the fastest of at least two within the budget (a
/// planner that keeps the graph, or takes the cheapest whatever its error, fails here).
fn fastest_of_several_within_budget(doc: &Value) -> &Value {
    let fits: Vec<&Value> = candidates(doc)
        .iter()
        .filter(|c| c["within_budget"] == true)
        .collect();
    assert!(fits.len() >= 2, "{doc}");
    let fastest = fits
        .iter()
        .map(|c| c["full_seconds_estimate"].as_f64().unwrap())
        .fold(f64::INFINITY, f64::min);
    let c = chosen(doc);
    assert_eq!(
        c["full_seconds_estimate"].as_f64().unwrap(),
        fastest,
        "{doc}"
    );
    c
}

fn chosen(doc: &Value) -> &Value {
    let name = doc["chosen"].as_str().expect("a chosen candidate");
    candidates(doc)
        .iter()
        .find(|c| c["candidate"] == name)
        .expect("the chosen is a candidate")
}

/// The acceptance a plan is held to, on the candidates its document measured: the choice is
/// within the budget where any candidate is, and the fastest of those (by the estimates the
/// candidates were measured at). `pick` is the planner: the name of its choice.
fn accepted(doc: &Value, pick: &dyn Fn(&[Value]) -> Option<String>) -> Result<(), String> {
    let all = candidates(doc);
    let (key, budget) = error_key(doc);
    let name = pick(all).ok_or("nothing chosen")?;
    let c = all
        .iter()
        .find(|c| c["candidate"] == name.as_str())
        .ok_or("not a candidate")?;
    let time = |c: &Value| c["full_seconds_estimate"].as_f64().unwrap_or(f64::INFINITY);
    let fits: Vec<&Value> = all.iter().filter(|c| c["within_budget"] == true).collect();
    if fits.is_empty() {
        return Ok(());
    }
    if c[key].as_f64().is_none_or(|e| e > budget) {
        return Err(format!("{name} misses the budget {budget}"));
    }
    let fastest = fits.iter().map(|c| time(c)).fold(f64::INFINITY, f64::min);
    if time(c) > fastest {
        return Err(format!(
            "{name} is slower than the fastest within the budget"
        ));
    }
    Ok(())
}

/// The candidates' error key and the budget: relative RMSE or FLIP.
fn error_key(doc: &Value) -> (&'static str, f64) {
    match doc["budget"]["flip"].as_f64() {
        Some(b) => ("flip", b),
        None => (
            "relative_rmse",
            doc["budget"]["relative_rmse"].as_f64().unwrap(),
        ),
    }
}

/// A planner: the name of the candidate it chooses from a plan's measured candidates.
type Planner = Box<dyn Fn(&[Value]) -> Option<String>>;

/// The planners a test must tell from the real one.
fn bad_planners() -> Vec<(&'static str, Planner)> {
    let name = |c: &Value| c["candidate"].as_str().map(String::from);
    let time = |c: &&Value| c["full_seconds_estimate"].as_f64().unwrap_or(f64::INFINITY);
    let error = |c: &&Value| {
        c["relative_rmse"]
            .as_f64()
            .or(c["flip"].as_f64())
            .unwrap_or(f64::INFINITY)
    };
    vec![
        (
            "never simplifies (the render as given)",
            Box::new(move |all: &[Value]| all.first().and_then(name)),
        ),
        (
            "always the cheapest, whatever its error",
            Box::new(move |all: &[Value]| {
                all.iter()
                    .min_by(|a, b| time(a).total_cmp(&time(b)))
                    .and_then(name)
            }),
        ),
        (
            "never brute force (the best model)",
            Box::new(move |all: &[Value]| {
                let models = all.iter().filter(|c| c["family"] == "model");
                let fits: Vec<&Value> = models
                    .clone()
                    .filter(|c| c["within_budget"] == true)
                    .collect();
                if fits.is_empty() {
                    models
                        .min_by(|a, b| error(a).total_cmp(&error(b)))
                        .and_then(name)
                } else {
                    fits.into_iter()
                        .min_by(|a, b| time(a).total_cmp(&time(b)))
                        .and_then(name)
                }
            }),
        ),
    ]
}

/// Each bad planner fails the acceptance on at least one of the budgets the real one passes.
fn bad_planners_fail(docs: &[&Value]) {
    for doc in docs {
        let chosen = doc["chosen"].as_str().map(String::from);
        accepted(doc, &|_| chosen.clone()).unwrap_or_else(|e| panic!("the planner: {e}\n{doc}"));
    }
    for (what, planner) in bad_planners() {
        assert!(
            docs.iter().any(|doc| accepted(doc, planner.as_ref()).is_err()),
            "a planner that {what} passes the acceptance: the test cannot tell it from the real one"
        );
    }
}

#[test]
fn the_truth_judges_every_family_and_the_fastest_within_budget_is_planned() {
    let s = Scratch::new();
    // Tight: the models are 0.14-0.21 from the truth over the family; only brute force fits.
    let (doc, planned) = plan(&s, "rmse=0.06");
    let tight = doc.clone();
    assert_eq!(doc["judge"], "truth");
    // The planning time, and its ratio to the longer full render (the graph as given or
    // brute force), are reported.
    let ratio = doc["plan_time"]["ratio"].as_f64().expect("plan_time.ratio");
    assert!(ratio > 0.0 && ratio.is_finite(), "{doc}");
    assert!(
        doc["truth"]["noise"].as_f64().unwrap() <= 0.06 / 3.0,
        "{doc}"
    );
    let all = candidates(&doc);
    assert!(all.len() >= 5, "{doc}");
    let brute = all
        .iter()
        .find(|c| c["family"] == "brute force")
        .expect("brute force is a candidate");
    assert_eq!(brute["kind"], "render.reference");
    let c = chosen(&doc);
    assert_eq!(c["family"], "brute force", "{doc}");
    assert!(c["relative_rmse"].as_f64().unwrap() <= 0.06, "{doc}");
    assert!(
        all.iter()
            .filter(|c| c["family"] == "model")
            .all(|c| c["within_budget"] == false),
        "a model within 0.06 here would make this test not a test of brute force: {doc}"
    );
    assert_eq!(planned["nodes"]["ours"]["kind"], "render.reference");
    // The lighting and the profile fed only the render: pruned.
    assert!(planned["nodes"].get("lighting").is_none(), "{planned}");
    // The render as given reads the graph's lighting node, as the graph does (the planner
    // computed it as that node: the graph's own run finds it in the cache), and is charged
    // its time.
    let given = &all[0];
    assert_eq!(given["candidate"], "the render as given", "{doc}");
    assert_eq!(given["inputs"]["lighting"], "lighting.lighting", "{doc}");
    let cache = s.path("cache");
    let mut extra = vec![
        "--output",
        "lighting.lighting",
        "--cache-dir",
        cache.to_str().unwrap(),
    ];
    for set in SETS {
        extra.extend(["--set", set]);
    }
    let (r, report) = run(&s, &graph(), "lighting-run", &extra);
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let lighting = mesoflow_testkit::cli::node(&report, "lighting");
    assert_ne!(lighting["status"], "computed", "{lighting}");
    let lit = lighting["timings"]["seconds"].as_f64().expect("its time");
    let probe = given["probe_seconds"]
        .as_f64()
        .expect("the candidate's time");
    assert!(
        probe >= lit,
        "{probe} s, under the lighting's {lit} s: {doc}"
    );

    // Lax: several candidates fit; the plan is the fastest of them, not the graph by default
    // and not the cheapest whatever its error.
    let (doc, planned) = plan(&s, "rmse=0.5");
    let c = fastest_of_several_within_budget(&doc);
    assert!(c["relative_rmse"].as_f64().unwrap() <= 0.5);
    assert_eq!(planned["nodes"]["ours"]["kind"], c["kind"]);
    bad_planners_fail(&[&tight, &doc]);

    // The planned graph runs and renders the view.
    run_planned(&s, "planned-rmse=0.5.json");
}

/// Runs a planned graph of the scratch folder (its render's image), which must succeed.
fn run_planned(s: &Scratch, file: &str) {
    let r = mesoflow(
        &[
            "run",
            s.path(file).to_str().unwrap(),
            "--output",
            "ours.image",
            "--quiet",
            "--out-dir",
            s.path("out").to_str().unwrap(),
            "--cache-dir",
            s.path("cache").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
}

#[test]
fn a_render_without_a_truth_and_an_unknown_budget_against_the_truth_are_clear_errors() {
    let s = Scratch::new();
    // qh.render: no single homogeneous medium stands for its measured material.
    let qh = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/plan_qh.json");
    let r = mesoflow(
        &[
            "plan",
            qh.to_str().unwrap(),
            "--render",
            "qh_view",
            "--against",
            "truth",
            "--budget",
            "rmse=0.1",
            "--cache-dir",
            s.path("cache").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("truth is not built"), "{}", r.stderr);
    assert!(r.stderr.contains("flip=B"), "{}", r.stderr);
    // With a FLIP budget it falls back to the graph's own model, and the plan says so and why.
    let out = s.path("qh.planned.json");
    let r = mesoflow(
        &[
            "plan",
            qh.to_str().unwrap(),
            "--render",
            "qh_view",
            "--against",
            "truth",
            "--budget",
            "flip=0.1",
            "--probe-budget",
            "0",
            "-o",
            out.to_str().unwrap(),
            "--cache-dir",
            s.path("cache").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(s.path("qh.plan.json")).unwrap()).unwrap();
    assert_eq!(doc["judge"], "model", "{doc}");
    let why = doc["judge_why"].as_str().unwrap_or("");
    assert!(why.contains("truth is not built"), "{doc}");
    let r = mesoflow(
        &[
            "plan",
            graph().to_str().unwrap(),
            "--render",
            "ours",
            "--against",
            "truth",
            "--budget",
            "psnr=30",
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("rmse=B") && r.stderr.contains("flip=B"),
        "{}",
        r.stderr
    );
}

/// `--budget flip=B` against the truth: every measured candidate has its mean FLIP against the
/// truth probe at the view's pixels per degree, and the plan is held to the same acceptance as
/// the relative RMSE's (within the budget where any candidate is, the fastest of those), which
/// the bad planners fail on one of a tight and a lax budget.
#[test]
fn a_flip_budget_is_judged_against_the_truth_too() {
    let s = Scratch::new();
    let mut docs = Vec::new();
    // Tight: the models are 0.10–0.12 from the truth here, brute force at 65 samples 0.07.
    for budget in ["flip=0.08", "flip=0.5"] {
        let (doc, _) = plan(&s, budget);
        assert_eq!(doc["judge"], "truth");
        let b = &doc["budget"];
        assert!(
            b["flip"].as_f64().is_some() && b["ppd"].as_f64().is_some(),
            "{doc}"
        );
        for c in candidates(&doc)
            .iter()
            .filter(|c| c["probe_seconds"].is_number())
        {
            let f = c["flip"].as_f64().unwrap_or(f64::NAN);
            // FLIP is in [0, 1] by construction.
            assert!((0.0..=1.0).contains(&f), "{c}");
        }
        // The probe is the whole view at a lower resolution (`sss.render`), where FLIP of noise
        // is not the frame's: brute force's FLIP is the full view's, from two full-view pilots,
        // and says so with its figures.
        let brute = candidates(&doc)
            .iter()
            .find(|c| c["family"] == "brute force" && c["probe_seconds"].is_number())
            .unwrap_or_else(|| panic!("no measured brute force: {doc}"));
        let said = brute["warnings"].to_string();
        assert!(said.contains("two full-view pilots"), "{brute}");
        docs.push(doc);
    }
    let (tight, lax) = (&docs[0], &docs[1]);
    assert_eq!(chosen(tight)["family"], "brute force", "{tight}");
    fastest_of_several_within_budget(lax);
    bad_planners_fail(&[tight, lax]);
}

/// A small mesostructure scene: a bumps tile captured at a few directions (so that every model
/// is visibly off the truth), its MDF, a sphere, 40 × 30; only the image is read from the render.
fn mesh_graph(s: &Scratch) -> PathBuf {
    let dirs = serde_json::json!({ "thetas": [0, 30, 60], "phis": [0, 90, 180, 270] });
    let camera = serde_json::json!({ "eye": [0.0, 0.8, 2.6], "target": [0.0, 0.0, 0.0], "fov": 40.0, "resolution": [40, 30] });
    let g = serde_json::json!({
        "mesoflow": 1,
        "nodes": {
            "surface": { "kind": "heightfield.procedural", "params": { "pattern": "bumps", "size": 16, "count": 2, "depth": 3.0 } },
            "capture": { "kind": "btf.capture", "inputs": { "height": "surface.height" },
                         "params": { "views": dirs, "lights": dirs, "albedo": [0.7, 0.5, 0.3] } },
            "mdf": { "kind": "mdf.tabulate", "inputs": { "height": "surface.height" },
                     "params": { "depth": 3.0, "views": dirs } },
            "sphere": { "kind": "mesh.primitive", "params": { "shape": "sphere", "size": 0.8, "segments": [32, 16] } },
            "ours": { "kind": "render.mesh", "inputs": { "mesh": "sphere.mesh", "btf": "capture.btf", "mdf": "mdf.mdf" },
                      "params": { "camera": camera, "light": { "direction": [0.5, 0.6, 0.6], "intensity": 3.0 },
                                  "tiling": [6.0, 3.0], "shell": 0.04, "shadows": true, "shadow_resolution": 128 } },
            "picture": { "kind": "image.write", "inputs": { "image": "ours.image" }, "params": { "path": "ours.exr" } }
        }
    });
    let path = s.path("mesh.json");
    std::fs::write(&path, g.to_string()).unwrap();
    path
}

fn plan_mesh(s: &Scratch, graph: &Path, budget: &str) -> (Value, Value) {
    plan_named(s, graph, "mesh", budget, &[])
}

#[test]
fn a_captured_mesostructure_is_judged_against_its_displaced_truth() {
    let s = Scratch::new();
    let graph = mesh_graph(&s);
    // Tight: the BTF from 12 × 12 directions is far from the truth; only brute force fits.
    let (doc, planned) = plan_mesh(&s, &graph, "rmse=0.05");
    let tight = doc.clone();
    assert_eq!(doc["judge"], "truth");
    assert!(
        doc["judge_why"].as_str().unwrap().contains("mesh.displace"),
        "{doc}"
    );
    let all = candidates(&doc);
    let models: Vec<&Value> = all.iter().filter(|c| c["family"] == "model").collect();
    // As given, shadows off, the other interpolation, without the MDF.
    assert_eq!(models.len(), 4, "{doc}");
    assert!(
        models.iter().all(|c| c["within_budget"] == false),
        "a model within 0.05 here would make this test not a test of brute force: {doc}"
    );
    let c = chosen(&doc);
    assert_eq!(c["family"], "brute force", "{doc}");
    assert!(c["relative_rmse"].as_f64().unwrap() <= 0.05, "{doc}");
    // The brute-force plan traces the displaced surface, the capture and the MDF pruned.
    assert_eq!(planned["nodes"]["ours"]["kind"], "render.reference");
    assert_eq!(
        planned["nodes"]["ours"]["inputs"]["mesh"],
        "plan_true_surface.mesh"
    );
    assert_eq!(
        planned["nodes"]["plan_true_surface"]["kind"],
        "mesh.displace"
    );
    assert!(planned["nodes"].get("capture").is_none(), "{planned}");
    assert!(planned["nodes"].get("mdf").is_none(), "{planned}");
    let run = |path: &Path| {
        let r = mesoflow(
            &[
                "run",
                path.to_str().unwrap(),
                "--quiet",
                "--out-dir",
                s.path("out").to_str().unwrap(),
                "--cache-dir",
                s.path("cache").to_str().unwrap(),
            ],
            s.dir.path(),
        );
        assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    };
    run(&s.path("mesh-rmse=0.05.json"));

    // Lax: the fastest candidate within it, a model.
    let (doc, planned) = plan_mesh(&s, &graph, "rmse=0.9");
    let c = fastest_of_several_within_budget(&doc);
    assert_eq!(planned["nodes"]["ours"]["kind"], c["kind"]);
    run(&s.path("mesh-rmse=0.9.json"));
    bad_planners_fail(&[&tight, &doc]);
}

/// The same scene under the procedural sky: the truth probe is path traced under the sky (the
/// environment sampled by its radiance), every candidate is measured under it, and the planned
/// graph, brute force at a budget no model meets, keeps the sky and runs.
#[test]
fn a_mesostructure_under_an_environment_is_planned_against_its_truth() {
    let s = Scratch::new();
    let path = mesh_graph(&s);
    let mut g: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    g["nodes"]["ours"]["params"]["light"] = serde_json::json!({ "sky": {}, "intensity": 3.0 });
    let graph = s.path("sky.json");
    std::fs::write(&graph, g.to_string()).unwrap();
    let (doc, planned) = plan_named(&s, &graph, "sky", "rmse=0.05", &[]);
    assert_eq!(doc["judge"], "truth", "{doc}");
    let c = chosen(&doc);
    assert_eq!(c["family"], "brute force", "{doc}");
    assert_eq!(planned["nodes"]["ours"]["kind"], "render.reference");
    assert!(
        planned["nodes"]["ours"]["params"]["light"]["sky"].is_object(),
        "{planned}"
    );
    run_planned(&s, "sky-rmse=0.05.json");
}
