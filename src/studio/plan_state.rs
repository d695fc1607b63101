//! The studio's plan as the page sees it: which render, judge and budget, whether it runs, the
//! plan document and the planned graph, its error, and the flag that stops it. `Studio` holds
//! one; `plan.rs` runs it (so `session.rs` and `plan.rs` do not import each other).

use mesoflow_graph::GraphFile;
use mesoflow_plan::arbiter::{
    PREVIEW_GIVEN, PREVIEW_GIVEN_ERROR, PREVIEW_PLANNED, PREVIEW_PLANNED_ERROR, TRUTH,
};
use serde_json::{json, Value};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// The plan's previews by name: the node and port in `Arbitration::previews`.
pub const PREVIEWS: [(&str, &str, &str); 5] = [
    ("truth", TRUTH, "image"),
    ("given", PREVIEW_GIVEN, "image"),
    ("planned", PREVIEW_PLANNED, "image"),
    ("given_error", PREVIEW_GIVEN_ERROR, "preview"),
    ("planned_error", PREVIEW_PLANNED_ERROR, "preview"),
];

/// The last plan asked for, as the page sees it.
#[derive(Default)]
pub struct PlanState {
    pub id: u64,
    pub running: bool,
    pub render: String,
    pub against: String,
    pub budget: f64,
    /// The graph's revision the plan was made of: applying it to a later one is refused.
    pub revision: u64,
    pub doc: Option<Value>,
    pub planned: Option<GraphFile>,
    /// The probe's truth, the render as given, the plan and their FLIP maps against the truth
    /// (`Arbitration::previews`), for `GET /api/plan/pixels`; a plan against the truth only.
    pub previews: Option<GraphFile>,
    pub error: Option<String>,
    pub(super) cancel: Option<Arc<AtomicBool>>,
}

impl PlanState {
    pub fn json(&self) -> Value {
        json!({ "id": self.id, "running": self.running, "render": self.render,
                "against": self.against, "budget": self.budget, "revision": self.revision,
                "plan": self.doc, "error": self.error,
                "previews": self.previews.as_ref().map(|_| PREVIEWS.iter().map(|(name, ..)| *name).collect::<Vec<_>>()) })
    }
}
