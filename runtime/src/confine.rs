//! Runs confined to folders: a front end that serves what a run computes (the studio) names the
//! folders a run may read, and every input file is checked against them *when it is used* — when
//! its content is hashed for the node's key and again when the node resolves its path to open
//! it — with its links followed. A file accepted by an edit and then replaced by a link to a file
//! outside is refused by the next run, not read and served (issue 43).

use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Folders a run's input files must lie in once their links are followed (canonical paths).
#[derive(Clone, Debug)]
pub struct Confinement(Arc<Vec<PathBuf>>);

impl Confinement {
    /// The folders, each made canonical (a folder that does not exist is left out: nothing lies
    /// in it).
    pub fn new(folders: &[PathBuf]) -> Confinement {
        Confinement(Arc::new(
            folders
                .iter()
                .filter_map(|f| f.canonicalize().ok())
                .collect(),
        ))
    }

    /// `path` as it is to be opened: its canonical form when it exists and lies inside, why not
    /// when it resolves outside. A path that does not exist is handed back as it is, for the
    /// reader's own "no such file".
    pub fn admit(&self, path: &Path) -> Result<PathBuf, String> {
        match path.canonicalize() {
            Ok(real) if self.0.iter().any(|r| real.starts_with(r)) => Ok(real),
            Ok(real) => Err(format!(
                "resolves to {} outside the folders this run may read ({})",
                real.display(),
                self.0
                    .iter()
                    .map(|r| r.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
            Err(_) => Ok(path.to_path_buf()),
        }
    }
}

/// `path` admitted by `confine` when there is one, unchanged when the run is not confined.
pub fn admit(confine: Option<&Confinement>, path: &Path) -> Result<PathBuf, String> {
    match confine {
        Some(c) => c.admit(path),
        None => Ok(path.to_path_buf()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(unix)]
    fn a_file_replaced_by_a_link_to_outside_is_refused_and_one_inside_admitted() {
        let dir = tempfile::tempdir().expect("temp dir");
        let inside = dir.path().join("graph");
        std::fs::create_dir_all(&inside).expect("mkdir");
        std::fs::write(dir.path().join("secret.npy"), b"x").expect("write");
        std::fs::write(inside.join("h.npy"), b"x").expect("write");
        let c = Confinement::new(std::slice::from_ref(&inside));
        assert!(c.admit(&inside.join("h.npy")).is_ok());
        assert!(c.admit(&inside.join("missing.npy")).is_ok());
        std::fs::remove_file(inside.join("h.npy")).expect("rm");
        std::os::unix::fs::symlink(dir.path().join("secret.npy"), inside.join("h.npy"))
            .expect("link");
        let e = c.admit(&inside.join("h.npy")).expect_err("outside");
        assert!(e.contains("outside the folders"), "{e}");
        assert!(admit(None, &inside.join("h.npy")).is_ok());
    }
}
