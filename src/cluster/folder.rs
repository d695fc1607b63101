//! The run folder a cluster run shares between its driver and its jobs (on the shared
//! filesystem, beside the cache):
//!
//! ```text
//! RUN/run.json        what to run: build id, executable, cache, graph variants, units
//! RUN/units/U.json    a job's result for unit U (status, host, attempt, seconds), written by
//!                     `mesoflow exec` atomically
//! RUN/units/U.job     the driver's last submission of U (job id, attempt)
//! RUN/logs/           the jobs' output
//! RUN/cancel          present once `mesoflow cancel RUN` was asked
//! ```

use super::units::UnitSpec;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RunSpec {
    /// `mesoflow_runtime::producer::build_id()` of the driver; a job of another build refuses.
    pub build: String,
    /// The executable the jobs run (the driver's own).
    pub exe: PathBuf,
    pub cache_dir: PathBuf,
    pub base_dir: PathBuf,
    pub graph_name: String,
    pub device: String,
    /// The graph files of every variant (after `--set` and `--vary`), as JSON text.
    pub variants: Vec<String>,
    pub units: BTreeMap<String, UnitSpec>,
}

/// What a job reports for its unit.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct UnitStatus {
    /// `done`, `failed` (a node error: not retried), `missing` (an input not yet in the cache).
    pub status: String,
    pub host: String,
    pub attempt: u32,
    pub seconds: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The driver's record of a submission.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Submission {
    pub job: String,
    pub attempt: u32,
}

pub struct Folder {
    pub dir: PathBuf,
}

pub use mesoflow_runtime::write_atomic;

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Option<T> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

impl Folder {
    pub fn new(dir: impl Into<PathBuf>) -> Folder {
        Folder { dir: dir.into() }
    }
    pub fn spec_path(&self) -> PathBuf {
        self.dir.join("run.json")
    }
    pub fn spec(&self) -> anyhow::Result<RunSpec> {
        let path = self.spec_path();
        let text = std::fs::read_to_string(&path).map_err(|e| {
            crate::exit::invalid(format!(
                "{}: not a cluster run folder: {e}",
                self.dir.display()
            ))
        })?;
        serde_json::from_str(&text)
            .map_err(|e| crate::exit::invalid(format!("{}: unreadable: {e}", path.display())))
    }
    pub fn write_spec(&self, spec: &RunSpec) -> anyhow::Result<()> {
        write_atomic(&self.spec_path(), &serde_json::to_string_pretty(spec)?)?;
        Ok(())
    }
    pub fn status_path(&self, unit: &str) -> PathBuf {
        self.dir.join("units").join(format!("{unit}.json"))
    }
    pub fn status(&self, unit: &str) -> Option<UnitStatus> {
        read_json(&self.status_path(unit))
    }
    pub fn write_status(&self, unit: &str, s: &UnitStatus) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(s).map_err(std::io::Error::other)?;
        write_atomic(&self.status_path(unit), &text)
    }
    pub fn submission(&self, unit: &str) -> Option<Submission> {
        read_json(&self.dir.join("units").join(format!("{unit}.job")))
    }
    pub fn write_submission(&self, unit: &str, s: &Submission) -> std::io::Result<()> {
        let text = serde_json::to_string(s).map_err(std::io::Error::other)?;
        write_atomic(&self.dir.join("units").join(format!("{unit}.job")), &text)
    }
    pub fn logs(&self) -> PathBuf {
        self.dir.join("logs")
    }
    pub fn cancel_path(&self) -> PathBuf {
        self.dir.join("cancel")
    }
}
