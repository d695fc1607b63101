//! Proving a plan on the view itself: the measured model proposes, a probe judges. The probe
//! is the user's own view on a reduced frame (the centre of the render's camera at the same
//! pixels per degree: the same footprint, fewer pixels), rendered twice through the engine and
//! its cache — the graph as given and the candidate — and compared by FLIP over the object's
//! pixels. A candidate is kept when its probed FLIP is within the budget and its measured frame
//! is not slower than the given graph's on the same probe (the same device); otherwise the plan
//! steps up (the measured model asked for half the error: more rank, the MDF back, finer
//! spacing) until one is, and where none is, or the probing time runs out, the plan is the
//! graph itself. The measured model's first proposal that fits is also tried one step cheaper
//! (twice the budget), so a prior that is too careful does not keep model the view cannot show.

use crate::{plan, BtfChain, Budget, Decision, Plan, PlanError, RenderKind, Scene, Split};
use mesoflow_graph::{Catalog, GraphFile, NodeDecl};
use mesoflow_nodes::support::raytrace::camera::CameraParams;
use mesoflow_runtime::{Engine, NodeStatus, RunOptions, RunReport, SilentObserver};
use serde_json::{json, Map, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::Instant;

/// The probe's FLIP node in the probe graph.
pub const FLIP: &str = "plan_probe_flip";
/// The prefix of the candidate's nodes (those the plan changed) in the probe graph.
pub const CANDIDATE: &str = "plan_probe_candidate_";

/// The probe's share of the view's pixels by default.
pub const PROBE_SHARE: f64 = 0.25;

/// How the plan is proved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeOptions {
    /// The probe frame's share of the render's pixels, in (0, 1]; each side at least 16 pixels.
    pub share: f64,
    /// The planning time the probes may spend, in renders of the full view (the given graph's
    /// frame scaled from the probe's): once spent, the plan is the graph itself.
    pub budget: f64,
}

impl Default for ProbeOptions {
    fn default() -> Self {
        ProbeOptions {
            share: PROBE_SHARE,
            budget: 1.0,
        }
    }
}

/// One candidate measured on the probe.
#[derive(Clone, Debug, PartialEq)]
pub struct Rung {
    /// What was probed: the measured model's plan for a budget, or a simplification the
    /// probe searched where the model had nothing within the budget.
    pub candidate: String,
    /// The budget the measured model was asked to plan for (absent for a searched one).
    pub prior_budget: Option<f64>,
    /// The model's predicted FLIP for it (absent where it could not say).
    pub predicted: Option<f64>,
    /// Its FLIP against the given graph on the probe (absent where the probe showed no object).
    pub flip: Option<f64>,
    /// Its frame on the probe, s (`frame_ms` where the renderer measures one, else the node's).
    pub frame_s: Option<f64>,
    /// Seconds this rung's probe computed (the candidate's own nodes and the comparison).
    pub spent_s: f64,
    pub fits: bool,
    pub faster: bool,
}

/// What the probes measured, and the outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct Proof {
    pub resolution: [u32; 2],
    /// The probe's pixels over the render's.
    pub share: f64,
    /// The given graph's frame on the probe, s, and one render of the full view estimated
    /// from the probe (its whole render time over its share of the pixels).
    pub given_frame_s: Option<f64>,
    pub full_frame_s: Option<f64>,
    pub rungs: Vec<Rung>,
    /// The rung kept; `None`: the graph itself.
    pub chosen: Option<usize>,
    pub why: String,
    /// Wall time of the whole plan (measuring the view, deciding and probing), s.
    pub plan_s: f64,
}

impl Proof {
    /// The chosen plan's probed FLIP (0 for the graph itself).
    pub fn flip(&self) -> Option<f64> {
        match self.chosen {
            Some(i) => self.rungs[i].flip,
            None => Some(0.0),
        }
    }

