//! The planner as the arbiter (issue 57): `mesoflow plan --against truth --budget rmse=B`. Where
//! the graph can make the truth itself — an `sss.render` whose mesh and medium are in the graph:
//! volumetric path tracing of the same mesh filled with the same medium (`render.reference`) —
//! every candidate, across model families, is measured against that truth on a probe of the
//! user's own view, and the cheapest within the budget wins, brute force included:
//!
//! - the render as given (its `sss.lighting`'s parameters, where it has one, inlined);
//! - the model switches that exist: `energy: half_space`, `geometry: exit_normal`, Jensen &
//!   Buhler's classic configuration, `mode: brdf`;
//! - brute force: `render.reference` with the medium at the samples a pixel its own measured
//!   noise says meet the budget (noise falls as 1/√samples: a 16-sample pilot measures the
//!   constant, the candidate asks for 0.8 of the budget).
//!
//! The truth probe is rendered at enough samples that its own noise is a third of the budget or
//! less (from 256 a pixel, raised from its measured noise, at most [`MOST_TRUTH_SAMPLES`]); each
//! candidate's error is its relative RMSE against it over the truth's coverage with the truth's
//! noise taken out (the families' measure). The probe is the centre of the view at the same pixels
//! per degree (`verify::probe_camera`); each candidate's time on the full view is estimated from
//! its probe: brute force in proportion to the pixels, `sss.render` as its camera-independent part
//! once plus its per-pixel stages (gather and shading) in proportion. Where no candidate meets the
//! budget the most accurate is chosen and the plan says so.
//!
//! `render.mesh` and `qh.render` have no truth here yet (`mesh.displace` of the height field behind
//! `btf.capture`, a medium for a quasi-homogeneous material): asking is an error that says so.

use crate::verify::{camera_of, probe_camera, run_for as run};
use crate::PlanError;
use mesoflow_graph::{GraphFile, NodeDecl};
use mesoflow_runtime::{Engine, NodeStatus, RunOptions, RunReport};
use serde_json::{json, Map, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

/// The truth probe's node.
pub const TRUTH: &str = "plan_truth";
/// The candidate's node and its comparison.
pub const CANDIDATE: &str = "plan_candidate";
const COMPARE: &str = "plan_candidate_error";
/// The truth's samples a pixel at most (its noise then decides nothing more).
pub const MOST_TRUTH_SAMPLES: u32 = 16_384;
/// The truth's first samples a pixel.
const TRUTH_SAMPLES: u32 = 256;
/// The brute-force pilot's samples a pixel.
const PILOT: u32 = 16;
/// Brute force aims at this share of the budget (its error is its noise, which the pilot
/// estimates from one run).
const AIM: f64 = 0.8;

/// How the arbiter judges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthOptions {
    /// The budget: relative RMSE against the truth over the pixels it covers.
    pub rmse: f64,
    /// The probe's share of the view's pixels, in (0, 1].
    pub share: f64,
}

/// One candidate as measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    pub name: String,
    /// `model` or `brute force`.
    pub family: &'static str,
    /// The render node it would be, at the view's own camera.
    pub decl: NodeDecl,
    /// Relative RMSE against the truth probe, the truth's noise removed (absent where the
    /// probe showed nothing or it failed).
    pub error: Option<f64>,
    /// Its render on the probe, s, and estimated on the full view.
    pub probe_s: Option<f64>,
    pub full_s: Option<f64>,
    pub fits: bool,
    /// Why it was not measured or cannot be used, where so.
    pub note: Option<String>,
}

/// The outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Arbitration {
    pub render: String,
    pub budget: f64,
    pub resolution: [u32; 2],
    pub share: f64,
    pub truth_samples: u32,
    pub truth_noise: Option<f64>,
    pub candidates: Vec<Candidate>,
    pub chosen: Option<usize>,
    pub why: String,
    pub planned: GraphFile,
    pub plan_s: f64,
}

