//! The planner as the arbiter (issue 57): `mesoflow plan --against truth --budget rmse=B`. Where
//! the graph can make the truth itself, every candidate, across model families, is measured
//! against that truth on a probe of the user's own view, and the cheapest within the budget
//! wins, brute force included. The truth and the candidates by kind:
//!
//! - `sss.render` whose mesh and medium are in the graph: the truth is volumetric path tracing
//!   of the same mesh filled with the same medium (`render.reference`). Candidates: the render as
//!   given (its `sss.lighting`'s parameters, where it has one, inlined); the model switches that
//!   exist: `energy: half_space`, `geometry: exit_normal`, Jensen & Buhler's classic
//!   configuration, `mode: brdf`.
//! - `render.mesh` whose BTF is captured in the graph (`btf.capture` of a height field, through
//!   any `btf.pca` and `btf.lod`): the truth is the true mesostructure, `mesh.displace` of the
//!   same height field on the same mesh (the render's tiling and shell, the MDF's depth), path
//!   traced with the capture's reflectance (`render.reference`, exact shadows). Candidates: the
//!   render as given; shadows switched; the other direction interpolation; without the MDF. A
//!   BTF read from a file, or a capture whose reflectance `render.reference` cannot represent
//!   (per-texel lobe maps, an anisotropic αv, a Fresnel index other than 1.5), has no truth
//!   here: the error says so, and the plan is against the graph's own model.
//! - both: brute force, `render.reference` of the truth's scene at the samples a pixel its own
//!   measured noise says meet the budget (noise falls as 1/√samples: a 16-sample pilot measures
//!   the constant, the candidate asks for 0.8 of the budget). Where the graph reads an output of
//!   the render that `render.reference` does not make, brute force is listed and refused.
//!
//! The truth probe is rendered at enough samples that its own noise is a third of the budget or
//! less (from 256 a pixel, raised from its measured noise, at most [`MOST_TRUTH_SAMPLES`]); each
//! candidate's error is its relative RMSE against it over the truth's coverage with the truth's
//! noise taken out (the families' measure). The probe is the centre of the view at the same pixels
//! per degree (`verify::probe_camera`); each candidate's time on the full view is estimated from
//! its probe: brute force in proportion to the pixels, a model as its camera-independent part
//! once plus its per-pixel stages (`sss.render`: gather and shading; `render.mesh`: its frame) in
//! proportion. Where no candidate meets the budget the most accurate is chosen and the plan says
//! so.
//!
//! `qh.render` has no truth here (one homogeneous medium does not stand for a quasi-homogeneous
//! material's measured profile): asking is an error that says so.

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
/// The true mesostructure the truth and brute force trace (`render.mesh`'s truth).
pub const TRUE_SURFACE: &str = "plan_true_surface";
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
    /// What the render warned of on the probe (its validity: where the scene is outside the
    /// model's domain, with numbers).
    pub warnings: Vec<String>,
}

/// The outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Arbitration {
    pub render: String,
    /// What the truth is, in words.
    pub judge_why: String,
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
    /// The longer of one full render of the graph as given (the first candidate) and of brute
    /// force at the budget, estimated, s, and the planning time over it (issue 57 asks for at
    /// most 2×); `None` where neither was measured.
    pub fn plan_time(&self) -> Option<(f64, f64)> {
        let given = self.candidates.first().and_then(|c| c.full_s);
        let brute = self
            .candidates
            .iter()
            .find(|c| c.family == "brute force")
            .and_then(|c| c.full_s);
        let longest = given.into_iter().chain(brute).fold(0.0, f64::max);
        (longest > 0.0).then(|| (longest, self.plan_s / longest))
    }

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
                o.insert("inputs".into(), json!(c.decl.inputs));
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
                if !c.warnings.is_empty() {
                    o.insert("warnings".into(), json!(c.warnings));
                }
                Value::Object(o)
            })
            .collect();
        let mut doc = json!({
            "render": self.render,
            "judge": "truth",
            "judge_why": self.judge_why,
            "budget": { "relative_rmse": self.budget },
            "probe": { "resolution": self.resolution, "share": self.share },
            "truth": { "samples": self.truth_samples },
            "candidates": candidates,
            "chosen": self.chosen.map_or(json!(null), |i| json!(self.candidates[i].name)),
            "why": self.why,
            "plan_seconds": self.plan_s,
        });
        if let Some((longest, ratio)) = self.plan_time() {
            doc["plan_time"] = json!({
                "seconds": self.plan_s,
                "longer_full_render_seconds": longest,
                "ratio": ratio,
            });
        }
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

