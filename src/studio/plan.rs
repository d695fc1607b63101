//! The studio's planner: `POST /api/plan` plans a render node of the graph being edited — against
//! the truth the graph makes at a relative RMSE budget (every candidate, brute force included,
//! measured against it: `mesoflow_plan::arbitrate`), or against its own model at a FLIP budget
//! (`plan_view`) — on a thread, one plan at a time (a new one stops the old). The page shows the
//! decisions as they were measured (`GET /api/plan`), and `POST /api/plan/apply` makes the
//! planned graph the edit, through the validator like any other, so a run and its previews follow.

use super::plan_state::{PlanState, PREVIEWS};
use super::session::{Problem, Refused, Studio};
use mesoflow_graph::PortRef;
use mesoflow_runtime::{SilentObserver, ValueRef};
use serde::Deserialize;
use serde_json::json;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// What the page asks for.
#[derive(Deserialize)]
pub struct PlanSpec {
    pub render: String,
    pub budget: f64,
    /// `truth` (the default: relative RMSE against the truth the graph makes) or `model` (FLIP
    /// against the graph's own model).
    #[serde(default = "truth")]
    pub against: String,
}

fn truth() -> String {
    "truth".into()
}

fn refused(m: impl Into<String>) -> Refused {
    Refused {
        errors: vec![Problem::plain(m)],
    }
}

/// Starts planning; its id. Refused at once for a budget out of range, an unknown node or a
/// graph with errors; the planner's own errors (no truth can be made, …) arrive as the plan's.
pub fn start(studio: &Arc<Studio>, spec: PlanSpec) -> Result<u64, Refused> {
    if !(spec.budget.is_finite() && spec.budget > 0.0 && spec.budget <= 10.0) {
        return Err(refused(format!(
            "budget {}: a relative RMSE or FLIP in (0, 10]",
            spec.budget
        )));
    }
    if spec.against != "truth" && spec.against != "model" {
        return Err(refused(format!(
            "against {:?}: \"truth\" or \"model\"",
            spec.against
        )));
    }
    let (file, revision) = {
        let doc = studio.doc();
        if doc.checked.is_none() {
            return Err(refused("the graph has errors; fix them to plan it"));
        }
        // The planner edits nodes one by one: subgraphs inlined (their nodes under their paths).
        let flat = mesoflow_graph::subgraph::expand(&doc.file)
            .map_err(|e| refused(e.first().map(|e| e.to_string()).unwrap_or_default()))?;
        if flat.node(&spec.render).is_none() {
            return Err(refused(format!("no node `{}`", spec.render)));
        }
        (flat, doc.revision)
    };
    let cancel = Arc::new(AtomicBool::new(false));
    let id = {
        let mut st = studio.plan.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = &st.cancel {
            c.store(true, Ordering::SeqCst);
        }
        *st = PlanState {
            id: st.id + 1,
            running: true,
            render: spec.render.clone(),
            against: spec.against.clone(),
            budget: spec.budget,
            revision,
            cancel: Some(cancel.clone()),
            ..PlanState::default()
        };
        st.id
    };
    studio.hub.publish(
        "plan_started",
        json!({ "plan": id, "render": spec.render, "budget": spec.budget, "against": spec.against }),
    );
    let studio = studio.clone();
    std::thread::spawn(move || {
        let opts = studio.options(&studio.out_dir.join("plan"), cancel);
        let name = studio.graph_path.display().to_string();
        let result = if spec.against == "truth" {
            mesoflow_plan::arbitrate(
                &studio.engine,
                &name,
                &file,
                &spec.render,
                &opts,
                mesoflow_plan::TruthOptions {
                    budget: spec.budget,
                    measure: mesoflow_plan::Measure::RelativeRmse,
                    share: mesoflow_plan::TRUTH_SHARE,
                },
            )
            .map(|a| (a.to_json(), a.planned.clone(), Some(a.previews())))
        } else {
            mesoflow_plan::plan_view(
                &studio.engine,
                &name,
                &file,
                &spec.render,
                mesoflow_plan::Budget {
                    flip: spec.budget,
                    ppd: mesoflow_nodes::image::flip::DEFAULT_PPD,
                },
                mesoflow_plan::Split::Joint,
                opts,
                Some(mesoflow_plan::ProbeOptions::default()),
            )
            .map(|p| (p.to_json(), p.plan.file, None))
        };
        let mut st = studio.plan.lock().unwrap_or_else(|e| e.into_inner());
        if st.id != id {
            return;
        }
        st.running = false;
        st.cancel = None;
        match result {
            Ok((doc, planned, previews)) => {
                st.doc = Some(doc);
                st.planned = Some(planned);
                st.previews = previews;
            }
            Err(e) => st.error = Some(e.to_string()),
        }
        let error = st.error.clone();
        drop(st);
        studio
            .hub
            .publish("plan_done", json!({ "plan": id, "error": error }));
    });
    Ok(id)
}

/// Makes the last plan's graph the edit; refused while it runs, without one, or when the graph
/// changed since it was planned.
pub fn apply(studio: &Studio) -> Result<u64, Refused> {
    let (planned, revision) = {
        let st = studio.plan.lock().unwrap_or_else(|e| e.into_inner());
        match (&st.planned, st.running) {
            (_, true) => return Err(refused("the plan is still running")),
            (None, _) => return Err(refused("no plan to apply: plan a render first")),
            (Some(p), false) => (p.clone(), st.revision),
        }
    };
    if studio.doc().revision != revision {
        return Err(refused(
            "the graph changed since it was planned: plan it again",
        ));
    }
    studio.edit(true, move |f| {
        *f = planned;
        Ok(())
    })
}

/// One of the last plan's previews (`GET /api/plan/pixels?image=NAME`): its renders come from the
/// cache the plan filled, the FLIP maps are computed on first asking.
pub fn preview(studio: &Studio, image: &str) -> Result<ValueRef, (u16, String)> {
    let (_, node, port) = PREVIEWS
        .iter()
        .find(|(name, ..)| *name == image)
        .ok_or_else(|| {
            let names: Vec<&str> = PREVIEWS.iter().map(|(n, ..)| *n).collect();
            (400, format!("image {image:?}: one of {}", names.join(", ")))
        })?;
    let graph = studio
        .plan
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .previews
        .clone()
        .ok_or((
            404,
            "no previews: plan a render against the truth first".to_string(),
        ))?;
    let checked = mesoflow_graph::check("plan previews", &graph, studio.engine.registry())
        .map_err(|e| (500, format!("the previews' graph: {e}")))?;
    let mut opts = studio.options(
        &studio.out_dir.join("plan"),
        Arc::new(AtomicBool::new(false)),
    );
    opts.outputs = vec![PortRef {
        node: node.to_string(),
        port: port.to_string(),
    }];
    let outcome = studio
        .engine
        .run_values(&checked, &opts, Arc::new(SilentObserver))
        .map_err(|e| (500, e.to_string()))?;
    outcome
        .values
        .get(*node)
        .and_then(|o| o.get(port))
        .cloned()
        .ok_or_else(|| (404, format!("{node}.{port}: not computed")))
}
