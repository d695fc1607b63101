//! `mesoflow cache stats`, `mesoflow cache clear` and `mesoflow cache gc`.

use crate::args::{CacheArgs, GcArgs};
use crate::exit::invalid;
use crate::progress::human_bytes;
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
        return vec![crate::session::graph_dir(g).join(".mesoflow").join("cache")];
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
        // Sizes in readable units (`--json` gives the bytes).
        println!(
            "{}: {} entries, {}",
            cache.dir().display(),
            s.entries,
            human_bytes(s.bytes)
        );
        for (kind, k) in &s.by_kind {
            println!(
                "  {kind:<28} {:>6} entries {:>11}",
                k.entries,
                human_bytes(k.bytes)
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

pub fn clear(c: &crate::args::ClearArgs) -> anyhow::Result<i32> {
    let a = &c.cache;
    let named = a.graph.is_some() || a.cache_dir.is_some();
    if !named && !c.all {
        let found: Vec<String> = dirs(a)
            .iter()
            .filter(|d| d.is_dir())
            .map(|d| {
                let s = DiskCache::new(d).stats();
                format!("  {} ({} entries)", d.display(), s.entries)
            })
            .collect();
        return Err(invalid(if found.is_empty() {
            "cache clear: no cache here; name a graph (the cache beside it) or --cache-dir".into()
        } else {
            format!(
                "cache clear: name a graph (the cache beside it) or --cache-dir, or add --all to clear every cache found here:\n{}",
                found.join("\n")
            )
        }));
    }
    for dir in dirs(a) {
        let cache = DiskCache::new(&dir);
        let n = cache.clear()?;
        println!("{}: removed {n} entries", cache.dir().display());
    }
    Ok(0)
}

/// `30d`, `12h`, `45m`, `90s` (or plain seconds).
fn parse_age(text: &str) -> anyhow::Result<std::time::Duration> {
    let t = text.trim();
    let (digits, unit) = match t.chars().last() {
        Some('d') => (&t[..t.len() - 1], 86_400.0),
        Some('h') => (&t[..t.len() - 1], 3_600.0),
        Some('m') => (&t[..t.len() - 1], 60.0),
        Some('s') => (&t[..t.len() - 1], 1.0),
        _ => (t, 1.0),
    };
    match digits.trim().parse::<f64>() {
        Ok(n) if n.is_finite() && n >= 0.0 && n * unit < 1e12 => {
            Ok(std::time::Duration::from_secs_f64(n * unit))
        }
        _ => Err(invalid(format!(
            "--older-than {text}: expected an age such as 30d, 12h, 45m or 90s"
        ))),
    }
}

pub fn gc(a: &GcArgs) -> anyhow::Result<i32> {
    let max_bytes = match &a.max_bytes {
        Some(s) => Some(crate::session::parse_size(s).map_err(|_| {
            invalid(format!(
                "--max-bytes {s}: expected bytes or a size like 512M, 20G"
            ))
        })? as u64),
        None => None,
    };
    let older_than = a.older_than.as_deref().map(parse_age).transpose()?;
    if max_bytes.is_none() && older_than.is_none() {
        return Err(invalid(
            "cache gc: say what to keep with --max-bytes and/or --older-than",
        ));
    }
    let mut all = Vec::new();
    for dir in dirs(&a.cache) {
        let cache = DiskCache::new(&dir);
        let s = cache.gc(max_bytes, older_than);
        if a.cache.json {
            all.push(serde_json::json!({"dir": dir.display().to_string(), "gc": s}));
        } else {
            println!(
                "{}: removed {} entries ({}); kept {} ({}){}",
                cache.dir().display(),
                s.removed,
                human_bytes(s.freed_bytes),
                s.kept,
                human_bytes(s.kept_bytes),
                if s.reclaimed > 0 {
                    format!("; {} orphaned temporary files", s.reclaimed)
                } else {
                    String::new()
                }
            );
        }
    }
    if a.cache.json {
        println!("{}", serde_json::to_string_pretty(&all)?);
    }
    Ok(0)
}
