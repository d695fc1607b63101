//! `mesoflow cache stats` and `mesoflow cache clear`.

use crate::args::CacheArgs;
use mesoflow_runtime::cache::DiskCache;
use std::path::PathBuf;

fn dir(a: &CacheArgs) -> PathBuf {
    a.cache_dir.clone().unwrap_or_else(|| match &a.graph {
        Some(g) => super::run::graph_dir(g).join(".mesoflow").join("cache"),
        None => PathBuf::from(".mesoflow").join("cache"),
    })
}

pub fn stats(a: &CacheArgs) -> anyhow::Result<i32> {
    let cache = DiskCache::new(dir(a));
    let s = cache.stats();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(0);
    }
    println!(
        "{}: {} entries, {} bytes",
        cache.dir().display(),
        s.entries,
        s.bytes
    );
    for (kind, k) in &s.by_kind {
        println!(
            "  {kind:<28} {:>6} entries {:>14} bytes",
            k.entries, k.bytes
        );
    }
    if s.unreadable > 0 {
        println!(
            "  ({} unreadable entries; they are recomputed when met)",
            s.unreadable
        );
    }
    Ok(0)
}

pub fn clear(a: &CacheArgs) -> anyhow::Result<i32> {
    let cache = DiskCache::new(dir(a));
    let n = cache.clear()?;
    println!("{}: removed {n} entries", cache.dir().display());
    Ok(0)
}