    pub fn to_json(&self) -> Value {
        let rungs: Vec<Value> = self
            .rungs
            .iter()
            .map(|r| {
                let mut o = Map::new();
                o.insert("candidate".into(), json!(r.candidate));
                if let Some(pb) = r.prior_budget {
                    o.insert("prior_budget".into(), json!(pb));
                }
                if let Some(p) = r.predicted {
                    o.insert("predicted_flip".into(), json!(p));
                }
                if let Some(f) = r.flip {
                    o.insert("probed_flip".into(), json!(f));
                }
                if let Some(t) = r.frame_s {
                    o.insert("frame_s".into(), json!(t));
                }
                o.insert("spent_s".into(), json!(r.spent_s));
                o.insert("fits".into(), json!(r.fits));
                o.insert("not_slower".into(), json!(r.faster));
                Value::Object(o)
            })
            .collect();
        let mut doc = json!({
            "resolution": self.resolution,
            "share": self.share,
            "rungs": rungs,
            "chosen": match self.chosen { Some(i) => json!(i), None => json!("the graph as given") },
            "why": self.why,
            "plan_seconds": self.plan_s,
        });
        if let Some(t) = self.given_frame_s {
            doc["given_frame_s"] = json!(t);
        }
        if let Some(t) = self.full_frame_s {
            doc["full_render_s_estimate"] = json!(t);
        }
        if let Some(f) = self.flip() {
            doc["probed_flip"] = json!(f);
        }
        doc
    }
}

/// The render node's camera with the kind's defaults filled in.
pub(crate) fn camera_of(
    file: &GraphFile,
    render: &str,
    catalog: &dyn Catalog,
) -> Map<String, Value> {
    let kind = file
        .node(render)
        .map(|n| n.kind.clone())
        .unwrap_or_default();
    let mut cam = crate::probe::kind_default(catalog, &kind, "camera")
        .and_then(|c| c.as_object().cloned())
        .unwrap_or_default();
    if let Some(Value::Object(given)) = file.node(render).and_then(|n| n.params.get("camera")) {
        for (k, v) in given {
            cam.insert(k.clone(), v.clone());
        }
    }
    cam
}

/// A render's camera as the kinds read it (`CameraParams`: its defaults where the graph gives
/// none). The camera comes from a checked graph, so it parses; the defaults stand in otherwise.
fn typed(cam: &Map<String, Value>) -> CameraParams {
    serde_json::from_value(Value::Object(cam.clone())).unwrap_or_default()
}

/// A camera's `resolution`, as the render kinds read it.
pub fn resolution_of(cam: &Map<String, Value>) -> [u32; 2] {
    typed(cam).resolution
}

/// `share` of a view's pixels, each side at least 16 and at most the view's: the probe's size
/// and the share it has.
fn probe_size(res: [u32; 2], share: f64) -> ([u32; 2], f64) {
    let k = share.clamp(0.0, 1.0).sqrt();
    let side = |n: u32| ((n as f64 * k).round() as u32).max(16).min(n);
    let probe = [side(res[0]), side(res[1])];
    let got = (probe[0] as f64 * probe[1] as f64) / (res[0] as f64 * res[1] as f64).max(1.0);
    (probe, got)
}

/// The probe's camera: the centre `share` of the render's pixels at the same pixels per degree
/// (the field of view narrowed with the frame), and the share it has.
pub fn probe_camera(
    mut cam: Map<String, Value>,
    share: f64,
) -> (Map<String, Value>, [u32; 2], f64) {
    let full = typed(&cam);
    let (probe, got) = probe_size(full.resolution, share);
    // The graph's own map with the crop's fields written in (the others as the graph gave them,
    // so the probe's keys name what the graph names).
    let crop = full.centre_crop(probe);
    match crop.orthographic {
        Some(h) => cam.insert("orthographic".into(), json!(h)),
        None => cam.insert("fov".into(), json!(crop.fov)),
    };
    cam.insert("resolution".into(), json!(probe));
    (cam, probe, got)
}

/// The whole view at a lower resolution: `share` of the pixels, each side at least 16 (and at
/// most the view's), the field of view unchanged; the camera and its share. Each pixel then
/// subtends a larger angle: for renders whose error does not hang on the pixel's footprint.
pub fn scaled_camera(
    mut cam: Map<String, Value>,
    share: f64,
) -> (Map<String, Value>, [u32; 2], f64) {
    let (probe, got) = probe_size(resolution_of(&cam), share);
    cam.insert("resolution".into(), json!(probe));
    (cam, probe, got)
}

fn upstream(from: &str) -> Option<&str> {
    from.split_once('.').map(|(n, _)| n)
}

