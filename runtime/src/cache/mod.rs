//! The two caches: [`MemoryCache`] for a process's runs (sweeps, watch), [`DiskCache`] across
//! processes and machines.

mod disk;
mod memory;

pub use disk::{CacheStats, DiskCache, DiskError, KindStats, ORPHAN_AGE};
pub use memory::MemoryCache;

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What the computation that produced a cached value measured and said: its wall time, the
/// node's own timings (`NodeContext::timing`) and the warnings it gave (`NodeContext::warn`).
/// Metadata about the value, never part of it: `--verify-cache` compares values only. A hit
/// reports the timings as the cost of the value it served and repeats the warnings, which belong
/// to the value (a thin object's is as true of a cached render as of a fresh one).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub seconds: f64,
    #[serde(default)]
    pub timings: BTreeMap<String, f64>,
    /// Absent from entries written before warnings were recorded: those hits repeat none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// Default memory budget: a quarter of physical memory (2 GiB when it cannot be read).
pub fn default_memory_budget() -> usize {
    let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<usize>().ok())
            .map(|kb| kb * 1024)
    });
    total.map(|t| t / 4).unwrap_or(2 << 30)
}
