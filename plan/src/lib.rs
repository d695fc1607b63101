//! The planner's decisions: from what a view shows (`scene.footprint`'s measurements) and a FLIP
//! budget B (the mean FLIP over the object's pixels), the cheapest model per stage, each with its
//! reason, its predicted error and its predicted cost, as edits to the graph.
//!
//! - B = 0 asks for the full model: raw BTF at λ = 0, the MDF, the PBD profile gathered by brute
//!   force. B ≥ 1 (FLIP's whole range) allows the cheapest: the BTF's average BRDF at rank 1, no
//!   MDF, subsurface scattering as a BRDF. Never nothing.
//! - Otherwise each stage takes its share of B — for `render.mesh`'s BTF and MDF the share that
//!   predicts the least render time ([`Split::Joint`]) or half each ([`Split::Equal`]); half each
//!   for `qh.render`'s BTF and subsurface; all of it for `sss.render` — and the cheapest
//!   candidate whose error, predicted by the measured model ([`calibration`]), fits it:
//!   - BTF: PCA in YCbCr at rank r (chroma r/4) and level λ, by memory; none fits → the raw BTF;
//!   - MDF: left out when its predicted error fits (always when the shell projects under half a
//!     pixel); where kept, tabulated 8, 4 or 2 times coarser than its height field (the
//!     coarsest that still has a texel per pixel and is predicted within the share);
//!   - subsurface: the BRDF approximation, or the brute-force gather with samples 4, 2, 1 or ½
//!     pixel footprints apart (never closer than the default spacing), by render time; none
//!     fits → the full model's gather (brute force, default spacing). Scattering under half a
//!     pixel is always the BRDF approximation.
//!   - synthesis (a `synthesis.texture` the renderer reads): stopped 1 or 2 pyramid levels early
//!     (2 or 4 times fewer texels per side) when that still gives a texel per pixel and is
//!     predicted within a tenth of the budget.
//!
//! A prediction beyond the calibrated range (a view nearer or farther than any calibrated one)
//! is not trusted: there the stage keeps the graph's own model, except for the half-pixel rules
//! and the cheapest plan. Stage errors are assumed to add; the verification sweep (benches/plan_verify.rs) measures
//! how far that and the calibration carry to a scene that is not the calibration scene.
//!
//! With `--against truth` the judge is not the graph's own model but a truth the graph can
//! make, and the candidates cross model families, brute force included (`arbiter`).
//!
//! One module per stage (`btf`, `mdf`, `synthesis`, `sss`, `shadows`), the scene a probe
//! measures (`scene`) and how it is measured (`probe`), and the graph edits (`edit`) apart.

pub mod arbiter;
mod btf;
pub mod calibration;
mod edit;
mod mdf;
pub mod probe;
mod scene;
mod shadows;
mod sss;
mod synthesis;
pub mod verify;
pub mod view;

pub use arbiter::{arbitrate, Arbitration, Measure, TruthOptions, TRUTH, TRUTH_SHARE};
pub use btf::BtfModel;
pub use edit::btf_chain;
pub use scene::{texture_sources, Scene, TextureView};
pub use verify::{ProbeOptions, Proof, PROBE_SHARE};
pub use view::{plan_view, render_kind, Planned};

use btf::{apply_btf, decide_btf, range_note};
use edit::{prune, upsert};
use mdf::{decide_mdf, decide_mdf_resolution};
use mesoflow_graph::GraphFile;
use serde_json::Value;
use shadows::decide_shadows;
use sss::{decide_profile, decide_sss, decide_threshold};
use synthesis::decide_synthesis;

/// One decision: the stage, what was chosen, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    pub stage: &'static str,
    pub choice: Value,
    pub reason: String,
    /// The FLIP the measured model predicts for this choice (0 for the full model's own
    /// choice); absent where the model has nothing to say.
    pub predicted_error: Option<f64>,
    /// What the choice costs where it can be said before running (texels, samples); absent
    /// otherwise.
    pub predicted_cost: Option<Value>,
}

/// The renderers the planner knows, and their ports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderKind {
    Mesh,
    Sss,
    Qh,
}

impl RenderKind {
    /// The kind's name in graph files.
    pub fn name(self) -> &'static str {
        match self {
            RenderKind::Mesh => "render.mesh",
            RenderKind::Sss => "sss.render",
            RenderKind::Qh => "qh.render",
        }
    }
    pub fn of(kind: &str) -> Option<RenderKind> {
        match kind {
            "render.mesh" => Some(RenderKind::Mesh),
            "sss.render" => Some(RenderKind::Sss),
            "qh.render" => Some(RenderKind::Qh),
            _ => None,
        }
    }
    /// Stages sharing the budget.
    fn stages(self) -> f64 {
        match self {
            RenderKind::Sss => 1.0,
            RenderKind::Mesh | RenderKind::Qh => 2.0,
        }
    }
    /// The port the BTF (or local reflectance) arrives on.
    pub fn btf_port(self) -> Option<&'static str> {
        match self {
            RenderKind::Mesh => Some("btf"),
            RenderKind::Qh => Some("lrf"),
            RenderKind::Sss => None,
        }
    }
}

