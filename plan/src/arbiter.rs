//! The planner as the arbiter (issue 57): `mesoflow plan --against truth --budget rmse=B` (or
//! `flip=B`). Where the graph can make the truth itself, every candidate, across model
//! families, is measured against that truth on a probe of the user's own view, and the cheapest
//! within the budget wins, brute force included. The truth and the candidates by kind:
//!
//! - `sss.render` whose mesh and medium are in the graph: the truth is volumetric path tracing
//!   of the same mesh filled with the same medium (`render.reference`). Candidates: the render as
//!   given (reading its `sss.lighting` where it has one, as the graph does: the lighting is a
//!   node of the probe's graph, a cache hit where the graph has run, and its time is charged
//!   to the candidate); the model switches (that `sss.lighting`'s parameters inlined) that
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
//! - both: brute force, `render.reference` of the truth's scene, aimed at [`AIM`] of the budget
//!   from the truth's own noise (noise falls as 1/√samples) and re-aimed from its measured
//!   error where that is over the budget or well under it. At a FLIP budget on a whole-view
//!   probe, its FLIP is taken on the full view (from two full-view pilots on other seeds), and
//!   it never passes the truth's own samples. Where the graph reads an output of the render
//!   that `render.reference` does not make, brute force is listed and refused.
//!
//! In order, each phase timed in the plan: two pilots (brute force at [`PILOT`] samples a pixel
//! on the probe and on the full view), the first's noise sizing the truth; the truth probe, its noise a third of the budget or
//! less (rendered once more where it is not); the render as given and the switches that keep its
//! camera-independent work; brute force; the switches that redo that work (`sss.render`'s
//! lighting with another `energy` or `geometry`), skipped where half the given render's
//! camera-independent time is already slower than a candidate within the budget. The probe is
//! [`TRUTH_SHARE`] of the view's pixels by default: for `render.mesh` the view's centre at the
//! same pixels per degree (`verify::probe_camera`: its model is chosen by the pixel's
//! footprint), for `sss.render` the whole view at a lower resolution (`verify::scaled_camera`:
//! its error is smooth at the pixel's scale and may lie where the centre does not look). A candidate's error is its relative RMSE against the truth over
//! the truth's coverage with the truth's noise taken out (the families' measure), or its mean
//! FLIP there (brute force's relative RMSE, its noise, scaled to the full view by the ratio of
//! a second pilot's noise there to the probe's); its time on the full view is estimated: brute
//! force as its BVH once plus its samples at the full view's pilot's cost a sample, a model as
//! its camera-independent part once plus its per-pixel stages (`sss.render`: gather and
//! shading; `render.mesh`: its frame) in proportion to the pixels the object covers. Where no candidate meets the budget the most accurate is chosen and the plan says
//! so.
//!
//! `qh.render` has no truth here (one homogeneous medium does not stand for a quasi-homogeneous
//! material's measured profile): asking is an error that says so.

use crate::verify::{camera_of, probe_camera, resolution_of, run_for as run, scaled_camera};
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
/// Brute force's second full-view pilot, on another seed (a FLIP budget's noise on the full view).
const TWIN: &str = "plan_twin";
/// The true mesostructure the truth and brute force trace (`render.mesh`'s truth).
pub const TRUE_SURFACE: &str = "plan_true_surface";
/// The truth's samples a pixel at most (its noise then decides nothing more).
pub const MOST_TRUTH_SAMPLES: u32 = 16_384;
/// The truth's fewest samples a pixel.
const TRUTH_SAMPLES: u32 = 64;
/// The brute-force pilot's samples a pixel.
const PILOT: u32 = 16;
/// The least share of a centre probe's pixels the object must cover for the centre to judge;
/// below it the whole view at a lower resolution is probed.
const MIN_COVERED: f64 = 0.05;
/// The truth's samples over what its noise estimate asks: on the translucent family's seed 0
/// (a development scene), the per-sample noise constant measured at 16 samples a pixel was
/// 6 % below the one at 1 024 (rare long paths the pilot misses), so (1.06)² and more
/// for the estimate's own scatter; a truth that still misses is rendered again, wasting the
/// first.
const TRUTH_MARGIN: f64 = 1.3;
/// The truth probe's share of the view's pixels by default: the truth, at a third of the
/// budget's noise, takes (3 × [`AIM`])² ≈ 7.3 times the samples of brute force at the budget, so
/// on this share about 0.73 of brute force's frame.
pub const TRUTH_SHARE: f64 = 0.1;
/// Brute force aims at this share of the budget (its error is its noise). Issue 57 holds a plan
/// to 1.2× the time of brute force at the samples that meet the budget; samples grow as
/// 1/aim², so an aim below 0.87 alone would break it. Where the measured error is over the
/// budget, brute force is re-aimed.
const AIM: f64 = 0.9;

