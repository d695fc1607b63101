//! Planning one view end to end, as the command line, Python and the benches do: measure the
//! render's view with the probe, decide each stage, check the planned graph, and describe the
//! plan as `<graph>.plan.json` holds it.

use crate::verify::{prove, Ask, ProbeOptions, Proof};
use crate::{btf_chain, plan, probe, Budget, Plan, PlanError, RenderKind, Scene, Split};
use mesoflow_graph::GraphFile;
use mesoflow_runtime::{Engine, RunOptions};
use serde_json::{json, Map, Value};
use std::time::Instant;

/// A view planned: what the probe measured, and the plan.
pub struct Planned {
    pub render: String,
    pub kind: RenderKind,
    pub scene: Scene,
    pub budget: Budget,
    pub split: Split,
    pub plan: Plan,
    /// What the probes of the view measured (absent where the plan was not proved on one).
    pub proof: Option<Proof>,
}

/// The renderer kind of node `render`, or why it cannot be planned.
pub fn render_kind(file: &GraphFile, render: &str) -> Result<RenderKind, PlanError> {
    let decl = file.node(render).ok_or_else(|| {
        let hint =
            mesoflow_graph::did_you_mean(render, file.nodes.iter().map(|(id, _)| id.as_str()));
        PlanError::NoRender(format!("no node `{render}`{hint}"))
    })?;
    RenderKind::of(&decl.kind).ok_or_else(|| {
        PlanError::NoRender(format!(
            "a `{}` node; the planner plans render.mesh, sss.render and qh.render",
            decl.kind
        ))
    })
}

/// Plans `render` of `file` (checked by the caller) for `budget`: measures the view on `engine`
/// with `opts` (see [`probe::measure`]), decides, proves the plan on a probe of the view where
/// `probe` is given (see [`crate::verify`]; `None`: the measured model alone), and checks the
/// planned graph against the engine's catalog. `name` names the graph in errors.
#[allow(clippy::too_many_arguments)]
pub fn plan_view(
    engine: &Engine,
    name: &str,
    file: &GraphFile,
    render: &str,
    budget: Budget,
    split: Split,
    opts: RunOptions,
    probe: Option<ProbeOptions>,
) -> Result<Planned, PlanError> {
    let start = Instant::now();
    let kind = render_kind(file, render)?;
    budget.check()?;
    let scene = probe::measure(engine, name, file, render, kind, opts.same_policy())?;
    let chain = kind
        .btf_port()
        .and_then(|port| btf_chain(file, render, port));
    let (p, proof) = match probe {
        Some(options) => {
            let ask = Ask {
                engine,
                name,
                file,
                render,
                kind,
                scene: &scene,
                chain: chain.as_ref(),
                budget,
                split,
                opts: &opts,
            };
            let (p, proof) = prove(&ask, options, start)?;
            (p, Some(proof))
        }
        None => (
            plan(file, render, kind, &scene, chain.as_ref(), budget, split)?,
            None,
        ),
    };
    mesoflow_graph::check(name, &p.file, engine.registry())
        .map_err(|e| PlanError::Invalid(e.to_string().trim_end().to_string()))?;
    Ok(Planned {
        render: render.to_string(),
        kind,
        scene,
        budget,
        split,
        plan: p,
        proof,
    })
}

impl Planned {
    /// Stage errors are taken to add; one unknown leaves the total unknown (`None`).
    pub fn predicted_error(&self) -> Option<f64> {
        self.plan.decisions.iter().map(|d| d.predicted_error).sum()
    }

    /// The plan as `<graph>.plan.json` holds it (the caller adds where the graphs are).
    pub fn to_json(&self) -> Value {
        let decisions: Vec<Value> = self
            .plan
            .decisions
            .iter()
            .map(|d| {
                let mut o = Map::new();
                o.insert("stage".into(), json!(d.stage));
                o.insert("choice".into(), d.choice.clone());
                o.insert("reason".into(), json!(d.reason));
                if let Some(e) = d.predicted_error {
                    o.insert("predicted_error".into(), json!(e));
                }
                if let Some(c) = &d.predicted_cost {
                    o.insert("predicted_cost".into(), c.clone());
                }
                Value::Object(o)
            })
            .collect();
        let ppd = self.budget.ppd;
        let mut doc = json!({
            "render": self.render,
            "kind": self.kind.name(),
            "budget": { "flip": self.budget.flip, "ppd": ppd },
            "calibrated_ppd": self.plan.calibrated_ppd,
            "scene": self.scene.to_json(),
            "decisions": decisions,
            "split": if self.split == Split::Joint { "joint" } else { "equal" },
            "shares": self.plan.shares.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<Map<String, Value>>(),
            "calibration": "plan/plan_calibration.json (benches/plan_calibrate.rs, a scene of its own); benches/plan_verify.rs measures the plan on graphs/plan_verify.json",
        });
        if let Some(t) = self.predicted_error() {
            doc["predicted_error"] = json!(t);
        }
        if let Some(p) = &self.proof {
            doc["probe"] = p.to_json();
            if let Some(f) = p.flip() {
                doc["probed_error"] = json!(f);
            }
        }
        if !self.plan.ppd_inside {
            doc["ppd_note"] = json!(format!(
                "{ppd:.1} pixels per degree is beyond the calibrated {:.0}: predictions may be low",
                self.plan.calibrated_ppd
            ));
        }
        doc
    }
}
