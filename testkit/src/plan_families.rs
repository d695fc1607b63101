//! The planner as the arbiter over the scene families (issue 57): each scene planned with
//! `mesoflow plan --against truth --budget rmse=B` (or `flip=B`, judged on the full frame by mean
//! FLIP at the default pixels per degree over the truth's coverage), the planned graph run on the full frame
//! against the family's converged truth (the template's `truth`, independent of the planner's
//! probe), beside a fixed list of candidates rendered here on the full frame: the graph as given,
//! each model variant the plan lists, and brute force (`render.reference`, a seed apart from the
//! truth's) at the sample count that meets the budget, found here from its own noise. Used by
//! `benches/plan_families.rs` (held-out seeds, the table and charts).
//!
//! Bounds (issue 57's, fixed before the first run): the plan within the budget on ≥ 95 % of
//! scenes and every miss within 1.5× of it; never slower than the graph as given where that
//! meets the budget, nor than 1.2× the fastest listed candidate that meets it (both with 1.2×
//! for timing noise: each time is one run on a shared machine); planning at most twice the longer
//! of one full render of the graph and of brute force at the budget. The first held-out run
//! (BENCHMARKS.md) did not meet all of them, so no test tier holds them yet: the bench reports
//! every scene that breaks one.

use crate::cli;
use crate::scenes::{self, Kind, Scene};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// What a budget measures: relative RMSE with the truth's noise removed, or mean FLIP (at
/// `image.flip`'s default pixels per degree, the planner's when no viewer is given) over the
/// truth's coverage, the truth's own noise left in (it is converged: its noise is far under
/// the budgets).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Measure {
    Rmse,
    Flip,
}

impl Measure {
    /// `rmse` or `flip`, as `--budget` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Measure::Rmse => "rmse",
            Measure::Flip => "flip",
        }
    }

    /// Words for tables and charts.
    pub fn label(self) -> &'static str {
        match self {
            Measure::Rmse => "relative RMSE",
            Measure::Flip => "mean FLIP",
        }
    }

    /// `rmse` or `flip`.
    pub fn parse(s: &str) -> Option<Measure> {
        match s {
            "rmse" => Some(Measure::Rmse),
            "flip" => Some(Measure::Flip),
            _ => None,
        }
    }
}

/// The node that judges a render by FLIP in a FLIP run (added to the scene's graph).
const FLIP_JUDGE: &str = "judge_flip";

/// What a run over the families is asked for.
#[derive(Clone)]
pub struct Options {
    /// The frame every render is made at.
    pub resolution: [u32; 2],
    /// The truth's samples a pixel.
    pub samples: u32,
    /// The budgets, in `measure`.
    pub budgets: Vec<f64>,
    /// What the budgets measure.
    pub measure: Measure,
    /// Where each scene's graphs, runs and plans go (`seed-N/`), and the shared cache.
    pub out: PathBuf,
    /// `--set`s applied after the scene's own (test sizes).
    pub sets: Vec<String>,
}

/// One render on the full frame: its error against the truth in the run's measure (relative
/// RMSE with the truth's noise removed, or mean FLIP) and its node's own compute time.
#[derive(Clone, Debug)]
pub struct Rendered {
    pub name: String,
    pub family: String,
    pub error: Option<f64>,
    pub seconds: Option<f64>,
}

impl Rendered {
    pub fn fits(&self, budget: f64) -> bool {
        self.error.is_some_and(|e| e <= budget)
    }
}

/// One budget on one scene.
#[derive(Clone, Debug)]
pub struct Budgeted {
    pub budget: f64,
    /// The plan's choice (its candidate name and family), rendered from the planned graph.
    pub planned: Rendered,
    /// Brute force at the sample count found here to meet the budget, and that count.
    pub brute: Rendered,
    pub brute_samples: u32,
    /// `mesoflow plan`'s own wall time, s (its `plan_seconds`).
    pub plan_seconds: f64,
}