/// What a candidate's distance from the truth is measured by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Measure {
    /// Relative RMSE over the pixels the truth covers, the truth's noise taken out.
    RelativeRmse,
    /// Mean FLIP over the pixels the truth covers, at these pixels per degree (the probe has
    /// the view's), the truth's noise left in (a third of the budget as relative RMSE).
    Flip { ppd: f64 },
}

impl Measure {
    pub fn name(&self) -> &'static str {
        match self {
            Measure::RelativeRmse => "relative RMSE",
            Measure::Flip { .. } => "mean FLIP",
        }
    }
}

/// How the arbiter judges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthOptions {
    /// The budget, in `measure`'s units.
    pub budget: f64,
    pub measure: Measure,
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
    /// The same at the probe's camera (what was measured).
    pub probe: NodeDecl,
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
    pub measure: Measure,
    pub resolution: [u32; 2],
    pub share: f64,
    /// Whether the probe was the whole view at a lower resolution (else the view's centre), and
    /// why where it was not the render kind's own choice.
    pub whole_view: bool,
    pub probe_note: Option<String>,
    pub truth_samples: u32,
    pub truth_noise: Option<f64>,
    /// The pilot's noise and each truth render (samples, noise): the last is the truth.
    pub pilot_noise: Option<f64>,
    pub truth_renders: Vec<(u32, Option<f64>)>,
    pub candidates: Vec<Candidate>,
    pub chosen: Option<usize>,
    pub why: String,
    pub planned: GraphFile,
    pub plan_s: f64,
    /// The probe's scene with the truth ([`TRUTH`]): what [`Arbitration::previews`] adds to.
    pub probe_scene: GraphFile,
    /// Where the planning time went: each phase and its seconds (the scene's own nodes count
    /// in the first phase that needs them).
    pub phases: Vec<(&'static str, f64)>,
}

/// The preview graph's nodes: the render as given and the plan on the probe, and each one's
/// FLIP map against the truth (the FLIP preview, magma).
pub const PREVIEW_GIVEN: &str = "plan_given";
pub const PREVIEW_PLANNED: &str = "plan_planned";
pub const PREVIEW_GIVEN_ERROR: &str = "plan_given_error";
pub const PREVIEW_PLANNED_ERROR: &str = "plan_planned_error";

