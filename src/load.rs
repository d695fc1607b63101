//! Loading a graph file: read, parse, apply `--set`, check. Every problem is an exit-2 error that
//! lists all of them.

use crate::exit::invalid;
use mesoflow_graph::{check, parse_override, CheckedGraph, GraphErrors, GraphFile};
use mesoflow_runtime::Registry;
use std::path::Path;

pub fn read(path: &Path) -> anyhow::Result<GraphFile> {
    let name = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|e| invalid(format!("{name}: cannot read: {e}")))?;
    GraphFile::parse(&text).map_err(|errors| {
        invalid(
            GraphErrors { file: name, errors }
                .to_string()
                .trim_end()
                .to_string(),
        )
    })
}

pub fn apply_sets(file: &mut GraphFile, sets: &[String]) -> anyhow::Result<()> {
    for s in sets {
        let o = parse_override(s).map_err(|e| invalid(format!("--set {e}")))?;
        file.apply(&o).map_err(invalid)?;
    }
    Ok(())
}

pub fn checked(path: &Path, file: &GraphFile, registry: &Registry) -> anyhow::Result<CheckedGraph> {
    check(&path.display().to_string(), file, registry)
        .map_err(|e| invalid(e.to_string().trim_end().to_string()))
}

pub fn load(path: &Path, sets: &[String], registry: &Registry) -> anyhow::Result<CheckedGraph> {
    let mut file = read(path)?;
    apply_sets(&mut file, sets)?;
    checked(path, &file, registry)
}
