//! Running graphs and sweeps on a Slurm cluster (`--engine slurm`): the run is split into units
//! (`units`), described in a run folder on the shared filesystem (`folder`), submitted and
//! followed by the driver (`driver`, through `slurm`), and executed by `mesoflow exec` in each
//! job (`exec`). `mesoflow status` and `mesoflow cancel` read and act on the run folder.

pub mod driver;
pub mod exec;
pub mod folder;
pub mod slurm;
pub mod units;

use folder::Folder;
use std::path::Path;

/// `mesoflow status RUN`: one line per unit.
pub fn status(run_dir: &Path) -> anyhow::Result<i32> {
    let folder = Folder::new(run_dir);
    let spec = folder.spec()?;
    let queue = slurm::queue().unwrap_or_default();
    let cache = mesoflow_runtime::cache::DiskCache::new(&spec.cache_dir);
    let mut counts = std::collections::BTreeMap::<String, usize>::new();
    println!(
        "{:<17} {:<10} {:>7} {:>9} {:<16} nodes",
        "unit", "state", "attempt", "seconds", "host"
    );
    for (id, u) in &spec.units {
        let sub = folder.submission(id);
        let st = folder.status(id);
        let cached = u
            .keys
            .iter()
            .all(|k| mesoflow_runtime::Key::from_hex(k).is_some_and(|key| cache.contains(&key)));
        let state = match (&sub, &st) {
            (Some(s), _) if queue.contains_key(&s.job) => queue[&s.job].to_lowercase(),
            _ if cached => "done".to_string(),
            (_, Some(s)) => s.status.clone(),
            (None, None) => "waiting".into(),
            (Some(_), None) => "lost".into(),
        };
        *counts.entry(state.clone()).or_default() += 1;
        println!(
            "{:<17} {:<10} {:>7} {:>9} {:<16} {}",
            id,
            state,
            sub.as_ref().map_or(0, |s| s.attempt),
            st.as_ref()
                .map(|s| format!("{:.2}", s.seconds))
                .unwrap_or_default(),
            st.as_ref().map(|s| s.host.as_str()).unwrap_or(""),
            u.nodes.join(", ")
        );
    }
    let summary: Vec<String> = counts.iter().map(|(k, v)| format!("{v} {k}")).collect();
    println!(
        "{}: {} units: {}",
        run_dir.display(),
        spec.units.len(),
        summary.join(", ")
    );
    if folder.cancel_path().exists() {
        println!("cancel requested");
    }
    Ok(0)
}

/// `mesoflow cancel RUN`: cancels the run's jobs and tells its driver to stop.
pub fn cancel(run_dir: &Path) -> anyhow::Result<i32> {
    let folder = Folder::new(run_dir);
    let spec = folder.spec()?;
    folder::write_atomic(&folder.cancel_path(), "cancel\n")?;
    let queue = slurm::queue()?;
    let jobs: Vec<String> = spec
        .units
        .keys()
        .filter_map(|id| folder.submission(id))
        .map(|s| s.job)
        .filter(|j| queue.contains_key(j))
        .collect();
    slurm::scancel(&jobs)?;
    println!("{}: cancelled {} jobs", run_dir.display(), jobs.len());
    Ok(0)
}
