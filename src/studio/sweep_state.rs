//! The studio's sweep as the page sees it: its id, whether it runs, its table's columns and rows,
//! its charts and error, and the flag that stops it. `Studio` holds one; `sweep.rs` runs it.

use serde_json::{json, Value};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// The studio's sweep: what the page shows of the last one asked for.
#[derive(Default)]
pub struct SweepState {
    pub id: u64,
    pub running: bool,
    pub total: usize,
    pub columns: Vec<String>,
    pub rows: Vec<Value>,
    pub charts: Vec<String>,
    pub error: Option<String>,
    /// The running sweep's stop flag.
    pub(super) cancel: Option<Arc<AtomicBool>>,
}

impl SweepState {
    pub fn json(&self) -> Value {
        json!({ "id": self.id, "running": self.running, "total": self.total,
                "columns": self.columns, "rows": self.rows, "charts": self.charts,
                "error": self.error })
    }
}