/// One scene: the graph as given, the model variants, and each budget.
#[derive(Clone, Debug)]
pub struct SceneRow {
    pub family: &'static str,
    pub seed: u64,
    pub name: String,
    pub given: Rendered,
    pub models: Vec<Rendered>,
    pub budgets: Vec<Budgeted>,
}

/// Timing noise allowed on one-run times (see the module's bounds).
pub const TIME_SLACK: f64 = 1.2;
/// The most a miss may exceed its budget by.
pub const MISS_SLACK: f64 = 1.5;
/// Planning time over the longer full render, at most.
pub const PLAN_RATIO: f64 = 2.0;

impl SceneRow {
    /// The fastest of the listed candidates (the models and brute force) within `b`'s budget.
    pub fn fastest_fit<'a>(&'a self, b: &'a Budgeted) -> Option<&'a Rendered> {
        self.models
            .iter()
            .chain(std::iter::once(&b.brute))
            .filter(|r| r.fits(b.budget) && r.seconds.is_some())
            .min_by(|x, y| {
                x.seconds
                    .unwrap_or(0.0)
                    .total_cmp(&y.seconds.unwrap_or(0.0))
            })
    }

    /// Planning time over the longer of the graph's and brute force's full render.
    pub fn plan_ratio(&self, b: &Budgeted) -> Option<f64> {
        let longest = self
            .given
            .seconds
            .into_iter()
            .chain(b.brute.seconds)
            .fold(0.0, f64::max);
        (longest > 0.0).then(|| b.plan_seconds / longest)
    }

    /// What `b` breaks of the bounds other than "within budget on 95 %" (which is over the
    /// family): each a sentence; empty when it holds them.
    pub fn failures(&self, b: &Budgeted) -> Vec<String> {
        let mut out = Vec::new();
        let (e, t) = (b.planned.error, b.planned.seconds);
        match e {
            None => out.push("the planned render has no error against the truth".into()),
            Some(e) if e > MISS_SLACK * b.budget => out.push(format!(
                "misses the budget {} by more than {MISS_SLACK}×: {e:.3}",
                b.budget
            )),
            _ => {}
        }
        if let (Some(t), Some(g)) = (t, self.given.seconds) {
            if self.given.fits(b.budget) && t > TIME_SLACK * g {
                out.push(format!(
                    "{t:.2} s, slower than the graph as given ({g:.2} s), which meets the budget"
                ));
            }
        }
        if let (Some(t), Some(f)) = (t, self.fastest_fit(b)) {
            let fs = f.seconds.unwrap_or(0.0);
            if t > TIME_SLACK * fs {
                out.push(format!(
                    "{t:.2} s, over {TIME_SLACK}× the fastest candidate within the budget ({}: {fs:.2} s)",
                    f.name
                ));
            }
        }
        if let Some(r) = self.plan_ratio(b) {
            if r > PLAN_RATIO {
                out.push(format!(
                    "planning took {:.1} s, {r:.2}× the longer full render (at most {PLAN_RATIO}×)",
                    b.plan_seconds
                ));
            }
        }
        out
    }
}

/// Relative file paths of the graph's readers made absolute against `base` (the template's
/// folder), so the graph runs from the scene's own folder.
fn absolute_paths(g: &mut Value, base: &Path) {
    if let Some(nodes) = g["nodes"].as_object_mut() {
        for n in nodes.values_mut() {
            let reader = n["kind"].as_str().is_some_and(|k| k.ends_with(".read"));
            if let Some(p) = n["params"]["path"].as_str().filter(|_| reader) {
                if Path::new(p).is_relative() {
                    n["params"]["path"] = json!(base.join(p).display().to_string());
                }
            }
        }
    }
}