impl Arbitration {
    pub fn to_json(&self) -> Value {
        let candidates: Vec<Value> = self
            .candidates
            .iter()
            .map(|c| {
                let mut o = Map::new();
                o.insert("candidate".into(), json!(c.name));
                o.insert("family".into(), json!(c.family));
                o.insert("kind".into(), json!(c.decl.kind));
                o.insert("params".into(), Value::Object(c.decl.params.clone()));
                for (k, v) in [
                    ("relative_rmse", c.error),
                    ("probe_seconds", c.probe_s),
                    ("full_seconds_estimate", c.full_s),
                ] {
                    if let Some(v) = v {
                        o.insert(k.into(), json!(v));
                    }
                }
                o.insert("within_budget".into(), json!(c.fits));
                if let Some(n) = &c.note {
                    o.insert("note".into(), json!(n));
                }
                Value::Object(o)
            })
            .collect();
        let mut doc = json!({
            "render": self.render,
            "judge": "truth",
            "judge_why": "the graph holds the mesh and the medium: the truth is volumetric path tracing of them (render.reference)",
            "budget": { "relative_rmse": self.budget },
            "probe": { "resolution": self.resolution, "share": self.share },
            "truth": { "samples": self.truth_samples },
            "candidates": candidates,
            "chosen": self.chosen.map_or(json!(null), |i| json!(self.candidates[i].name)),
            "why": self.why,
            "plan_seconds": self.plan_s,
        });
        if let Some(n) = self.truth_noise {
            doc["truth"]["noise"] = json!(n);
        }
        doc
    }
}

/// The nodes `ids` need, in the file's order.
fn needed(file: &GraphFile, ids: &[&str]) -> BTreeSet<String> {
    ids.iter()
        .flat_map(|id| crate::probe::ancestors(file, id))
        .collect()
}

/// A node's compute time, a cache hit's as measured when it was computed.
fn seconds(report: &RunReport, id: &str) -> Option<f64> {
    let n = report.node(id)?;
    n.timings
        .get("seconds")
        .copied()
        .or(Some(n.seconds).filter(|_| n.status == NodeStatus::Computed))
}

fn metric(report: &RunReport, id: &str, m: &str) -> Option<f64> {
    report
        .node(id)
        .and_then(|n| n.metrics.get(m).copied())
        .filter(|v| v.is_finite())
}

/// The sss.render's parameters with its `sss.lighting`'s inlined (as `sss.render` merges them),
/// and its inputs without `lighting`.
fn inlined(file: &GraphFile, decl: &NodeDecl) -> (Map<String, Value>, BTreeMap<String, String>) {
    let mut params = decl.params.clone();
    let mut inputs = decl.inputs.clone();
    if let Some(from) = inputs.remove("lighting") {
        let lighting = from.split_once('.').and_then(|(n, _)| file.node(n));
        for (k, v) in lighting.map(|l| l.params.clone()).unwrap_or_default() {
            params.insert(k, v);
        }
    }
    (params, inputs)
}

/// What a graph reads from `render` (port names).
fn ports_read(file: &GraphFile, render: &str) -> BTreeSet<String> {
    file.nodes
        .iter()
        .flat_map(|(_, d)| d.inputs.values())
        .filter_map(|f| f.split_once('.'))
        .filter(|(n, _)| *n == render)
        .map(|(_, p)| p.to_string())
        .collect()
}

/// `sss.render`'s parameters that `Params::classic` sets apart from the defaults.
fn classic() -> Vec<(String, Value)> {
    use mesoflow_nodes::sss::render::Params;
    let classic = serde_json::to_value(Params::classic()).unwrap_or_default();
    let default = serde_json::to_value(Params::default()).unwrap_or_default();
    classic
        .as_object()
        .into_iter()
        .flatten()
        .filter(|(k, v)| default.get(k.as_str()) != Some(*v))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect()
}

