//! `mesoflow exec RUN --unit U`, the body of every job. It checks that it is the driver's build,
//! reads its inputs only from the shared cache (one missing: exit 75, "try again"; never
//! computed here), re-derives its nodes' keys (the files they declare are hashed again; a key
//! that differs from the driver's is an error), runs its nodes with the normal engine, which
//! writes their cache entries, then writes `RUN/units/U.json` atomically.

use super::folder::{Folder, UnitStatus};
use crate::exit;
use mesoflow_graph::{check, GraphFile, PortRef};
use mesoflow_runtime::cache::{default_memory_budget, DiskCache};
use mesoflow_runtime::{
    DeviceMode, Engine, EngineConfig, NodeStatus, RunOptions, RunPolicy, SilentObserver,
    NOT_IN_CACHE,
};
use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// Exit code of a unit whose input is not in the cache yet (sysexits' EX_TEMPFAIL).
pub const TRY_AGAIN: i32 = 75;

pub fn exec(run_dir: &Path, unit: &str) -> anyhow::Result<i32> {
    let t0 = Instant::now();
    let folder = Folder::new(run_dir);
    let spec = folder.spec()?;
    let build = mesoflow_runtime::producer::build_id();
    if spec.build != build {
        return Err(exit::invalid(format!(
            "{}: the run was made by mesoflow build {}, this is build {build}; run the driver's \
             executable ({}) on the workers",
            run_dir.display(),
            spec.build,
            spec.exe.display()
        )));
    }
    let Some(u) = spec.units.get(unit) else {
        return Err(exit::invalid(format!(
            "{}: no unit `{unit}` in this run",
            run_dir.display()
        )));
    };
    let attempt: u32 = std::env::var("MESOFLOW_ATTEMPT")
        .ok()
        .and_then(|a| a.parse().ok())
        .unwrap_or(1);
    let job = std::env::var("SLURM_JOB_ID").ok();
    let report = |status: &str, error: Option<String>| -> anyhow::Result<()> {
        folder.write_status(
            unit,
            &UnitStatus {
                status: status.into(),
                host: mesoflow_runtime::producer::host().into(),
                attempt,
                seconds: t0.elapsed().as_secs_f64(),
                job: job.clone(),
                error,
            },
        )?;
        Ok(())
    };
    let cache = DiskCache::new(&spec.cache_dir);
    let mut missing = u
        .inputs
        .iter()
        .filter(|k| mesoflow_runtime::Key::from_hex(k).is_none_or(|key| !cache.contains(&key)));
    if let Some(k) = missing.next() {
        report(
            "missing",
            Some(format!("input {k} is not in the cache yet")),
        )?;
        return Ok(TRY_AGAIN);
    }
    let Some(text) = spec.variants.get(u.variant) else {
        return Err(exit::invalid(format!(
            "unit {unit}: no variant {}",
            u.variant
        )));
    };
    let file = GraphFile::parse(text)
        .map(|f| f.in_folder(&spec.base_dir))
        .map_err(|e| {
            exit::invalid(format!(
                "unit {unit}: {}",
                e.iter()
                    .map(|e| e.to_string())
                    .collect::<Vec<_>>()
                    .join("; ")
            ))
        })?;
    let engine = Engine::new(
        mesoflow_nodes::registry::builtin(),
        EngineConfig {
            memory_budget: default_memory_budget(),
            disk: Some(cache),
        },
    );
    let graph = check(&spec.graph_name, &file, engine.registry())
        .map_err(|e| exit::invalid(e.to_string()))?;
    let mut opts = RunOptions::new(
        &spec.graph_name,
        spec.base_dir.clone(),
        run_dir.join("scratch").join(unit),
        RunPolicy {
            device: match spec.device.as_str() {
                "cpu" => DeviceMode::Cpu,
                "gpu" => DeviceMode::Gpu,
                _ => DeviceMode::Auto,
            },
            cancel: crate::interrupt::cancel_flag(),
            ..RunPolicy::default()
        },
    );
    opts.outputs = u
        .nodes
        .iter()
        .filter_map(|id| {
            let kind = &graph.nodes[graph.index(id)?].kind;
            let port = engine
                .registry()
                .node(kind)?
                .signature()
                .outputs
                .first()?
                .name
                .clone();
            Some(PortRef {
                node: id.clone(),
                port,
            })
        })
        .collect();
    // The files the unit's nodes declare are hashed again here: a key that is not the one the
    // driver computed means the inputs changed under the run.
    let keys = engine.keys(&graph, &opts);
    for (id, want) in u.nodes.iter().zip(&u.keys) {
        let got = keys.get(id).and_then(|k| k.as_ref().ok()).map(|k| k.hex());
        if got.as_deref() != Some(want.as_str()) {
            let message = format!(
                "node `{id}`: its key here ({}) is not the driver's ({want}): a file it reads \
                 changed, or this host resolves it differently",
                got.unwrap_or_else(|| "none".into())
            );
            report("failed", Some(message.clone()))?;
            eprintln!("error: {message}");
            return Ok(exit::FAILED);
        }
    }
    opts.compute_only = Some(u.nodes.iter().cloned().collect::<BTreeSet<_>>());
    opts.cache_everything = true;
    let result = engine
        .run(&graph, &opts, Arc::new(SilentObserver))
        .map_err(|e| exit::invalid(e.to_string()))?;
    if result.cancelled {
        return Ok(exit::CANCELLED);
    }
    let failed: Vec<&mesoflow_runtime::NodeReport> = result
        .nodes
        .iter()
        .filter(|n| n.status == NodeStatus::Failed)
        .collect();
    if failed.is_empty() {
        report("done", None)?;
        return Ok(exit::OK);
    }
    if failed
        .iter()
        .any(|n| n.error.as_deref().is_some_and(|e| e.contains(NOT_IN_CACHE)))
    {
        report("missing", failed[0].error.clone())?;
        return Ok(TRY_AGAIN);
    }
    let error = failed
        .iter()
        .filter_map(|n| n.error.clone())
        .collect::<Vec<_>>()
        .join("; ");
    eprintln!("error: {error}");
    report("failed", Some(error))?;
    Ok(exit::FAILED)
}
