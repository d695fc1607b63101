//! `mesoflow plan --against truth` (issue 57) on the translucent family's template at test size:
//! the truth probe is made from the graph's own mesh and medium; every candidate, the render as
//! given, its model switches and brute force, is measured against it; the plan is the fastest
//! within the budget. At a budget no model reaches, brute force is planned (a planner that never
//! plans brute force fails here); at a lax one a model is, the fastest that fits (a planner that
//! keeps the graph, or takes the cheapest whatever its error, fails here); the planned graph runs.
//! A render the truth cannot be made for is a clear error.

use crate::common::{mesoflow, Scratch};
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
    let out = s.path(&format!("planned-{budget}.json"));
    let graph = graph();
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
    ];
    let cache = s.path("cache");
    args.push(cache.to_str().unwrap());
    for set in SETS {
        args.extend(["--set", set]);
    }
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let doc: Value = serde_json::from_str(
        &std::fs::read_to_string(s.path(&format!("planned-{budget}.plan.json"))).unwrap(),
    )
    .unwrap();
    let planned: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    (doc, planned)
}

fn candidates(doc: &Value) -> &Vec<Value> {
    doc["candidates"].as_array().expect("candidates")
}

fn chosen(doc: &Value) -> &Value {
    let name = doc["chosen"].as_str().expect("a chosen candidate");
    candidates(doc)
        .iter()
        .find(|c| c["candidate"] == name)
        .expect("the chosen is a candidate")
}

#[test]
fn the_truth_judges_every_family_and_the_fastest_within_budget_is_planned() {
    let s = Scratch::new();
    // Tight: the models are 0.14-0.21 from the truth over the family; only brute force fits.
    let (doc, planned) = plan(&s, "rmse=0.06");
    assert_eq!(doc["judge"], "truth");
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

    // Lax: several candidates fit; the plan is the fastest of them, not the graph by default
    // and not the cheapest whatever its error.
    let (doc, planned) = plan(&s, "rmse=0.5");
    let fits: Vec<&Value> = candidates(&doc)
        .iter()
        .filter(|c| c["within_budget"] == true)
        .collect();
    assert!(fits.len() >= 2, "{doc}");
    let fastest = fits
        .iter()
        .map(|c| c["full_seconds_estimate"].as_f64().unwrap())
        .fold(f64::INFINITY, f64::min);
    let c = chosen(&doc);
    assert_eq!(
        c["full_seconds_estimate"].as_f64().unwrap(),
        fastest,
        "{doc}"
    );
    assert!(c["relative_rmse"].as_f64().unwrap() <= 0.5);
    assert_eq!(planned["nodes"]["ours"]["kind"], c["kind"]);

    // The planned graph runs and renders the view.
    let path = s.path("planned-rmse=0.5.json");
    let r = mesoflow(
        &[
            "run",
            path.to_str().unwrap(),
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
fn a_render_without_a_truth_and_a_flip_budget_against_the_truth_are_clear_errors() {
    let s = Scratch::new();
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/mdf_render.json");
    let r = mesoflow(
        &[
            "plan",
            mesh.to_str().unwrap(),
            "--render",
            "torus_mdf",
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
    assert!(r.stderr.contains("truth is not built yet"), "{}", r.stderr);
    let r = mesoflow(
        &[
            "plan",
            graph().to_str().unwrap(),
            "--render",
            "ours",
            "--against",
            "truth",
            "--budget",
            "flip=0.1",
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("rmse=B"), "{}", r.stderr);
}