/// What node `id` warned of in the run.
fn warnings(report: &RunReport, id: &str) -> Vec<String> {
    report
        .warnings
        .iter()
        .filter(|w| w.node == id)
        .map(|w| w.message.clone())
        .collect()
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

/// What the arbiter needs of one render kind: the truth's scene and the model candidates.
struct Setting {
    /// The render's parameters (an `sss.lighting`'s inlined) and inputs.
    params: Map<String, Value>,
    inputs: BTreeMap<String, String>,
    /// Nodes the truth adds before its `render.reference` (the displaced surface), which a
    /// brute-force plan keeps.
    extra: Vec<(String, NodeDecl)>,
    /// `render.reference`'s parameters (not the camera, samples or seed) and inputs.
    reference_params: Map<String, Value>,
    reference_inputs: BTreeMap<String, String>,
    /// The model switches: a label and the parameters it sets.
    variants: Vec<(String, Vec<(String, Value)>)>,
    /// The render's timings that grow with the pixels, and their unit in seconds.
    per_pixel: &'static [(&'static str, f64)],
    /// What the graph may read from the render for brute force to stand in for it: each port
    /// and `render.reference`'s port that gives the same (`render.mesh`'s 0/1 `mask` is the
    /// reference's `coverage`, over 0.5 where a pixel shows the surface).
    readable: &'static [(&'static str, &'static str)],
    judge_why: String,
}

/// `sss.render`: the mesh filled with the medium.
fn sss_setting(file: &GraphFile, decl: &NodeDecl, render: &str) -> Result<Setting, PlanError> {
    let (Some(mesh), Some(material)) = (decl.inputs.get("mesh"), decl.inputs.get("material"))
    else {
        return Err(PlanError::NoRender(format!(
            "`{render}` has no mesh or material input to make the truth from"
        )));
    };
    let (params, inputs) = inlined(file, decl);
    let one = |k: &str, v: &str| vec![(k.to_string(), json!(v))];
    Ok(Setting {
        extra: Vec::new(),
        reference_params: Map::new(),
        reference_inputs: BTreeMap::from([
            ("mesh".to_string(), mesh.clone()),
            ("medium".to_string(), material.clone()),
        ]),
        variants: vec![
            ("the render as given".into(), vec![]),
            ("energy: half_space".into(), one("energy", "half_space")),
            ("geometry: exit_normal".into(), one("geometry", "exit_normal")),
            ("Jensen & Buhler's classic gather".into(), classic()),
            ("mode: brdf".into(), one("mode", "brdf")),
        ],
        per_pixel: &[("gather_seconds", 1.0), ("shading_seconds", 1.0)],
        readable: &[
            ("image", "image"),
            ("coverage", "coverage"),
            ("covered", "covered"),
            ("noise", "noise"),
        ],
        judge_why: "the graph holds the mesh and the medium: the truth is volumetric path tracing of them (render.reference)".into(),
        params,
        inputs,
    })
}