impl Arbitration {
    /// The probe's truth, the render as given, the plan's choice and their FLIP maps against
    /// the truth, as one graph (every render in it is in the cache the plan filled): the
    /// studio's previews. The images are [`TRUTH`]`.image`, [`PREVIEW_GIVEN`]`.image`,
    /// [`PREVIEW_PLANNED`]`.image` and the two error nodes' `preview`.
    pub fn previews(&self) -> GraphFile {
        let mut g = self.probe_scene.clone();
        let given = self.candidates.first().map(|c| c.probe.clone());
        let chosen = self.chosen.map(|i| self.candidates[i].probe.clone());
        for (id, err, decl) in [
            (PREVIEW_GIVEN, PREVIEW_GIVEN_ERROR, given),
            (PREVIEW_PLANNED, PREVIEW_PLANNED_ERROR, chosen),
        ] {
            let Some(decl) = decl else { continue };
            g.nodes.push((id.into(), decl));
            g.nodes.push((
                err.into(),
                NodeDecl {
                    kind: "image.flip".into(),
                    params: Map::new(),
                    inputs: BTreeMap::from([
                        ("reference".to_string(), format!("{TRUTH}.image")),
                        ("test".to_string(), format!("{id}.image")),
                        ("mask".to_string(), format!("{TRUTH}.coverage")),
                    ]),
                },
            ));
        }
        g
    }

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
                let error_key = match self.measure {
                    Measure::RelativeRmse => "relative_rmse",
                    Measure::Flip { .. } => "flip",
                };
                for (k, v) in [
                    (error_key, c.error),
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
            "budget": match self.measure {
                Measure::RelativeRmse => json!({ "relative_rmse": self.budget }),
                Measure::Flip { ppd } => json!({ "flip": self.budget, "ppd": ppd }),
            },
            "probe": {
                "resolution": self.resolution,
                "share": self.share,
                "kind": if self.whole_view { "the whole view at a lower resolution" } else { "the view's centre at its own pixels per degree" },
                "note": self.probe_note,
            },
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
                "phases": self.phases.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<Map<String, Value>>(),
                "ratio": ratio,
            });
        }
        doc["truth"]["renders"] = json!(self
            .truth_renders
            .iter()
            .map(|(s, n)| json!({ "samples": s, "noise": n }))
            .collect::<Vec<_>>());
        if let Some(n) = self.pilot_noise {
            doc["truth"]["pilot"] = json!({ "samples": PILOT, "noise": n });
        }
        if let Some(n) = self.truth_noise {
            doc["truth"]["noise"] = json!(n);
            if n > self.budget / 3.0 {
                doc["truth"]["note"] = json!(format!(
                    "its noise (relative RMSE {n:.3}) is above a third of the budget ({:.3}) at {} samples a pixel: the candidates' errors carry that much more uncertainty",
                    self.budget / 3.0,
                    self.truth_samples
                ));
            }
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

/// A model switch: its label, the parameters it sets, and whether it redoes the render's
/// camera-independent work with other parameters (`sss.render`'s lighting).
#[derive(Clone)]
struct Variant {
    label: String,
    overrides: Vec<(String, Value)>,
    redoes_lighting: bool,
}

impl Variant {
    fn new(label: impl Into<String>, overrides: Vec<(String, Value)>) -> Variant {
        Variant {
            label: label.into(),
            overrides,
            redoes_lighting: false,
        }
    }
}

/// What the arbiter needs of one render kind: the truth's scene and the model candidates.
struct Setting {
    /// The render's parameters (an `sss.lighting`'s inlined) and inputs.
    params: Map<String, Value>,
    inputs: BTreeMap<String, String>,
    /// Where the render reads an `sss.lighting` node: that node's id, and the render's own
    /// parameters and inputs (the lighting connected). The render as given is measured so,
    /// its lighting a node of the probe's graph (a cache hit where the graph has run), and
    /// charged that node's time; the other switches have it inlined.
    lighting: Option<GivenLighting>,
    /// Nodes the truth adds before its `render.reference` (the displaced surface), which a
    /// brute-force plan keeps.
    extra: Vec<(String, NodeDecl)>,
    /// `render.reference`'s parameters (not the camera, samples or seed) and inputs.
    reference_params: Map<String, Value>,
    reference_inputs: BTreeMap<String, String>,
    /// The model switches, the render as given first.
    variants: Vec<Variant>,
    /// The render's timings that grow with the pixels, and their unit in seconds.
    per_pixel: &'static [(&'static str, f64)],
    /// What the graph may read from the render for brute force to stand in for it: each port
    /// and `render.reference`'s port that gives the same (`render.mesh`'s 0/1 `mask` is the
    /// reference's `coverage`, over 0.5 where a pixel shows the surface).
    readable: &'static [(&'static str, &'static str)],
    /// Whether the probe is the whole view at a lower resolution (where the render's error does
    /// not hang on the pixel's footprint) rather than its centre at the view's own.
    whole_view: bool,
    judge_why: String,
}

/// An `sss.render` that reads an `sss.lighting` node: that node's id, and the render's own
/// parameters and inputs (the lighting connected).
struct GivenLighting {
    node: String,
    params: Map<String, Value>,
    inputs: BTreeMap<String, String>,
}