/// The probe graph for `planned` against `file`: the given render and the candidate's (every
/// node the plan changed or added, and whatever reads them, under [`CANDIDATE`] ids), both with
/// the probe's camera, and their FLIP over the object's pixels; only what those need.
pub fn probe_graph(
    file: &GraphFile,
    planned: &GraphFile,
    render: &str,
    camera: &Map<String, Value>,
    ppd: f64,
) -> GraphFile {
    let mut changed: BTreeSet<String> = planned
        .nodes
        .iter()
        .filter(|(id, d)| file.node(id) != Some(d))
        .map(|(id, _)| id.clone())
        .collect();
    changed.insert(render.to_string());
    loop {
        let more: Vec<String> = planned
            .nodes
            .iter()
            .filter(|(id, d)| {
                !changed.contains(id)
                    && d.inputs
                        .values()
                        .any(|f| upstream(f).is_some_and(|n| changed.contains(n)))
            })
            .map(|(id, _)| id.clone())
            .collect();
        if more.is_empty() {
            break;
        }
        changed.extend(more);
    }
    let mut out = file.clone();
    let with_camera = |d: &mut NodeDecl| {
        d.params
            .insert("camera".into(), Value::Object(camera.clone()));
    };
    if let Some(d) = out.node_mut(render) {
        with_camera(d);
    }
    for (id, d) in &planned.nodes {
        if !changed.contains(id) {
            continue;
        }
        let mut d = d.clone();
        for from in d.inputs.values_mut() {
            if let Some((n, port)) = from.split_once('.') {
                if changed.contains(n) {
                    *from = format!("{CANDIDATE}{n}.{port}");
                }
            }
        }
        if id == render {
            with_camera(&mut d);
        }
        out.nodes.push((format!("{CANDIDATE}{id}"), d));
    }
    let mut params = Map::new();
    params.insert("object_only".into(), json!(true));
    params.insert("ppd".into(), json!(ppd));
    out.nodes.push((
        FLIP.into(),
        NodeDecl {
            kind: "image.flip".into(),
            params,
            inputs: BTreeMap::from([
                ("reference".to_string(), format!("{render}.image")),
                ("test".to_string(), format!("{CANDIDATE}{render}.image")),
            ]),
        },
    ));
    let keep = crate::probe::ancestors(&out, FLIP);
    out.nodes.retain(|(id, _)| keep.contains(id));
    out
}

/// A render node's frame in a report: `frame_ms` where the renderer measures one (without its
/// one-off set-up and read-back), else the node's compute time. A cache hit carries the timings
/// measured when it was computed.
pub fn frame_seconds(report: &RunReport, id: &str) -> Option<f64> {
    let n = report.node(id)?;
    n.timings
        .get("frame_ms")
        .map(|ms| ms / 1e3)
        .or_else(|| n.timings.get("seconds").copied())
        .or(Some(n.seconds).filter(|_| n.status == NodeStatus::Computed))
        .filter(|t| t.is_finite() && *t >= 0.0)
}

/// Runs `graph` through the engine for `outputs` (`(node, port)`), with `opts`' device, cache
/// and cancel flag; a failed node is an error.
pub(crate) fn run_for(
    engine: &Engine,
    name: &str,
    graph: &GraphFile,
    outputs: &[(&str, &str)],
    opts: &RunOptions,
) -> Result<RunReport, PlanError> {
    let checked = mesoflow_graph::check(name, graph, engine.registry())
        .map_err(|e| PlanError::Probe(e.to_string().trim_end().to_string()))?;
    let mut opts = opts.same_policy();
    opts.outputs = outputs
        .iter()
        .map(|(n, p)| mesoflow_graph::PortRef {
            node: n.to_string(),
            port: p.to_string(),
        })
        .collect();
    let report = engine
        .run(&checked, &opts, Arc::new(SilentObserver))
        .map_err(|e| PlanError::Probe(e.to_string()))?;
    crate::probe::failed(&report)?;
    Ok(report)
}

/// What one probe run measured: (FLIP, the given's frame, the candidate's frame, seconds the
/// candidate's nodes and the comparison computed).
struct Measured {
    flip: Option<f64>,
    given: Option<f64>,
    candidate: Option<f64>,
    /// The given render's whole compute time (set-up and read-back included), s.
    given_node: Option<f64>,
    spent: f64,
}