/// Why a plan cannot be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlanError {
    #[error("the camera is inside the mesh: no footprint to plan from; move `eye` outside")]
    CameraInside,
    #[error("budget {0}: a FLIP budget is a number ≥ 0")]
    Budget(f64),
    #[error("{0} pixels per degree: the viewer's ppd is a number ≥ 0.5")]
    Ppd(f64),
    #[error("{0}")]
    Calibration(String),
    #[error("the view's probe (scene.footprint) reported no finite `{0}`: cannot plan from an unknown view")]
    MissingMetric(&'static str),
    #[error("measuring the view failed: {0}")]
    Probe(String),
    #[error("{0}")]
    NoRender(String),
    /// `--against truth` where the graph cannot make a truth (why, in words): the graph's own
    /// model is the judge instead (`mesoflow plan` falls back to it for a FLIP budget).
    #[error("{0}")]
    NoTruth(String),
    #[error("the planned graph is invalid: {0}")]
    Invalid(String),
}

/// The chain a BTF reaches the renderer through.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfChain {
    /// The node and port giving the raw BTF (what `btf.pca` reads, or the renderer directly).
    pub raw: String,
    /// What the graph itself gives the renderer: the raw BTF, or a PCA basis of a rank and
    /// level (`None` where its rank is only known after running, `max_rmse` or `energy`). The
    /// plan never gives more than this: no candidate of a higher rank, a finer level or more
    /// memory, and where none fits the graph's own model is kept.
    pub given: Option<GivenBtf>,
}

/// The graph's own BTF model, as its chain declares it.
#[derive(Clone, Debug, PartialEq)]
pub enum GivenBtf {
    Raw,
    Pca {
        /// The renderer's input (`btf.lod`'s or `btf.pca`'s basis): what a plan that keeps the
        /// graph's model connects back.
        from: String,
        rank: u32,
        chroma_rank: u32,
        ycbcr: bool,
        level: f64,
    },
}

/// The error the view may show: mean FLIP over the object's pixels, for a viewer at `ppd`
/// pixels per degree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Budget {
    pub flip: f64,
    pub ppd: f64,
}

impl Budget {
    /// A budget is a FLIP ≥ 0 for a viewer at 0.5 pixels per degree or more.
    pub fn check(&self) -> Result<(), PlanError> {
        if !(self.flip.is_finite() && self.flip >= 0.0) {
            return Err(PlanError::Budget(self.flip));
        }
        if !(self.ppd.is_finite() && self.ppd >= 0.5) {
            return Err(PlanError::Ppd(self.ppd));
        }
        Ok(())
    }
}

#[cfg(test)]
impl Budget {
    /// `flip` at FLIP's default viewing condition (67 pixels per degree).
    pub fn flip(flip: f64) -> Budget {
        Budget {
            flip,
            ppd: mesoflow_nodes::image::flip::DEFAULT_PPD,
        }
    }
}

/// How a render's budget is shared between its BTF and MDF stages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Half each.
    Equal,
    /// Whichever share of nine (0, B/8, …, B) to the BTF gives the least predicted render time
    /// (the product of the stages' predicted time ratios; memory breaks ties): the budget goes
    /// where it saves the most time per unit of error.
    Joint,
}

/// Decisions and the graph edits that carry them out.
#[derive(Clone)]
pub struct Plan {
    pub decisions: Vec<Decision>,
    pub file: GraphFile,
    /// The budget each stage was given, by stage.
    pub shares: Vec<(&'static str, f64)>,
    /// The calibrated viewing condition the predictions are for, and whether the viewer's lies
    /// within the calibrated ones.
    pub calibrated_ppd: f64,
    pub ppd_inside: bool,
}

/// A decision's predicted render time over the full model's (1 where it says none).
fn time_ratio(d: &Decision) -> f64 {
    d.predicted_cost
        .as_ref()
        .and_then(|c| c["render_time_vs_full"].as_f64())
        .unwrap_or(1.0)
}

fn floats_of(d: &Decision) -> f64 {
    d.predicted_cost
        .as_ref()
        .and_then(|c| c["floats"].as_f64())
        .unwrap_or(f64::INFINITY)
}

const PREFIX: &str = "plan_";

/// What every stage's decision reads: the measured model, the graph as given, the render node
/// and what its view shows, and whether the budget asks for the full or the cheapest model.
#[derive(Clone, Copy)]
struct Stage<'a> {
    model: &'a calibration::Calibration,
    file: &'a GraphFile,
    render: &'a str,
    kind: RenderKind,
    scene: &'a Scene,
    full: bool,
    cheapest: bool,
    why_cheapest: &'a str,
    /// The graph's own BTF model (see [`BtfChain::given`]).
    btf_given: Option<&'a GivenBtf>,
}