/// `render.mesh`: the captured height field displaced on the mesh, with the capture's
/// reflectance.
fn mesh_setting(
    file: &GraphFile,
    decl: &NodeDecl,
    render: &str,
    catalog: &dyn mesoflow_graph::Catalog,
) -> Result<Setting, PlanError> {
    let no_truth = |why: String| {
        PlanError::NoRender(format!(
            "`{render}`: no truth can be made here: {why}; plan it against its own model (--budget flip=B without --against)"
        ))
    };
    let mesh = decl
        .inputs
        .get("mesh")
        .ok_or_else(|| no_truth("it has no mesh input".into()))?;
    let chain = crate::edit::btf_chain(file, render, "btf")
        .ok_or_else(|| no_truth("its btf input is not connected to a node".into()))?;
    let capture_id = chain.raw.split_once('.').map_or("", |(n, _)| n);
    let capture = file
        .node(capture_id)
        .filter(|n| n.kind == "btf.capture")
        .ok_or_else(|| {
            no_truth(format!(
                "its BTF comes from `{}`, not from a btf.capture of a height field in the graph (a measured BTF has no geometry to trace)",
                chain.raw
            ))
        })?;
    if capture.inputs.contains_key("maps") {
        return Err(no_truth(format!(
            "`{capture_id}` captures per-texel lobe maps, which render.reference cannot represent"
        )));
    }
    let height = capture
        .inputs
        .get("height")
        .ok_or_else(|| no_truth(format!("`{capture_id}` has no height input")))?;
    let cap = |p: &str| {
        capture
            .params
            .get(p)
            .cloned()
            .or_else(|| crate::probe::kind_default(catalog, "btf.capture", p))
    };
    let roughness_v = cap("roughness_v").filter(|v| !v.is_null());
    if roughness_v.is_some() && roughness_v != cap("roughness") {
        return Err(no_truth(format!(
            "`{capture_id}`'s anisotropic roughness_v, which render.reference cannot represent"
        )));
    }
    if cap("brdf") == Some(json!("ggx")) && cap("ior").and_then(|v| v.as_f64()) != Some(1.5) {
        return Err(no_truth(format!(
            "`{capture_id}`'s GGX Fresnel index other than 1.5, which render.reference cannot represent"
        )));
    }
    let params = decl.params.clone();
    let view = |p: &str| {
        params
            .get(p)
            .cloned()
            .or_else(|| crate::probe::kind_default(catalog, "render.mesh", p))
    };
    // The shell's depth in texels: the MDF's, where it tabulates one (its default, the height
    // range, is mesh.displace's too).
    let depth = decl
        .inputs
        .get("mdf")
        .and_then(|f| file.node(f.split_once('.')?.0))
        .filter(|n| n.kind == "mdf.tabulate")
        .and_then(|n| n.params.get("depth").cloned())
        .unwrap_or(Value::Null);
    let mut displace = Map::new();
    for k in ["tiling", "shell"] {
        if let Some(v) = view(k) {
            displace.insert(k.into(), v);
        }
    }
    displace.insert("depth".into(), depth);
    // Two vertices a texel, as the mesostructure family's truth.
    displace.insert("density".into(), json!(2.0));
    let mut reference_params = Map::new();
    for k in ["tiling", "background"] {
        if let Some(v) = view(k) {
            reference_params.insert(k.into(), v);
        }
    }
    for k in ["brdf", "albedo", "specular", "roughness"] {
        if let Some(v) = cap(k) {
            reference_params.insert(k.into(), v);
        }
    }
    let mut reference_inputs =
        BTreeMap::from([("mesh".to_string(), format!("{TRUE_SURFACE}.mesh"))]);
    if let Some(albedo) = capture.inputs.get("albedo") {
        reference_inputs.insert("albedo".into(), albedo.clone());
    }
    let flag = |k: &str| view(k).and_then(|v| v.as_bool()).unwrap_or(false);
    let mut variants: Vec<(String, Vec<(String, Value)>)> =
        vec![("the render as given".into(), vec![])];
    let shadows = flag("shadows");
    variants.push((
        format!("shadows: {}", !shadows),
        vec![("shadows".into(), json!(!shadows))],
    ));
    let other = if view("interpolation") == Some(json!("nearest")) {
        "rings"
    } else {
        "nearest"
    };
    variants.push((
        format!("interpolation: {other}"),
        vec![("interpolation".into(), json!(other))],
    ));
    if decl.inputs.contains_key("mdf") && flag("use_mdf") {
        variants.push((
            "without the MDF (use_mdf: false)".into(),
            vec![("use_mdf".into(), json!(false))],
        ));
    }
    Ok(Setting {
        extra: vec![(
            TRUE_SURFACE.into(),
            NodeDecl {
                kind: "mesh.displace".into(),
                params: displace,
                inputs: BTreeMap::from([
                    ("mesh".to_string(), mesh.clone()),
                    ("height".to_string(), height.clone()),
                ]),
            },
        )],
        reference_params,
        reference_inputs,
        variants,
        per_pixel: &[("frame_ms", 1e-3)],
        readable: &[("image", "image"), ("mask", "coverage")],
        judge_why: format!(
            "the graph captures the BTF from a height field (`{capture_id}`): the truth is that height field displaced on the mesh (mesh.displace), path traced with the capture's reflectance (render.reference)"
        ),
        params,
        inputs: decl.inputs.clone(),
    })
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
    let catalog = engine.registry();
    let setting = match decl.kind.as_str() {
        "sss.render" => sss_setting(file, &decl, render)?,
        "render.mesh" => mesh_setting(file, &decl, render, catalog)?,
        other => {
            return Err(PlanError::NoRender(format!(
                "`{render}` is a {other}: --against truth plans sss.render (its mesh and medium path traced) and render.mesh (its captured height field displaced and path traced); {other}'s truth is not built: plan it against its own model (--budget flip=B without --against)"
            )))
        }
    };
    let Setting {
        params,
        inputs,
        extra,
        reference_params,
        reference_inputs,
        variants,
        per_pixel,
        readable,
        judge_why,
    } = setting;
    let default = |p: &str| crate::probe::kind_default(catalog, &decl.kind, p);
    let view = |p: &str| params.get(p).cloned().or_else(|| default(p));
    let full_camera = camera_of(file, render, catalog);
    let (camera, resolution, share) = probe_camera(full_camera.clone(), o.share);
    // The scene's nodes: the candidates' inputs and the truth's.
    let base: Vec<&str> = inputs
        .values()
        .chain(extra.iter().flat_map(|(_, d)| d.inputs.values()))
        .chain(reference_inputs.values())
        .filter_map(|f| f.split_once('.').map(|(n, _)| n))
        .filter(|n| extra.iter().all(|(id, _)| id.as_str() != *n))
        .collect();
    let keep = needed(file, &base);
    let mut scene = file.clone();
    scene.nodes.retain(|(id, _)| keep.contains(id));
    scene.nodes.extend(extra.iter().cloned());
    scene.description = None;

    let reference = |samples: u32, seed: u64, camera: &Map<String, Value>| -> NodeDecl {
        let mut p = reference_params.clone();
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
            inputs: reference_inputs.clone(),
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
                // At least twice the last, at most the cap (a held-out scene once asked for
                // more than the cap, and `clamp` with min > max panicked).
                truth_samples = (want.ceil() as u32)
                    .max(truth_samples.saturating_mul(2))
                    .min(MOST_TRUTH_SAMPLES);
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
    let model = |overrides: &[(String, Value)], camera: &Map<String, Value>| -> NodeDecl {
        let mut p = params.clone();
        for (k, v) in overrides {
            p.insert(k.clone(), v.clone());
        }
        p.insert("camera".into(), Value::Object(camera.clone()));
        NodeDecl {
            kind: decl.kind.clone(),
            params: p,
            inputs: inputs.clone(),
        }
    };
    let mut candidates = Vec::new();
    let mut seen: Vec<Map<String, Value>> = Vec::new();
    for (label, overrides) in variants {
        let probe = model(&overrides, &camera);
        if seen.contains(&probe.params) {
            continue;
        }
        seen.push(probe.params.clone());
        let full = model(&overrides, &full_camera);
        let (error, probe_s, note, full_s, warned) = match measure(&probe) {
            Ok((error, probe_s, r)) => {
                // The camera-independent part once, the per-pixel stages in proportion.
                let per_pixel: f64 = per_pixel
                    .iter()
                    .map(|(k, unit)| {
                        r.node(CANDIDATE)
                            .and_then(|n| n.timings.get(*k).copied())
                            .unwrap_or(0.0)
                            * unit
                    })
                    .sum();
                let full_s = probe_s.map(|s| s + per_pixel * (1.0 / share - 1.0));
                (error, probe_s, None, full_s, warnings(&r, CANDIDATE))
            }
            Err(e) => (None, None, Some(e.to_string()), None, Vec::new()),
        };
        candidates.push(Candidate {
            name: label,
            family: "model",
            decl: full,
            fits: error.is_some_and(|e| e <= o.rmse),
            error,
            probe_s,
            full_s,
            note,
            warnings: warned,
        });
    }

    // Brute force, where what the graph reads from the render, render.reference makes too.
    let readable_ports: BTreeSet<String> = readable.iter().map(|(s, _)| s.to_string()).collect();
    let missing: Vec<String> = ports_read(file, render)
        .difference(&readable_ports)
        .cloned()
        .collect();
    let brute = if missing.is_empty() {
        let pilot = measure(&reference(PILOT, 1, &camera))?;
        let noise = metric(&pilot.2, CANDIDATE, "noise");
        let samples = noise.map_or(PILOT, |n| {
            ((PILOT as f64 * (n / (AIM * o.rmse)).powi(2)).ceil() as u32).clamp(1, 65_536)
        });
        let (error, probe_s, r) = if samples == PILOT {
            pilot
        } else {
            measure(&reference(samples, 1, &camera))?
        };
        let mut warned = warnings(&r, CANDIDATE);
        // A brute-force plan states its noise (its seed is fixed, so frames do not flicker).
        if let Some(n) = metric(&r, CANDIDATE, "noise") {
            warned.push(format!(
                "its own noise on the probe: relative RMSE {n:.3} at {samples} samples a pixel (seed fixed: the same noise every frame)"
            ));
        }
        Candidate {
            name: format!("brute force: render.reference at {samples} samples a pixel"),
            family: "brute force",
            decl: reference(samples, 1, &full_camera),
            fits: error.is_some_and(|e| e <= o.rmse),
            error,
            full_s: probe_s.map(|s| s / share),
            probe_s,
            note: None,
            warnings: warned,
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
            warnings: Vec::new(),
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
    // The render as given (the first candidate) leaves the graph as it is: its candidate's
    // declaration has the lighting inlined, which would compute it again inside the render.
    if let Some(i) = chosen.filter(|&i| i > 0) {
        let c = &candidates[i];
        if c.family == "brute force" {
            // The truth's own nodes (the displaced surface) go in before the render.
            let at = planned
                .nodes
                .iter()
                .position(|(id, _)| id == render)
                .unwrap_or(planned.nodes.len());
            for (k, node) in extra.iter().enumerate() {
                if planned.node(&node.0).is_none() {
                    planned.nodes.insert(at + k, node.clone());
                }
            }
        }
        if let Some(n) = planned.node_mut(render) {
            *n = c.decl.clone();
        }
        if c.family == "brute force" {
            // What the graph read from the render under another name (render.mesh's `mask`)
            // it now reads from render.reference's port that gives the same.
            for (_, d) in &mut planned.nodes {
                for from in d.inputs.values_mut() {
                    let renamed = readable
                        .iter()
                        .find(|(was, is)| was != is && from.as_str() == format!("{render}.{was}"));
                    if let Some((_, is)) = renamed {
                        *from = format!("{render}.{is}");
                    }
                }
            }
        }
        crate::edit::prune(&mut planned, file, render);
    }
    Ok(Arbitration {
        render: render.to_string(),
        judge_why,
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