fn measure(
    engine: &Engine,
    name: &str,
    graph: &GraphFile,
    render: &str,
    opts: &RunOptions,
) -> Result<Measured, PlanError> {
    // Both renders asked for by name: a comparison served from the cache would otherwise
    // leave them out of the report, and their frames with them.
    let candidate = format!("{CANDIDATE}{render}");
    let report = run_for(
        engine,
        name,
        graph,
        &[
            (FLIP, "mean"),
            (render, "image"),
            (candidate.as_str(), "image"),
        ],
        opts,
    )?;
    let spent = report
        .nodes
        .iter()
        .filter(|n| n.status == NodeStatus::Computed)
        .filter(|n| n.id.starts_with(CANDIDATE) || n.id == FLIP || n.id == render)
        .map(|n| n.seconds)
        .sum();
    Ok(Measured {
        flip: report
            .node(FLIP)
            .and_then(|n| n.metrics.get("mean").copied())
            .filter(|v| v.is_finite()),
        given: frame_seconds(&report, render),
        given_node: report.node(render).and_then(|n| {
            n.timings
                .get("seconds")
                .copied()
                .or(Some(n.seconds).filter(|_| n.status == NodeStatus::Computed))
        }),
        candidate: frame_seconds(&report, &candidate),
        spent,
    })
}

/// The graph itself as a plan: every stage as written.
pub fn as_given(file: &GraphFile, reason: String, calibrated_ppd: f64, ppd_inside: bool) -> Plan {
    Plan {
        decisions: vec![Decision {
            stage: "graph",
            choice: json!({ "model": "as given" }),
            reason,
            predicted_error: Some(0.0),
            predicted_cost: Some(json!({ "render_time_vs_full": 1.0 })),
        }],
        file: file.clone(),
        shares: Vec::new(),
        calibrated_ppd,
        ppd_inside,
    }
}

/// What a proved plan needs from its caller: the graph, the render, what its view showed.
pub struct Ask<'a> {
    pub engine: &'a Engine,
    pub name: &'a str,
    pub file: &'a GraphFile,
    pub render: &'a str,
    pub kind: RenderKind,
    pub scene: &'a Scene,
    pub chain: Option<&'a BtfChain>,
    pub budget: Budget,
    pub split: Split,
    pub opts: &'a RunOptions,
}