/// Plans `render` (a node of `file`) for `budget`, from `scene`. `chain` is where its BTF comes
/// from (for renderers with one).
pub fn plan(
    file: &GraphFile,
    render: &str,
    kind: RenderKind,
    scene: &Scene,
    chain: Option<&BtfChain>,
    budget: Budget,
    split: Split,
) -> Result<Plan, PlanError> {
    budget.check()?;
    let b = budget.flip;
    if scene.camera_inside || scene.backfacing_fraction.is_some_and(|f| f > 0.5) {
        return Err(PlanError::CameraInside);
    }
    let model = calibration::Calibration::builtin(budget.ppd).map_err(PlanError::Calibration)?;
    let share = b / kind.stages();
    let mut out = file.clone();
    let mut decisions = Vec::new();
    let full = b == 0.0;
    let cheapest = b >= 1.0 || scene.visible_fraction == 0.0;
    let why_cheapest = if scene.visible_fraction == 0.0 {
        "the mesh is not in view: nothing it shows needs detail"
    } else {
        "a budget of 1 or more is FLIP's whole range: any model meets it"
    };
    let cx = Stage {
        model: &model,
        file,
        render,
        kind,
        scene,
        full,
        cheapest,
        why_cheapest,
        btf_given: chain.and_then(|c| c.given.as_ref()),
    };

    let mut shares = Vec::new();
    // The BTF's share: half for the equal split; for the joint split, the one of nine that
    // predicts the least render time for BTF and MDF together.
    let mdf_connected = kind == RenderKind::Mesh
        && file
            .node(render)
            .is_some_and(|n| n.inputs.contains_key("mdf"));
    let btf_share = match (split, kind.btf_port().zip(chain), mdf_connected) {
        (Split::Joint, Some(_), true) if !full && !cheapest => {
            // Inside this arm neither the full nor the cheapest model is asked for.
            let try_share = |s: f64| {
                let (bd, _) = decide_btf(&cx, s);
                let mut scratch = file.clone();
                let md = decide_mdf(&cx, &mut scratch, b - s);
                let t = time_ratio(&bd) * md.as_ref().map_or(1.0, time_ratio);
                (t, floats_of(&bd))
            };
            (0..=8)
                .map(|k| b * k as f64 / 8.0)
                .map(|s| (s, try_share(s)))
                .min_by(|x, y| x.1 .0.total_cmp(&y.1 .0).then(x.1 .1.total_cmp(&y.1 .1)))
                .map_or(share, |(s, _)| s)
        }
        _ => share,
    };
    if let (Some(port), Some(chain)) = (kind.btf_port(), chain) {
        let d = decide_btf(&cx, btf_share);
        apply_btf(&mut out, render, port, chain, &d.1);
        decisions.push(d.0);
        shares.push(("btf", btf_share));
    }
    if kind == RenderKind::Mesh {
        let mdf_share = if chain.is_some() {
            b - btf_share
        } else {
            share
        };
        if let Some(d) = decide_mdf(&cx, &mut out, mdf_share) {
            decisions.push(d);
            shares.push(("mdf", mdf_share));
            if let Some(d) = decide_mdf_resolution(&cx, &mut out, mdf_share) {
                decisions.push(d);
            }
        }
    }
    if matches!(kind, RenderKind::Sss | RenderKind::Qh) {
        decisions.push(decide_sss(&cx, &mut out, share));
        shares.push(("sss", share));
        if let Some(d) = decide_threshold(&cx, &mut out, share) {
            decisions.push(d);
        }
        if let Some(d) = decide_profile(&cx, &mut out, share) {
            decisions.push(d);
        }
    }
    if let Some(d) = decide_shadows(&cx, &mut out, b) {
        decisions.push(d);
    }
    decisions.extend(decide_synthesis(&cx, &mut out, b));
    prune(&mut out, file, render);
    Ok(Plan {
        decisions,
        file: out,
        shares,
        calibrated_ppd: model.ppd,
        ppd_inside: model.ppd_inside,
    })
}

#[cfg(test)]
mod tests;
