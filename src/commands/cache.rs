//! `mesoflow cache stats` and `mesoflow cache clear`.

use crate::args::CacheArgs;
use mesoflow_runtime::cache::DiskCache;
use std::path::PathBuf;

/// The caches meant: `--cache-dir`/`MESOFLOW_CACHE`, else the one beside the named graph (where
/// `run` puts it), else every `.mesoflow/cache` here and one folder down — so that a plain
/// `mesoflow cache stats` in a checkout finds the cache of `run graphs/x.json`.
fn dirs(a: &CacheArgs) -> Vec<PathBuf> {
    if let Some(d) = &a.cache_dir {
        return vec![d.clone()];
    }
    if let Some(g) = &a.graph {
        return vec![super::run::graph_dir(g).join(".mesoflow").join("cache")];
    }
    let here = PathBuf::from(".mesoflow").join("cache");
    let mut found: Vec<PathBuf> = std::fs::read_dir(".")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join(".mesoflow").join("cache"))
        .filter(|p| p.is_dir())
        .collect();
    found.sort();
    if here.is_dir() || found.is_empty() {
        found.insert(0, here);
    }
    found
}

pub fn stats(a: &CacheArgs) -> anyhow::Result<i32> {
    let mut all = Vec::new();
    for dir in dirs(a) {
        let cache = DiskCache::new(&dir);
        let s = cache.stats();
        if a.json {
            all.push(serde_json::json!({"dir": dir.display().to_string(), "stats": s}));
            continue;
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
        if s.temporary > 0 || s.reclaimed > 0 {
            println!(
                "  ({} temporary files of writes in progress or interrupted; {} orphans older \
                 than an hour reclaimed now)",
                s.temporary, s.reclaimed
            );
        }
    }
    if a.json {
        // One cache: its stats object; several: a list of {dir, stats}.
        let value = match all.as_slice() {
            [one] => one["stats"].clone(),
            _ => serde_json::Value::Array(all),
        };
        println!("{}", serde_json::to_string_pretty(&value)?);
    }
    Ok(0)
}

pub fn clear(a: &CacheArgs) -> anyhow::Result<i32> {
    for dir in dirs(a) {
        let cache = DiskCache::new(&dir);
        let n = cache.clear()?;
        println!("{}: removed {n} entries", cache.dir().display());
    }
    Ok(0)
}
