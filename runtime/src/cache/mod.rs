//! The two caches: [`MemoryCache`] for a process's runs (sweeps, watch), [`DiskCache`] across
//! processes and machines.

mod disk;
mod memory;

pub use disk::{CacheStats, DiskCache, DiskError, KindStats};
pub use memory::MemoryCache;

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
