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
        // A sub-folder planted as a link (`out/sub → a folder outside`) would carry the write out
        // of the output folder: refused (issue 43). The file itself, a link or not, is replaced
        // by the rename, never written through.
        let mut at = out_dir.to_path_buf();
        for part in Path::new(&a.path)
            .parent()
            .into_iter()
            .flat_map(Path::components)
        {
            at.push(part);
            if std::fs::symlink_metadata(&at).is_ok_and(|m| m.file_type().is_symlink()) {
                return Err(format!(
                    "cannot write {}: {} is a link, and the output folder's sub-folders must be its own",
                    a.path,
                    at.display()
                ));
            }
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
    #[cfg(unix)]
    fn a_planted_link_is_never_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir_all(&out).unwrap();
        // A sub-folder that is a link out: refused, nothing written outside.
        std::os::unix::fs::symlink(outside.path(), out.join("sub")).unwrap();
        let err = write_artifacts(&one("sub/h.npy"), &out).unwrap_err();
        assert!(err.contains("is a link"), "{err}");
        assert!(!outside.path().join("h.npy").exists());
        // A file that is a link out: replaced by the file, the target untouched.
        let target = outside.path().join("precious.txt");
        std::fs::write(&target, "keep").unwrap();
        std::os::unix::fs::symlink(&target, out.join("r.txt")).unwrap();
        write_artifacts(&one("r.txt"), &out).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
        assert!(!std::fs::symlink_metadata(out.join("r.txt"))
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(out.join("r.txt")).unwrap(), b"abc");
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
