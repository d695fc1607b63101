//! Writing a node's `File`/`Files` outputs under the output folder, for computed values and cache
//! hits alike. A write is atomic (a temporary file beside the target, then a rename) and a failed
//! write fails the node: a run that could not write what was asked for is not a success.

use crate::node::Outputs;
use crate::value::{Artifact, Artifacts};
use std::path::Path;

/// Writes every file of `outputs`; returns the paths written, or the first failure.
pub(crate) fn write_artifacts(outputs: &Outputs, out_dir: &Path) -> Result<Vec<String>, String> {
    let all = outputs.values.values().flat_map(|v| {
        let one = v.as_any().downcast_ref::<Artifact>().into_iter();
        let many = v
            .as_any()
            .downcast_ref::<Artifacts>()
            .into_iter()
            .flat_map(|s| s.files.iter());
        one.chain(many)
    });
    let mut written = Vec::new();
    for a in all {
        // Validation refuses such paths already; a node that builds one itself is refused here.
        if let Some(problem) = mesoflow_graph::params::output_path_problem(&a.path) {
            return Err(format!("cannot write: {problem}"));
        }
        let path = out_dir.join(&a.path);
        // Re-running into the same folder is the common case while tuning; a file that already
        // holds these bytes is left alone (a read is cheaper than a write and a rename).
        let unchanged = std::fs::metadata(&path)
            .is_ok_and(|m| m.is_file() && m.len() == a.bytes.len() as u64)
            && std::fs::read(&path).is_ok_and(|b| b == a.bytes);
        if !unchanged {
            crate::atomic_file::write_atomic(&path, &a.bytes)
                .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        }
        written.push(path.display().to_string());
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(path: &str) -> Outputs {
        Outputs::new().with(
            "file",
            Artifact {
                path: path.into(),
                bytes: b"abc".to_vec(),
            },
        )
    }

    #[test]
    fn writes_inside_the_folder_and_refuses_to_leave_it() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_artifacts(&one("a/b.txt"), dir.path()).unwrap();
        assert_eq!(written.len(), 1);
        assert_eq!(std::fs::read(dir.path().join("a/b.txt")).unwrap(), b"abc");
        for bad in ["../x.txt", "/tmp/x.txt", "a/../../x.txt"] {
            let err = write_artifacts(&one(bad), dir.path()).unwrap_err();
            assert!(err.contains("output folder"), "{bad}: {err}");
        }
    }

    #[test]
    fn a_failed_write_is_an_error_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        // A folder where the file should go: the rename fails.
        std::fs::create_dir_all(dir.path().join("x.png/inner")).unwrap();
        let err = write_artifacts(&one("x.png"), dir.path()).unwrap_err();
        assert!(err.contains("cannot write"), "{err}");
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(left, ["x.png"], "no temporary file left beside it");
    }
}