/// Plans `render` of `file` against the truth (see the module's doc).
pub fn arbitrate(
    engine: &Engine,
    name: &str,
    file: &GraphFile,
    render: &str,
    opts: &RunOptions,
    o: TruthOptions,
) -> Result<Arbitration, PlanError> {
    let start = Instant::now();
    if !(o.rmse.is_finite() && o.rmse > 0.0) {
        return Err(PlanError::Invalid(format!(
            "budget rmse={}: a relative RMSE > 0",
            o.rmse
        )));
    }
    let decl = file
        .node(render)
        .ok_or_else(|| PlanError::NoRender(format!("no node `{render}`")))?
        .clone();
    if decl.kind != "sss.render" {
        return Err(PlanError::NoRender(format!(
            "`{render}` is a {}: --against truth plans sss.render nodes, whose truth (the mesh filled with the medium, path traced) the graph holds; {}'s truth is not built yet: plan it against its own model (--budget flip=B without --against)",
            decl.kind, decl.kind
        )));
    }
    let (Some(mesh), Some(material)) = (decl.inputs.get("mesh"), decl.inputs.get("material"))
    else {
        return Err(PlanError::NoRender(format!(
            "`{render}` has no mesh or material input to make the truth from"
        )));
    };
    let (params, inputs) = inlined(file, &decl);
    let catalog = engine.registry();
    let default = |p: &str| crate::probe::kind_default(catalog, "sss.render", p);
    let view = |p: &str| params.get(p).cloned().or_else(|| default(p));
    let full_camera = camera_of(file, render, catalog);
    let (camera, resolution, share) = probe_camera(full_camera.clone(), o.share);
    // The scene's nodes, the candidates' inputs.
    let base: Vec<&str> = inputs
        .values()
        .filter_map(|f| f.split_once('.').map(|(n, _)| n))
        .collect();
    let keep = needed(file, &base);
    let mut scene = file.clone();
    scene.nodes.retain(|(id, _)| keep.contains(id));
    scene.description = None;

    let reference = |samples: u32, seed: u64, camera: &Map<String, Value>| -> NodeDecl {
        let mut p = Map::new();
        p.insert("camera".into(), Value::Object(camera.clone()));
        for k in ["light", "mm_per_unit", "background"] {
            if let Some(v) = view(k) {
                p.insert(k.into(), v);
            }
        }
        p.insert("samples".into(), json!(samples));
        p.insert("seed".into(), json!(seed));
        NodeDecl {
            kind: "render.reference".into(),
            params: p,
            inputs: BTreeMap::from([
                ("mesh".to_string(), mesh.clone()),
                ("medium".to_string(), material.clone()),
            ]),
        }
    };

    // The truth probe, its noise a third of the budget or less.
    let mut truth_samples = TRUTH_SAMPLES;
    let truth_noise = loop {
        let mut g = scene.clone();
        g.nodes
            .push((TRUTH.into(), reference(truth_samples, 104_729, &camera)));
        let r = run(engine, name, &g, &[(TRUTH, "image")], opts)?;
        let noise = metric(&r, TRUTH, "noise");
        match noise {
            Some(n) if n > o.rmse / 3.0 && truth_samples < MOST_TRUTH_SAMPLES => {
                let want = truth_samples as f64 * (n / (o.rmse / 3.0)).powi(2) * 1.1;
                truth_samples = (want.ceil() as u32).clamp(truth_samples * 2, MOST_TRUTH_SAMPLES);
            }
            _ => break noise,
        }
    };
    let truth = reference(truth_samples, 104_729, &camera);

    // Measures `cand` (at the probe's camera) against the truth: error and probe seconds, and
    // the report for its stages.
    let measure = |cand: &NodeDecl| -> Result<(Option<f64>, Option<f64>, RunReport), PlanError> {
        let mut g = scene.clone();
        g.nodes.push((TRUTH.into(), truth.clone()));
        g.nodes.push((CANDIDATE.into(), cand.clone()));
        g.nodes.push((
            COMPARE.into(),
            NodeDecl {
                kind: "image.compare".into(),
                params: Map::new(),
                inputs: BTreeMap::from([
                    ("reference".to_string(), format!("{TRUTH}.image")),
                    ("image".to_string(), format!("{CANDIDATE}.image")),
                    ("reference_mask".to_string(), format!("{TRUTH}.coverage")),
                ]),
            },
        ));
        let r = run(
            engine,
            name,
            &g,
            &[(COMPARE, "relative_rmse"), (CANDIDATE, "image")],
            opts,
        )?;
        let raw = metric(&r, COMPARE, "relative_rmse");
        let noise = truth_noise.unwrap_or(0.0);
        let error = raw.map(|e| (e * e - noise * noise).max(0.0).sqrt());
        Ok((error, seconds(&r, CANDIDATE), r))
    };

    // The model candidates.
    let sss = |overrides: &[(String, Value)], camera: &Map<String, Value>| -> NodeDecl {
        let mut p = params.clone();
        for (k, v) in overrides {
            p.insert(k.clone(), v.clone());
        }
        p.insert("camera".into(), Value::Object(camera.clone()));
        NodeDecl {
            kind: "sss.render".into(),
            params: p,
            inputs: inputs.clone(),
        }
    };
    let one = |k: &str, v: &str| vec![(k.to_string(), json!(v))];
    let variants: Vec<(&str, Vec<(String, Value)>)> = vec![
        ("the render as given", vec![]),
        ("energy: half_space", one("energy", "half_space")),
        ("geometry: exit_normal", one("geometry", "exit_normal")),
        ("Jensen & Buhler's classic gather", classic()),
        ("mode: brdf", one("mode", "brdf")),
    ];
    let mut candidates = Vec::new();
    let mut seen: Vec<Map<String, Value>> = Vec::new();
    for (label, overrides) in variants {
        let probe = sss(&overrides, &camera);
        if seen.contains(&probe.params) {
            continue;
        }
        seen.push(probe.params.clone());
        let full = sss(&overrides, &full_camera);
        let (error, probe_s, note, full_s) = match measure(&probe) {
            Ok((error, probe_s, r)) => {
                // The camera-independent part once, the per-pixel stages in proportion.
                let t = |k: &str| {
                    r.node(CANDIDATE)
                        .and_then(|n| n.timings.get(k).copied())
                        .unwrap_or(0.0)
                };
                let per_pixel = t("gather_seconds") + t("shading_seconds");
                let full_s = probe_s.map(|s| s + per_pixel * (1.0 / share - 1.0));
                (error, probe_s, None, full_s)
            }
            Err(e) => (None, None, Some(e.to_string()), None),
        };
        candidates.push(Candidate {
            name: label.to_string(),
            family: "model",
            decl: full,
            fits: error.is_some_and(|e| e <= o.rmse),
            error,
            probe_s,
            full_s,
            note,
        });
    }

    // Brute force, where what the graph reads from the render, render.reference makes too.
    let readable: BTreeSet<String> = ["image", "coverage", "covered", "noise"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let missing: Vec<String> = ports_read(file, render)
        .difference(&readable)
        .cloned()
        .collect();
    let brute = if missing.is_empty() {
        let pilot = measure(&reference(PILOT, 1, &camera))?;
        let noise = metric(&pilot.2, CANDIDATE, "noise");
        let samples = noise.map_or(PILOT, |n| {
            ((PILOT as f64 * (n / (AIM * o.rmse)).powi(2)).ceil() as u32).clamp(1, 65_536)
        });
        let (error, probe_s, _) = if samples == PILOT {
            pilot
        } else {
            measure(&reference(samples, 1, &camera))?
        };
        Candidate {
            name: format!("brute force: render.reference at {samples} samples a pixel"),
            family: "brute force",
            decl: reference(samples, 1, &full_camera),
            fits: error.is_some_and(|e| e <= o.rmse),
            error,
            full_s: probe_s.map(|s| s / share),
            probe_s,
            note: None,
        }
    } else {
        Candidate {
            name: "brute force".into(),
            family: "brute force",
            decl: reference(PILOT, 1, &full_camera),
            error: None,
            probe_s: None,
            full_s: None,
            fits: false,
            note: Some(format!(
                "not a candidate: the graph reads {} from `{render}`, which render.reference does not make",
                missing.join(", ")
            )),
        }
    };
    candidates.push(brute);

    let fastest = |c: &&Candidate| c.full_s.unwrap_or(f64::INFINITY);
    let (chosen, why) = match candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| c.fits)
        .min_by(|a, b| fastest(&a.1).total_cmp(&fastest(&b.1)))
    {
        Some((i, c)) => (
            Some(i),
            format!(
                "{}: relative RMSE {:.3} against the truth (budget {}), the fastest within it ({:.2} s estimated on the full view)",
                c.name,
                c.error.unwrap_or(f64::NAN),
                o.rmse,
                c.full_s.unwrap_or(f64::NAN)
            ),
        ),
        None => {
            let best = candidates
                .iter()
                .enumerate()
                .filter(|(_, c)| c.error.is_some())
                .min_by(|a, b| a.1.error.unwrap_or(f64::INFINITY).total_cmp(&b.1.error.unwrap_or(f64::INFINITY)));
            match best {
                Some((i, c)) => (
                    Some(i),
                    format!(
                        "no candidate is within the budget {}: the most accurate, {} ({:.3}), is planned",
                        o.rmse,
                        c.name,
                        c.error.unwrap_or(f64::NAN)
                    ),
                ),
                None => (None, "no candidate could be measured: the graph as given".into()),
            }
        }
    };
    let mut planned = file.clone();
    if let Some(i) = chosen {
        if let Some(n) = planned.node_mut(render) {
            *n = candidates[i].decl.clone();
        }
        crate::edit::prune(&mut planned, file, render);
    }
    Ok(Arbitration {
        render: render.to_string(),
        budget: o.rmse,
        resolution,
        share,
        truth_samples,
        truth_noise,
        candidates,
        chosen,
        why,
        planned,
        plan_s: start.elapsed().as_secs_f64(),
    })
}