/// `sss.render`: the mesh filled with the medium.
fn sss_setting(file: &GraphFile, decl: &NodeDecl, render: &str) -> Result<Setting, PlanError> {
    let (Some(mesh), Some(material)) = (decl.inputs.get("mesh"), decl.inputs.get("material"))
    else {
        return Err(PlanError::NoTruth(format!(
            "`{render}` has no mesh or material input to make the truth from"
        )));
    };
    let (params, inputs) = inlined(file, decl);
    let lighting = decl
        .inputs
        .get("lighting")
        .and_then(|from| from.split_once('.'))
        .filter(|(id, _)| file.node(id).is_some_and(|n| n.kind == "sss.lighting"))
        .map(|(id, _)| GivenLighting {
            node: id.to_string(),
            params: decl.params.clone(),
            inputs: decl.inputs.clone(),
        });
    let one = |k: &str, v: &str| vec![(k.to_string(), json!(v))];
    Ok(Setting {
        lighting,
        extra: Vec::new(),
        reference_params: Map::new(),
        reference_inputs: BTreeMap::from([
            ("mesh".to_string(), mesh.clone()),
            ("medium".to_string(), material.clone()),
        ]),
        variants: vec![
            Variant::new("the render as given", vec![]),
            Variant {
                redoes_lighting: true,
                ..Variant::new("energy: half_space", one("energy", "half_space"))
            },
            Variant {
                redoes_lighting: true,
                ..Variant::new("geometry: exit_normal", one("geometry", "exit_normal"))
            },
            Variant::new("Jensen & Buhler's classic gather", classic()),
            Variant::new("mode: brdf", one("mode", "brdf")),
        ],
        per_pixel: &[("gather_seconds", 1.0), ("shading_seconds", 1.0)],
        readable: &[
            ("image", "image"),
            ("coverage", "coverage"),
            ("covered", "covered"),
            ("noise", "noise"),
        ],
        // A translucent render's error is smooth at the pixel's scale and lies where the
        // centre may not show it (a back-lit rim, a thin part at the edge): the whole view.
        whole_view: true,
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
    let no_truth =
        |why: String| PlanError::NoTruth(format!("`{render}`: no truth can be made here: {why}"));
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
    let mut variants = vec![Variant::new("the render as given", vec![])];
    let shadows = flag("shadows");
    variants.push(Variant::new(
        format!("shadows: {}", !shadows),
        vec![("shadows".into(), json!(!shadows))],
    ));
    let other = if view("interpolation") == Some(json!("nearest")) {
        "rings"
    } else {
        "nearest"
    };
    variants.push(Variant::new(
        format!("interpolation: {other}"),
        vec![("interpolation".into(), json!(other))],
    ));
    if decl.inputs.contains_key("mdf") && flag("use_mdf") {
        variants.push(Variant::new(
            "without the MDF (use_mdf: false)",
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
        // A mesostructure's model (its BTF level, its MDF) is chosen by the pixel's footprint:
        // the view's centre at its own pixels per degree.
        whole_view: false,
        judge_why: format!(
            "the graph captures the BTF from a height field (`{capture_id}`): the truth is that height field displaced on the mesh (mesh.displace), path traced with the capture's reflectance (render.reference)"
        ),
        params,
        inputs: decl.inputs.clone(),
        lighting: None,
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
    if !(o.budget.is_finite() && o.budget > 0.0) {
        return Err(PlanError::Invalid(format!(
            "budget {}: a {} > 0",
            o.budget,
            o.measure.name()
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
            return Err(PlanError::NoTruth(format!(
                "`{render}` is a {other}: --against truth plans sss.render (its mesh and medium path traced) and render.mesh (its captured height field displaced and path traced); {other}'s truth is not built"
            )))
        }
    };
    let Setting {
        params,
        inputs,
        lighting,
        extra,
        reference_params,
        reference_inputs,
        variants,
        per_pixel,
        readable,
        whole_view,
        judge_why,
    } = setting;
    let default = |p: &str| crate::probe::kind_default(catalog, &decl.kind, p);
    let view = |p: &str| params.get(p).cloned().or_else(|| default(p));
    let full_camera = camera_of(file, render, catalog);
    let mut whole_view = whole_view;
    let (mut camera, mut resolution, mut share) = if whole_view {
        scaled_camera(full_camera.clone(), o.share)
    } else {
        probe_camera(full_camera.clone(), o.share)
    };
    // The scene's nodes: the candidates' inputs and the truth's.
    let base: Vec<&str> = inputs
        .values()
        .chain(lighting.iter().flat_map(|l| l.inputs.values()))
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

    let fits = |e: Option<f64>| e.is_some_and(|e| e <= o.budget);
    let timing = |r: &RunReport, k: &str| r.node(CANDIDATE).and_then(|n| n.timings.get(k).copied());

    // The pilots: brute force at PILOT samples a pixel on the probe and on the full view. The
    // probe's noise sizes the truth; its BVH (kept by the process for the renders after it) is
    // brute force's fixed cost. The full view's gives brute force's cost a sample there and how
    // its noise compares with the probe's (the view's centre may show more or less of the
    // object's noisiest parts than the whole view), and the two coverages scale the models'
    // per-pixel stages.
    let mut phases: Vec<(&'static str, f64)> = Vec::new();
    let mut lap = Instant::now();
    let mut phase = |name: &'static str| {
        phases.push((name, lap.elapsed().as_secs_f64()));
        lap = Instant::now();
    };
    let pilot_at = |camera: &Map<String, Value>| -> Result<RunReport, PlanError> {
        let mut g = scene.clone();
        g.nodes
            .push((CANDIDATE.into(), reference(PILOT, 1, camera)));
        run(engine, name, &g, &[(CANDIDATE, "image")], opts)
    };
    let mut pilot = pilot_at(&camera)?;
    let mut bvh_s = timing(&pilot, "bvh_seconds").unwrap_or(0.0);
    // A centre that shows too little of the object (a torus seen through its hole, an object
    // off the view's centre) or none of its light (an unlit side: the pilot's image is black,
    // its relative noise undefined) judges nothing: the whole view at a lower resolution.
    let mut probe_note = None;
    let centre_covers = metric(&pilot, CANDIDATE, "covered").unwrap_or(0.0);
    let centre_lit = metric(&pilot, CANDIDATE, "noise").is_some();
    if !whole_view && (centre_covers < MIN_COVERED || !centre_lit) {
        (camera, resolution, share) = scaled_camera(full_camera.clone(), o.share);
        whole_view = true;
        probe_note = Some(if centre_lit {
            format!(
                "the view's centre shows the object on {:.1}% of its pixels (under {:.0}%): the whole view at a lower resolution was probed instead",
                100.0 * centre_covers,
                100.0 * MIN_COVERED
            )
        } else {
            "the view's centre shows no light (brute force's pilot there is black): the whole view at a lower resolution was probed instead".to_string()
        });
        pilot = pilot_at(&camera)?;
        bvh_s = bvh_s.max(timing(&pilot, "bvh_seconds").unwrap_or(0.0));
    }
    let pilot_noise = metric(&pilot, CANDIDATE, "noise");
    let full_resolution = resolution_of(&full_camera);
    // FLIP at the view's pixels per degree: a whole-view probe's pixels subtend more.
    let probe_ppd = |ppd: f64| {
        if whole_view {
            ppd * resolution[0] as f64 / full_resolution[0].max(1) as f64
        } else {
            ppd
        }
    };
    let full_pilot = if share < 1.0 {
        Some(pilot_at(&full_camera)?)
    } else {
        None
    };
    let full = full_pilot.as_ref().unwrap_or(&pilot);
    let pixels = |r: &[u32; 2]| r[0] as f64 * r[1] as f64;
    // Covered pixels on the full view over those on the probe (1/share where neither covers).
    let pixel_scale = match (
        metric(full, CANDIDATE, "covered"),
        metric(&pilot, CANDIDATE, "covered"),
    ) {
        (Some(f), Some(p)) if f > 0.0 && p > 0.0 => {
            f * pixels(&full_resolution) / (p * pixels(&resolution))
        }
        _ => 1.0 / share,
    };
    // Brute force's relative noise on the full view over the probe's (relative RMSE only).
    let to_full = match (o.measure, metric(full, CANDIDATE, "noise"), pilot_noise) {
        (Measure::RelativeRmse, Some(f), Some(p)) if f > 0.0 && p > 0.0 => f / p,
        _ => 1.0,
    };
    let full_trace_per_sample = timing(full, "trace_seconds").map(|t| t / PILOT as f64);
    // At a FLIP budget on a whole-view probe, brute force's FLIP on the full view: FLIP of noise
    // does not carry from a lower resolution to the frame (each probe pixel subtends more, where
    // the same noise is a larger FLIP: brute force was planned at 4–40 times the samples it
    // needed), so it is measured on the full view itself, as the FLIP between two full-view
    // pilots on other seeds: their difference has the noise of one render at half their samples
    // against a noiseless truth. A centre probe has the frame's pixels: its own FLIP is kept
    // (the twin measure planned a median third of the samples needed there, over the budget).
    let full_noise_flip = match o.measure {
        Measure::Flip { ppd } if whole_view && share < 1.0 => {
            let mut g = scene.clone();
            g.nodes
                .push((CANDIDATE.into(), reference(PILOT, 1, &full_camera)));
            g.nodes
                .push((TWIN.into(), reference(PILOT, 2, &full_camera)));
            g.nodes.push((
                COMPARE.into(),
                NodeDecl {
                    kind: "image.flip".into(),
                    params: json!({ "ppd": ppd })
                        .as_object()
                        .cloned()
                        .unwrap_or_default(),
                    inputs: BTreeMap::from([
                        ("reference".to_string(), format!("{CANDIDATE}.image")),
                        ("test".to_string(), format!("{TWIN}.image")),
                        ("mask".to_string(), format!("{CANDIDATE}.coverage")),
                    ]),
                },
            ));
            let r = run(engine, name, &g, &[(COMPARE, "mean")], opts)?;
            metric(&r, COMPARE, "mean").filter(|f| *f > 0.0)
        }
        _ => None,
    };

    // The truth probe, its noise (as relative RMSE, for either measure) a third of the budget or
    // less: sized from the pilot's noise (1/√samples). A pilot underestimates heavy-tailed noise
    // (a back-lit medium's rare long paths), so where the truth's own noise is still above, it
    // is rendered once more, sized from that noise (at most four times the samples).
    let aim_truth = o.budget / 3.0;
    let size = |samples: u32, noise: f64| -> u32 {
        (samples as f64 * (noise / aim_truth).powi(2) * TRUTH_MARGIN)
            .ceil()
            .clamp(TRUTH_SAMPLES as f64, MOST_TRUTH_SAMPLES as f64) as u32
    };
    let render_truth = |samples: u32| -> Result<Option<f64>, PlanError> {
        let mut g = scene.clone();
        g.nodes
            .push((TRUTH.into(), reference(samples, 104_729, &camera)));
        let r = run(engine, name, &g, &[(TRUTH, "image")], opts)?;
        Ok(metric(&r, TRUTH, "noise"))
    };
    phase("pilot");
    let mut truth_samples = pilot_noise.map_or(TRUTH_SAMPLES, |n| size(PILOT, n));
    let mut truth_noise = render_truth(truth_samples)?;
    let mut truth_renders = vec![(truth_samples, truth_noise)];
    if let Some(n) = truth_noise.filter(|&n| n > aim_truth && truth_samples < MOST_TRUTH_SAMPLES) {
        truth_samples = size(truth_samples, n).min(truth_samples.saturating_mul(4));
        truth_noise = render_truth(truth_samples)?;
        truth_renders.push((truth_samples, truth_noise));
    }
    let truth = reference(truth_samples, 104_729, &camera);
    phase("truth");

    // Measures `cand` (at the probe's camera) against the truth: its error (relative RMSE with
    // the truth's noise taken out, or mean FLIP over the truth's coverage) and the report.
    let measure = |cand: &NodeDecl| -> Result<(Option<f64>, RunReport), PlanError> {
        let mut g = scene.clone();
        g.nodes.push((TRUTH.into(), truth.clone()));
        g.nodes.push((CANDIDATE.into(), cand.clone()));
        let (compare, port) = match o.measure {
            Measure::RelativeRmse => (
                NodeDecl {
                    kind: "image.compare".into(),
                    params: Map::new(),
                    inputs: BTreeMap::from([
                        ("reference".to_string(), format!("{TRUTH}.image")),
                        ("image".to_string(), format!("{CANDIDATE}.image")),
                        ("reference_mask".to_string(), format!("{TRUTH}.coverage")),
                    ]),
                },
                "relative_rmse",
            ),
            Measure::Flip { ppd } => (
                NodeDecl {
                    kind: "image.flip".into(),
                    params: json!({ "ppd": probe_ppd(ppd) })
                        .as_object()
                        .cloned()
                        .unwrap_or_default(),
                    inputs: BTreeMap::from([
                        ("reference".to_string(), format!("{TRUTH}.image")),
                        ("test".to_string(), format!("{CANDIDATE}.image")),
                        ("mask".to_string(), format!("{TRUTH}.coverage")),
                    ]),
                },
                "mean",
            ),
        };
        g.nodes.push((COMPARE.into(), compare));
        let r = run(
            engine,
            name,
            &g,
            &[(COMPARE, port), (CANDIDATE, "image")],
            opts,
        )?;
        let error = match o.measure {
            Measure::RelativeRmse => {
                let noise = truth_noise.unwrap_or(0.0);
                metric(&r, COMPARE, "relative_rmse")
                    .map(|e| (e * e - noise * noise).max(0.0).sqrt())
            }
            Measure::Flip { .. } => metric(&r, COMPARE, "mean"),
        };
        Ok((error, r))
    };

    // The model candidates: the render as given and the switches that do not redo its
    // camera-independent work first; then brute force; then the switches that redo that work
    // (`energy`, `geometry`), unless the given render's camera-independent time already shows
    // they cannot beat a candidate within the budget.
    let model = |overrides: &[(String, Value)], camera: &Map<String, Value>| -> NodeDecl {
        // The render as given reads its lighting node, as the graph does.
        let (mut p, inputs) = match &lighting {
            Some(l) if overrides.is_empty() => (l.params.clone(), l.inputs.clone()),
            _ => (params.clone(), inputs.clone()),
        };
        for (k, v) in overrides {
            p.insert(k.clone(), v.clone());
        }
        p.insert("camera".into(), Value::Object(camera.clone()));
        NodeDecl {
            kind: decl.kind.clone(),
            params: p,
            inputs,
        }
    };
    let measure_model = |v: &Variant| -> (Candidate, f64) {
        let probe = model(&v.overrides, &camera);
        let measured_probe = probe.clone();
        let full = model(&v.overrides, &full_camera);
        let (error, probe_s, note, full_s, warned, fixed) = match measure(&measured_probe) {
            Ok((error, r)) => {
                // A lighting node the candidate reads is its camera-independent work: its
                // time (measured when it was computed, where it came from the cache) counts.
                let lit = lighting
                    .as_ref()
                    .filter(|_| v.overrides.is_empty())
                    .and_then(|l| seconds(&r, &l.node))
                    .unwrap_or(0.0);
                let probe_s = seconds(&r, CANDIDATE).map(|s| s + lit);
                // The camera-independent part once, the per-pixel stages in proportion.
                let per_pixel: f64 = per_pixel
                    .iter()
                    .map(|(k, unit)| timing(&r, k).unwrap_or(0.0) * unit)
                    .sum();
                let full_s = probe_s.map(|s| s + per_pixel * (pixel_scale - 1.0));
                let fixed = probe_s.map_or(0.0, |s| (s - per_pixel).max(0.0));
                (error, probe_s, None, full_s, warnings(&r, CANDIDATE), fixed)
            }
            Err(e) => (None, None, Some(e.to_string()), None, Vec::new(), 0.0),
        };
        let c = Candidate {
            name: v.label.clone(),
            family: "model",
            decl: full,
            probe,
            fits: fits(error),
            error,
            probe_s,
            full_s,
            note,
            warnings: warned,
        };
        (c, fixed)
    };
    let mut unique: Vec<&Variant> = Vec::new();
    // Compared with the lighting's parameters inlined: a switch that sets what the given
    // lighting already has is the render as given.
    let mut seen: Vec<Map<String, Value>> = Vec::new();
    for v in &variants {
        let mut p = params.clone();
        p.extend(v.overrides.iter().cloned());
        if !seen.contains(&p) {
            seen.push(p);
            unique.push(v);
        }
    }
    let mut measured: Vec<Option<Candidate>> = vec![None; unique.len()];
    let mut given_fixed = 0.0;
    for (i, v) in unique
        .iter()
        .enumerate()
        .filter(|(_, v)| !v.redoes_lighting)
    {
        let (c, fixed) = measure_model(v);
        if i == 0 {
            given_fixed = fixed;
        }
        measured[i] = Some(c);
    }

    // Brute force, where what the graph reads from the render, render.reference makes too.
    let readable_ports: BTreeSet<String> = readable.iter().map(|(s, _)| s.to_string()).collect();
    let missing: Vec<String> = ports_read(file, render)
        .difference(&readable_ports)
        .cloned()
        .collect();
    phase("models");
    let brute = if missing.is_empty() {
        // Aimed at AIM of the budget from the truth's noise (its many samples estimate the
        // per-sample constant best), then re-aimed from its measured error where that is over
        // the budget or under 0.6 of it (at most twice; FLIP's fall with the samples measured
        // from two renders, relative RMSE's is 1/√samples).
        let per_sample = truth_noise
            .map(|n| n * (truth_samples as f64).sqrt())
            .or(pilot_noise.map(|n| n * (PILOT as f64).sqrt()));
        // At a FLIP budget the truth's noise stays in the measure, so brute force at more
        // samples than the truth measures the truth's noise, not its own: the truth's samples
        // are its most (a FLIP budget on a whole-view probe once took brute force to thousands
        // of samples a pixel and planning past a quarter of an hour).
        let most = match o.measure {
            Measure::RelativeRmse => 65_536.0,
            Measure::Flip { .. } => truth_samples as f64,
        };
        let clamp = |x: f64| x.ceil().clamp(1.0, most) as u32;
        // The samples of a render whose noise the two full-view pilots' FLIP measures.
        let twin_samples = PILOT as f64 / 2.0;
        let mut samples = match full_noise_flip {
            Some(f) => clamp(twin_samples * (f / (AIM * o.budget)).powi(2)),
            None => per_sample.map_or(PILOT, |c| clamp((c * to_full / (AIM * o.budget)).powi(2))),
        };
        // At a FLIP budget: the probe pilot's FLIP against the truth, so that the first try
        // measures FLIP's fall with the samples on the probe.
        let probe_pilot_flip = match full_noise_flip {
            Some(_) => measure(&reference(PILOT, 1, &camera))?
                .0
                .filter(|e| *e > 0.0),
            None => None,
        };
        // Each try: samples, its error on the full view (its probe error, noise, scaled by the
        // pilots' ratio), the report.
        let mut tried: Vec<(u32, Option<f64>, RunReport)> = Vec::new();
        for _ in 0..3 {
            let (error, r) = measure(&reference(samples, 1, &camera))?;
            let error = match (full_noise_flip, probe_pilot_flip, error) {
                // Brute force's FLIP on the full view, from the pilots' twin FLIP, falling with
                // the samples as the probe measured it fall from its pilot (FLIP ∝ samples^(−γ/2)).
                (Some(f), Some(e0), Some(e)) if e > 0.0 && samples != PILOT => {
                    let g = -2.0 * (e / e0).ln() / (samples as f64 / PILOT as f64).ln();
                    let g = if g.is_finite() {
                        g.clamp(0.3, 1.5)
                    } else {
                        1.0
                    };
                    Some(f * (samples as f64 / twin_samples).powf(-g / 2.0))
                }
                (Some(f), _, Some(_)) => Some(f * (samples as f64 / twin_samples).powf(-0.5)),
                _ => error.map(|e| e * to_full),
            };
            tried.push((samples, error, r));
            let Some(e) = error.filter(|e| *e > 0.0) else {
                break;
            };
            if (0.6 * o.budget..=o.budget).contains(&e) {
                break;
            }
            // The error's fall with the samples: e ∝ samples^(−γ/2).
            let gamma = match (o.measure, tried.len()) {
                (Measure::Flip { .. }, n) if n >= 2 => {
                    let (s0, e0) = (tried[n - 2].0 as f64, tried[n - 2].1.unwrap_or(0.0));
                    let (s1, e1) = (tried[n - 1].0 as f64, e);
                    let g = -2.0 * (e1 / e0).ln() / (s1 / s0).ln();
                    if g.is_finite() {
                        g.clamp(0.3, 1.5)
                    } else {
                        1.0
                    }
                }
                _ => 1.0,
            };
            let next = clamp(samples as f64 * (e / (AIM * o.budget)).powf(2.0 / gamma));
            if next == samples || tried.iter().any(|t| t.0 == next) {
                break;
            }
            samples = next;
        }
        // The fewest samples within the budget; where none is, the most accurate.
        let pick = tried
            .iter()
            .filter(|t| fits(t.1))
            .min_by_key(|t| t.0)
            .or_else(|| {
                tried.iter().filter(|t| t.1.is_some()).min_by(|a, b| {
                    a.1.unwrap_or(f64::INFINITY)
                        .total_cmp(&b.1.unwrap_or(f64::INFINITY))
                })
            })
            .unwrap_or(&tried[0]);
        let (samples, error, r) = (pick.0, pick.1, &pick.2);
        let probe_s = seconds(r, CANDIDATE);
        let trace = timing(r, "trace_seconds").or(probe_s);
        let mut warned = warnings(r, CANDIDATE);
        // A brute-force plan states its noise (its seed is fixed, so frames do not flicker).
        if let Some(n) = metric(r, CANDIDATE, "noise") {
            warned.push(format!(
                "its own noise: relative RMSE {n:.3} on the probe, {:.3} on the full view (the pilots' ratio {to_full:.2}), at {samples} samples a pixel (seed fixed: the same noise every frame)",
                n * to_full
            ));
        }
        if let (Some(f), Some(e)) = (full_noise_flip, error) {
            warned.push(format!(
                "its FLIP on the full view, {e:.3} at {samples} samples a pixel, is estimated from two full-view pilots on other seeds (their FLIP {f:.3}: one render's noise at {twin_samples} samples), falling with the samples as the probe measured: a whole-view probe's own FLIP of noise is not the frame's"
            ));
        }
        Candidate {
            name: format!("brute force: render.reference at {samples} samples a pixel"),
            family: "brute force",
            decl: reference(samples, 1, &full_camera),
            probe: reference(samples, 1, &camera),
            fits: fits(error),
            error,
            // Its BVH once (the pilot built it), its tracing as the full view's pilot traced.
            full_s: full_trace_per_sample
                .map(|t| bvh_s + t * samples as f64)
                .or(trace.map(|t| bvh_s + t / share)),
            probe_s,
            note: None,
            warnings: warned,
        }
    } else {
        Candidate {
            name: "brute force".into(),
            family: "brute force",
            decl: reference(PILOT, 1, &full_camera),
            probe: reference(PILOT, 1, &camera),
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

    phase("brute force");
    // The switches that redo the camera-independent work: at least half the given render's
    // (measured), so not measured where a candidate within the budget is already faster.
    for (i, v) in unique.iter().enumerate().filter(|(_, v)| v.redoes_lighting) {
        let best = measured
            .iter()
            .flatten()
            .chain(std::iter::once(&brute))
            .filter(|c| c.fits)
            .filter_map(|c| Some((c.full_s?, c.name.clone())))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let least = 0.5 * given_fixed;
        measured[i] = Some(match best {
            Some((t, who)) if least >= t => Candidate {
                name: v.label.clone(),
                family: "model",
                decl: model(&v.overrides, &full_camera),
                probe: model(&v.overrides, &camera),
                error: None,
                probe_s: None,
                full_s: None,
                fits: false,
                note: Some(format!(
                    "not measured: it redoes the camera-independent work that took {given_fixed:.2} s in the render as given, so it takes at least {least:.2} s; {who} is within the budget at {t:.2} s"
                )),
                warnings: Vec::new(),
            },
            _ => measure_model(v).0,
        });
    }
    phase("models that redo the lighting");
    let mut candidates: Vec<Candidate> = measured.into_iter().flatten().collect();
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
                "{}: {} {:.3} against the truth (budget {}), the fastest within it ({:.2} s estimated on the full view)",
                c.name,
                o.measure.name(),
                c.error.unwrap_or(f64::NAN),
                o.budget,
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
                        o.budget,
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
        budget: o.budget,
        measure: o.measure,
        resolution,
        share,
        whole_view,
        probe_note,
        truth_samples,
        truth_noise,
        pilot_noise,
        truth_renders,
        probe_scene: {
            let mut g = scene.clone();
            g.nodes.push((TRUTH.into(), truth.clone()));
            g
        },
        candidates,
        chosen,
        why,
        planned,
        plan_s: start.elapsed().as_secs_f64(),
        phases,
    })
}