/// Plans `ask` with the measured model and proves the plan on the probe (see the module's
/// doc), starting the clock at `start`.
pub fn prove(ask: &Ask, probe: ProbeOptions, start: Instant) -> Result<(Plan, Proof), PlanError> {
    let b = ask.budget.flip;
    let prior = |pb: f64| {
        plan(
            ask.file,
            ask.render,
            ask.kind,
            ask.scene,
            ask.chain,
            Budget {
                flip: pb,
                ..ask.budget
            },
            ask.split,
        )
    };
    let first = prior(b)?;
    let (cal_ppd, inside) = (first.calibrated_ppd, first.ppd_inside);
    let cam = camera_of(ask.file, ask.render, ask.engine.registry());
    let (mut camera, mut resolution, mut share) = probe_camera(cam.clone(), probe.share);
    let mut proof = Proof {
        resolution,
        share,
        given_frame_s: None,
        full_frame_s: None,
        rungs: Vec::new(),
        chosen: None,
        why: String::new(),
        plan_s: 0.0,
    };
    let finish = |mut proof: Proof, plan: Plan| {
        proof.plan_s = start.elapsed().as_secs_f64();
        Ok((plan, proof))
    };
    if b == 0.0 {
        proof.why = "budget 0: the graph as given (nothing to prove)".into();
        let p = as_given(ask.file, proof.why.clone(), cal_ppd, inside);
        return finish(proof, p);
    }
    let mut plans: Vec<Plan> = Vec::new();
    let mut spent = 0.0;
    // Probes one candidate graph: its FLIP against the graph and its frame beside the
    // graph's, on the probe (the whole frame instead where the probe's centre missed the
    // object). Returns (fits, not slower).
    let mut probe_one = |proof: &mut Proof,
                         p: &Plan,
                         candidate: String,
                         prior_budget: Option<f64>,
                         spent: &mut f64|
     -> Result<(bool, bool), PlanError> {
        let graph = probe_graph(ask.file, &p.file, ask.render, &camera, ask.budget.ppd);
        let mut m = measure(ask.engine, ask.name, &graph, ask.render, ask.opts)?;
        if m.flip.is_none() && share < 1.0 {
            (camera, resolution, share) = probe_camera(cam.clone(), 1.0);
            proof.resolution = resolution;
            proof.share = share;
            let graph = probe_graph(ask.file, &p.file, ask.render, &camera, ask.budget.ppd);
            m = measure(ask.engine, ask.name, &graph, ask.render, ask.opts)?;
        }
        if proof.given_frame_s.is_none() {
            proof.given_frame_s = m.given;
            // One render of the full view: the probe's whole render time scaled by its
            // share of the pixels (an estimate; the set-up does not scale, so it is high).
            proof.full_frame_s = m.given_node.or(m.given).map(|t| t / share);
        }
        *spent += m.spent;
        let fits = m.flip.is_some_and(|f| f <= b);
        let faster = match (m.candidate, proof.given_frame_s) {
            (Some(c), Some(g)) => c <= g,
            _ => false,
        };
        proof.rungs.push(Rung {
            candidate,
            prior_budget,
            predicted: p.decisions.iter().map(|d| d.predicted_error).sum(),
            flip: m.flip,
            frame_s: m.candidate,
            spent_s: m.spent,
            fits,
            faster,
        });
        Ok((fits, faster))
    };
    let out_of_time = |proof: &Proof, spent: f64| {
        let allowed = proof.full_frame_s.map_or(0.0, |t| probe.budget * t);
        (spent > allowed).then(|| {
            format!(
                "the probes spent {spent:.2} s, over the {allowed:.2} s allowed ({} full frames)",
                probe.budget
            )
        })
    };
    // The ladder: the model's plan for the budget, then for half, a quarter, … of it.
    let ladder = [1.0, 0.5, 0.25, 0.125, 0.0625];
    let mut step_down_tried = false;
    let mut i = 0;
    let mut queue: Vec<f64> = ladder.iter().map(|f| b * f).collect();
    let mut nothing_to_simplify = None;
    while i < queue.len() {
        let pb = queue[i];
        i += 1;
        let p = if plans.is_empty() && pb == b {
            first.clone()
        } else {
            prior(pb)?
        };
        if p.file == *ask.file && proof.chosen.is_none() {
            nothing_to_simplify = Some(p);
            break;
        }
        if plans.iter().any(|q| q.file == p.file) {
            continue;
        }
        let (fits, faster) = probe_one(
            &mut proof,
            &p,
            format!("the measured model's plan for {pb:.4}"),
            Some(pb),
            &mut spent,
        )?;
        plans.push(p);
        let r = proof.rungs.len() - 1;
        if fits && faster {
            proof.chosen = Some(r);
            // One step cheaper, once, where the model's first plan already fits.
            if pb == b && !step_down_tried && 2.0 * b < 1.0 {
                step_down_tried = true;
                queue = vec![2.0 * b];
                i = 0;
                continue;
            }
            break;
        }
        if fits && !faster {
            proof.why = "a plan within the budget measured no faster than the graph: more model would not be either".into();
            break;
        }
        if proof.chosen.is_some() {
            // The cheaper step missed: the plan that fitted stands.
            break;
        }
        if let Some(why) = out_of_time(&proof, spent) {
            proof.why = why;
            break;
        }
    }
    // Where the measured model had nothing within the budget (its plan is the graph itself,
    // or every plan it made missed), the probe searches the render's own simplifications,
    // stage by stage, the costlier first (see [`search`]).
    if proof.chosen.is_none() && ask.kind == RenderKind::Mesh && proof.why.is_empty() {
        let mut base = ask.file.clone();
        let mut level_kept = false;
        for (label, cand) in search(ask) {
            if level_kept && label.starts_with(LEVEL) {
                continue;
            }
            if let Some(why) = out_of_time(&proof, spent) {
                proof.why = why;
                break;
            }
            let mut file = cand(&base);
            if file == base {
                continue;
            }
            crate::edit::prune(&mut file, ask.file, ask.render);
            if plans.iter().any(|q| q.file == file) {
                // Probed already, as one of the measured model's plans (which missed).
                continue;
            }
            let p = Plan {
                decisions: vec![Decision {
                    stage: "probe",
                    choice: json!(label),
                    reason:
                        "searched on the probe: the measured model had nothing within the budget"
                            .into(),
                    predicted_error: None,
                    predicted_cost: None,
                }],
                file: file.clone(),
                shares: Vec::new(),
                calibrated_ppd: cal_ppd,
                ppd_inside: inside,
            };
            let (fits, faster) = probe_one(&mut proof, &p, label.clone(), None, &mut spent)?;
            plans.push(p);
            if fits && faster {
                proof.chosen = Some(proof.rungs.len() - 1);
                base = file;
                // The coarsest level that fits is kept: finer ones are not tried.
                level_kept |= label.starts_with(LEVEL);
            } else if label.starts_with(RANK) {
                // A lower rank missed: the ranks below would too.
                break;
            }
        }
        if proof.chosen.is_some() {
            proof.why.clear();
        }
    }
    if let (None, Some(p)) = (proof.chosen, nothing_to_simplify) {
        if proof.why.is_empty() {
            proof.why = "the measured model's plan is the graph itself, and no simplification the probe tried was within the budget and faster".into();
        }
        return finish(proof, p);
    }
    match proof.chosen {
        Some(r) => {
            let rung = &proof.rungs[r];
            proof.why = format!(
                "{}: probed FLIP {:.4} within the budget {b}, frame {:.4} s against the graph's {:.4} s",
                rung.candidate,
                rung.flip.unwrap_or(f64::NAN),
                rung.frame_s.unwrap_or(f64::NAN),
                proof.given_frame_s.unwrap_or(f64::NAN),
            );
            let p = plans.swap_remove(r);
            finish(proof, p)
        }
        None => {
            if proof.why.is_empty() {
                proof.why = "no plan the probe measured was within the budget and not slower than the graph: the graph as given".into();
            }
            let p = as_given(ask.file, proof.why.clone(), cal_ppd, inside);
            finish(proof, p)
        }
    }
}

