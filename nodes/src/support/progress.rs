//! Progress and cancellation for long loops that run on rayon: a shared counter of finished work
//! units that reports to the node's context, and the context's cancellation flag.

use mesoflow_runtime::NodeContext;
use std::sync::atomic::{AtomicU64, Ordering};

pub struct Counter<'a> {
    ctx: Option<&'a NodeContext>,
    done: AtomicU64,
    total: AtomicU64,
}

impl<'a> Counter<'a> {
    pub fn new(ctx: &'a NodeContext, total: u64) -> Counter<'a> {
        Counter {
            ctx: Some(ctx),
            done: AtomicU64::new(0),
            total: AtomicU64::new(total),
        }
    }

    /// A counter that reports nowhere and never stops (tests, benchmarks, nested calls).
    pub fn none() -> Counter<'static> {
        Counter {
            ctx: None,
            done: AtomicU64::new(0),
            total: AtomicU64::new(0),
        }
    }

    /// Adds work found after the start (a caller that learns the total as it goes).
    pub fn grow(&self, more: u64) {
        self.total.fetch_add(more, Ordering::Relaxed);
    }

    /// Marks `n` units done and reports.
    pub fn add(&self, n: u64) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if let Some(ctx) = self.ctx {
            ctx.progress(done, self.total.load(Ordering::Relaxed));
        }
    }

    /// The run was cancelled: loops stop at their next unit, and the node returns `Cancelled`.
    pub fn stopped(&self) -> bool {
        self.ctx.is_some_and(|c| c.is_cancelled())
    }
}