fn write_json(path: &Path, v: &Value) {
    std::fs::create_dir_all(path.parent().expect("a folder")).expect("the scene's folder");
    std::fs::write(path, serde_json::to_string_pretty(v).expect("json")).expect("write a graph");
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Runs `graph` on the CPU into `out` with the shared cache; the report.
fn run(graph: &Path, out: &Path, cache: &Path) -> Value {
    cli::mesoflow(&[
        "run",
        graph.to_str().expect("utf-8 path"),
        "--quiet",
        "--device",
        "cpu",
        "--out-dir",
        out.to_str().expect("utf-8 path"),
        "--cache-dir",
        cache.to_str().expect("utf-8 path"),
    ]);
    read_json(&out.join("report.json"))
}

/// The render `ours`' error against the truth in `measure` and compute time in a report:
/// the render's own seconds, and its `sss.lighting`'s where it reads one (a candidate of the
/// plan computes its lighting inside the render, so the graph as given is charged for its own).
fn measured(report: &Value, graph: &Value, name: &str, family: &str, measure: Measure) -> Rendered {
    let m = |id: &str, k: &str| cli::node(report, id)["metrics"][k].as_f64();
    let error = match measure {
        Measure::Rmse => m("error", "relative_rmse").map(|raw| {
            let noise = m("truth", "noise").unwrap_or(0.0);
            (raw * raw - noise * noise).max(0.0).sqrt()
        }),
        Measure::Flip => m(FLIP_JUDGE, "mean"),
    };
    let secs = |id: &str| {
        let n = cli::node(report, id);
        n["timings"]["seconds"].as_f64().or(n["seconds"].as_f64())
    };
    let lighting = graph["nodes"]["ours"]["inputs"]["lighting"]
        .as_str()
        .and_then(|from| from.split_once('.'))
        .and_then(|(id, _)| secs(id));
    Rendered {
        name: name.into(),
        family: family.into(),
        error,
        seconds: secs("ours").map(|s| s + lighting.unwrap_or(0.0)),
    }
}

/// The node ids a graph's nodes read from.
fn read(g: &Value) -> std::collections::BTreeSet<String> {
    g["nodes"]
        .as_object()
        .into_iter()
        .flat_map(|nodes| nodes.values())
        .filter_map(|n| n.get("inputs").and_then(Value::as_object))
        .flat_map(|inputs| inputs.values())
        .filter_map(|v| v.as_str()?.split_once('.').map(|(id, _)| id.to_string()))
        .collect()
}

/// The scene's graph with `ours` replaced by `decl` (its kind, parameters and inputs), and
/// the error node reading render.reference's coverage where `ours` was render.mesh's mask.
/// What only the old `ours` read (brute force needs no BTF, an inlined lighting no lighting
/// node) is left out, so the run does not load it from the cache.
fn with_ours(g: &Value, decl: &Value) -> Value {
    let before = read(g);
    let mut g = g.clone();
    g["nodes"]["ours"] = decl.clone();
    loop {
        let now = read(&g);
        let orphans: Vec<String> = before.difference(&now).cloned().collect();
        let Some(nodes) = g["nodes"].as_object_mut() else {
            break;
        };
        let count = nodes.len();
        nodes.retain(|id, _| !orphans.contains(id));
        if nodes.len() == count {
            break;
        }
    }
    if decl["kind"] == "render.reference" {
        if let Some(nodes) = g["nodes"].as_object_mut() {
            for n in nodes.values_mut() {
                // `get_mut`, not indexing: indexing a missing key would insert a null.
                if let Some(inputs) = n.get_mut("inputs").and_then(Value::as_object_mut) {
                    for v in inputs.values_mut() {
                        if v == "ours.mask" {
                            *v = json!("ours.coverage");
                        }
                    }
                }
            }
        }
    }
    g
}

/// Brute force at `samples`: the template's truth with another seed and those samples.
fn brute_decl(g: &Value, samples: u32) -> Value {
    let mut d = g["nodes"]["truth"].clone();
    d["params"]["samples"] = json!(samples);
    let seed = d["params"]["seed"].as_u64().unwrap_or(1);
    d["params"]["seed"] = json!(seed + 7919);
    d
}

/// Plans, renders and measures one scene at every budget.
pub fn scene(kind: Kind, seed: u64, o: &Options) -> SceneRow {
    let scene: Scene = scenes::family(kind, seed);
    let dir = o.out.join(match o.measure {
        Measure::Rmse => format!("{}-{seed}", kind.name()),
        Measure::Flip => format!("{}-{seed}-flip", kind.name()),
    });
    let cache = o.out.join("cache");
    let mut g = scene.graph(o.resolution, o.samples);
    if o.measure == Measure::Flip {
        g["nodes"][FLIP_JUDGE] = json!({
            "kind": "image.flip",
            "inputs": {
                "reference": "truth.image",
                "test": "ours.image",
                "mask": "truth.coverage",
            },
        });
    }
    let template_dir = cli::repo().join(kind.template());
    let template_dir = template_dir.parent().expect("graphs/");
    absolute_paths(&mut g, template_dir);
    let graph = dir.join("graph.json");
    write_json(&graph, &g);
    if !o.sets.is_empty() {
        set(&graph, &o.sets);
        g = read_json(&graph);
    }
    let given = measured(
        &run(&graph, &dir.join("given"), &cache),
        &g,
        "the graph as given",
        "model",
        o.measure,
    );
    let mut models: Vec<Rendered> = Vec::new();
    let mut budgets = Vec::new();
    for &b in &o.budgets {
        let planned_path = dir.join(format!("planned-{b}.json"));
        cli::mesoflow(&[
            "plan",
            graph.to_str().expect("utf-8"),
            "--render",
            "ours",
            "--against",
            "truth",
            "--budget",
            &format!("{}={b}", o.measure.name()),
            "--device",
            "cpu",
            "-o",
            planned_path.to_str().expect("utf-8"),
            "--cache-dir",
            cache.to_str().expect("utf-8"),
        ]);
        let doc = read_json(&dir.join(format!("planned-{b}.plan.json")));
        if models.is_empty() {
            // The model variants the plan lists, each rendered on the full frame (the first is
            // the graph as given: a cache hit).
            for c in doc["candidates"].as_array().into_iter().flatten() {
                if c["family"] != "model" {
                    continue;
                }
                let name = c["candidate"].as_str().unwrap_or("?").to_string();
                let decl =
                    json!({ "kind": c["kind"], "params": c["params"], "inputs": c["inputs"] });
                let path = dir.join(format!("model-{}.json", models.len()));
                let model = with_ours(&g, &decl);
                write_json(&path, &model);
                let out = dir.join(format!("model-{}", models.len()));
                models.push(measured(
                    &run(&path, &out, &cache),
                    &model,
                    &name,
                    "model",
                    o.measure,
                ));
            }
        }
        let chosen = doc["chosen"].as_str().unwrap_or("nothing").to_string();
        let family = doc["candidates"]
            .as_array()
            .and_then(|cs| cs.iter().find(|c| c["candidate"] == chosen.as_str()))
            .and_then(|c| c["family"].as_str())
            .unwrap_or("?")
            .to_string();
        // A planned brute force on the truth's own seed would share its first samples' noise
        // and look better than it is: measured on another seed (the same samples a pixel).
        let mut planned_graph = read_json(&planned_path);
        let truth_seed = planned_graph["nodes"]["truth"]["params"]["seed"].clone();
        let ours = &mut planned_graph["nodes"]["ours"];
        if ours["kind"] == "render.reference" && ours["params"]["seed"] == truth_seed {
            ours["params"]["seed"] = json!(truth_seed.as_u64().unwrap_or(1) + 15_485_863);
        }
        let measured_path = dir.join(format!("planned-{b}-measured.json"));
        write_json(&measured_path, &planned_graph);
        let mut planned = measured(
            &run(&measured_path, &dir.join(format!("planned-{b}")), &cache),
            &planned_graph,
            &chosen,
            &family,
            o.measure,
        );
        // The render as given leaves the graph as it is: its nodes come from the cache the
        // graph's own run filled, so its time is that run's.
        if chosen == "the render as given" {
            planned.seconds = given.seconds;
        }
        let (brute, brute_samples) = brute_at(&g, b, o.measure, o.samples, &dir, &cache);
        budgets.push(Budgeted {
            budget: b,
            planned,
            brute,
            brute_samples,
            plan_seconds: doc["plan_seconds"].as_f64().unwrap_or(f64::NAN),
        });
    }
    SceneRow {
        family: kind.name(),
        seed,
        name: scene.name(),
        given,
        models,
        budgets,
    }
}

/// The `--set`s (`ID.PARAM[.KEY…]=VALUE`, test sizes) written into the graph file, applied as
/// the command line applies them (`mesoflow_graph::parse_override`, `GraphFile::apply`).
fn set(graph: &Path, sets: &[String]) {
    let text = std::fs::read_to_string(graph).expect("the scene's graph");
    let mut file = mesoflow_graph::GraphFile::parse(&text).expect("a scene's graph parses");
    for s in sets {
        let o = mesoflow_graph::parse_override(s).unwrap_or_else(|e| panic!("--set {e}"));
        file.apply(&o).unwrap_or_else(|e| panic!("{e}"));
    }
    std::fs::write(graph, file.to_json()).expect("write a graph");
}

/// Brute force at the samples that meet `budget`: a pilot at 4 samples a pixel gives its
/// noise constant (relative RMSE falls as 1/√samples; FLIP is aimed as if it did, then once
/// along the slope two renders measured), then the count it asks for with 10 % to spare,
/// doubled until it fits (at most three times); for FLIP never past the truth's own samples
/// (`most`): FLIP cannot take the truth's noise out, so past them brute force measures the
/// truth's noise, not its own.
fn brute_at(
    g: &Value,
    budget: f64,
    measure: Measure,
    most: u32,
    dir: &Path,
    cache: &Path,
) -> (Rendered, u32) {
    let most = match measure {
        Measure::Rmse => 1 << 16,
        Measure::Flip => most.max(1),
    };
    let render = |samples: u32| {
        let path = dir.join(format!("brute-{samples}.json"));
        let brute = with_ours(g, &brute_decl(g, samples));
        write_json(&path, &brute);
        let name = format!("brute force at {samples} samples a pixel");
        measured(
            &run(&path, &dir.join(format!("brute-{samples}")), cache),
            &brute,
            &name,
            "brute force",
            measure,
        )
    };
    let pilot_samples = 4;
    let pilot = render(pilot_samples);
    let mut samples = match pilot.error {
        Some(e) if e > 0.0 => {
            ((pilot_samples as f64 * 1.1 * (e / budget).powi(2)).ceil() as u32).clamp(1, most)
        }
        _ => pilot_samples,
    };
    if samples == pilot_samples {
        return (pilot, samples);
    }
    let mut r = render(samples);
    // FLIP does not fall as 1/√samples: re-aimed once along the slope the pilot and the first
    // render measured (with 10 % to spare) before doubling.
    if let (Measure::Flip, Some(e0), Some(e)) = (measure, pilot.error, r.error) {
        let slope = (e0 / e).ln() / (samples as f64 / pilot_samples as f64).ln();
        if !r.fits(budget) && e0 > e && slope > 0.05 && samples < most {
            let more = (e / (0.9 * budget)).powf(1.0 / slope).min(16.0);
            samples = ((samples as f64 * more).ceil() as u32).clamp(samples + 1, most);
            r = render(samples);
        }
    }
    for _ in 0..3 {
        if r.fits(budget) {
            break;
        }
        if samples >= most {
            break;
        }
        samples = (samples * 2).min(most);
        r = render(samples);
    }
    (r, samples)
}