/// The labels of the searched BTF candidates.
const LEVEL: &str = "btf basis at level";
const RANK: &str = "btf basis at rank";

/// A graph edit the probe tries.
type Edit = Box<dyn Fn(&GraphFile) -> GraphFile>;

/// The render's own simplifications, in the order the probe tries them, each applied to the
/// last one kept: the MDF out (the costlier stage of a `render.mesh` frame), then the BTF's
/// basis at the coarsest level the view still has a texel a pixel at, its rank halved down to 1
/// (never above the graph's rank, never finer than its level; from a raw BTF, rank 16 first).
fn search(ask: &Ask) -> Vec<(String, Edit)> {
    let render = ask.render.to_string();
    let mut out: Vec<(String, Edit)> = Vec::new();
    if ask
        .file
        .node(ask.render)
        .is_some_and(|n| n.inputs.contains_key("mdf"))
    {
        let r = render.clone();
        out.push((
            "mdf out".into(),
            Box::new(move |f: &GraphFile| {
                let mut f = f.clone();
                if let Some(n) = f.node_mut(&r) {
                    n.inputs.remove("mdf");
                    n.params.insert("use_mdf".into(), json!(false));
                }
                f
            }),
        ));
    }
    let Some(chain) = ask.chain.cloned() else {
        return out;
    };
    let (rank, given_level) = match &chain.given {
        Some(crate::GivenBtf::Pca { rank, level, .. }) => (*rank, *level),
        Some(crate::GivenBtf::Raw) => (32, 0.0),
        None => return out,
    };
    let tpp = ask.scene.texels_per_pixel.unwrap_or(1.0);
    let coarsest = ask
        .scene
        .tile_texels
        .map_or(0.0, |t| t.max(1.0).log2().floor());
    let top = tpp.max(1.0).log2().floor().min(coarsest).max(given_level);
    let port = ask.kind.btf_port().unwrap_or("btf");
    let basis = move |render: &str, chain: &BtfChain, f: &GraphFile, rank: u32, level: f64| {
        let mut f = f.clone();
        let model = crate::BtfModel {
            given: false,
            raw: false,
            level,
            rank,
            chroma_rank: (rank / 4).max(1),
        };
        crate::btf::apply_btf(&mut f, render, port, chain, &model);
        f
    };
    // The level first, at the graph's rank: the coarsest with a texel a pixel, then finer.
    let mut level = top;
    while level > given_level || chain.given == Some(crate::GivenBtf::Raw) {
        let (render, chain) = (render.clone(), chain.clone());
        out.push((
            format!("{LEVEL} {level} at rank {rank}"),
            Box::new(move |f: &GraphFile| basis(&render, &chain, f, rank, level)),
        ));
        if level <= given_level {
            break;
        }
        level -= 1.0;
    }
    // Then the rank halved at the level kept (the graph's where none was).
    let mut r = rank / 2;
    while r >= 1 {
        let (render, chain) = (render.clone(), chain.clone());
        out.push((
            format!("{RANK} {r}"),
            Box::new(move |f: &GraphFile| {
                let level = f
                    .node(&format!("{}lod", crate::PREFIX))
                    .and_then(|n| n.params.get("level"))
                    .and_then(Value::as_f64)
                    .unwrap_or(given_level);
                basis(&render, &chain, f, r, level)
            }),
        ));
        r /= 2;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_probe_keeps_the_pixels_per_degree() {
        // A pixel at the frame's centre subtends the same angle on the probe as on the render:
        // tan(fov'/2)/h' = tan(fov/2)/h.
        let cam: Map<String, Value> =
            serde_json::from_value(json!({"fov": 42.0, "resolution": [240, 180]})).unwrap();
        let (probe, res, share) = probe_camera(cam, 0.25);
        assert_eq!(res, [120, 90]);
        assert!((share - 0.25).abs() < 1e-12);
        let fov = probe["fov"].as_f64().unwrap();
        let per_pixel = |f: f64, h: f64| (f.to_radians() / 2.0).tan() / h;
        assert!((per_pixel(fov, 90.0) - per_pixel(42.0, 180.0)).abs() < 1e-12);
        // Orthographic: the half height scales with the rows; never under 16 pixels a side.
        let cam: Map<String, Value> =
            serde_json::from_value(json!({"orthographic": 2.0, "resolution": [40, 20]})).unwrap();
        let (probe, res, _) = probe_camera(cam, 0.01);
        assert_eq!(res, [16, 16]);
        assert!((probe["orthographic"].as_f64().unwrap() - 2.0 * 16.0 / 20.0).abs() < 1e-12);
    }

    #[test]
    fn the_probe_graph_renders_the_given_and_the_changed_nodes_side_by_side() {
        let file = GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {
              "hf": {"kind": "heightfield.procedural"},
              "capture": {"kind": "btf.capture", "inputs": {"height": "hf.height"}},
              "mdf": {"kind": "mdf.tabulate", "inputs": {"height": "hf.height"}},
              "torus": {"kind": "mesh.primitive"},
              "r": {"kind": "render.mesh", "inputs": {"mesh": "torus.mesh", "btf": "capture.btf", "mdf": "mdf.mdf"}},
              "png": {"kind": "image.write", "inputs": {"image": "r.image"}, "params": {"path": "r.png"}}
            }}"#,
        )
        .unwrap();
        let mut planned = file.clone();
        planned
            .node_mut("mdf")
            .unwrap()
            .params
            .insert("resolution".into(), json!(16));
        let cam: Map<String, Value> = serde_json::from_value(json!({"fov": 30.0})).unwrap();
        let g = probe_graph(&file, &planned, "r", &cam, 67.0);
        let ids: BTreeSet<&str> = g.nodes.iter().map(|(id, _)| id.as_str()).collect();
        // The changed table and the render that reads it under candidate ids, the unchanged
        // capture and mesh shared, the writer left out.
        for id in ["hf", "capture", "mdf", "torus", "r", FLIP] {
            assert!(ids.contains(id), "{id} in {ids:?}");
        }
        assert!(ids.contains(format!("{CANDIDATE}mdf").as_str()));
        assert!(ids.contains(format!("{CANDIDATE}r").as_str()));
        assert!(!ids.contains("png") && !ids.contains(format!("{CANDIDATE}capture").as_str()));
        let c = g.node(&format!("{CANDIDATE}r")).unwrap();
        assert_eq!(c.inputs["mdf"], format!("{CANDIDATE}mdf.mdf"));
        assert_eq!(c.inputs["btf"], "capture.btf");
        assert_eq!(c.params["camera"], json!(cam));
        assert_eq!(g.node("r").unwrap().params["camera"], json!(cam));
    }
}
