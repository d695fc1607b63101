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
    GraphFile::parse(&text)
        .map(|f| f.located(path))
        .map_err(|errors| {
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

/// The graph with its subgraphs inlined (`crate::subgraph::expand`): what the planner edits,
/// node by node, under their paths (`tile/capture`); its planned graph is written flat.
pub fn flat(path: &Path, file: &GraphFile) -> anyhow::Result<GraphFile> {
    mesoflow_graph::subgraph::expand(file).map_err(|errors| {
        invalid(
            GraphErrors {
                file: path.display().to_string(),
                errors,
            }
            .to_string()
            .trim_end()
            .to_string(),
        )
    })
}

/// `--output`s and measures as a run reads them: a graph node's exposed output (`p.y`) as the
/// inner output it names (`p/b.y`).
pub fn through_subgraphs(
    path: &Path,
    sets: &[String],
    ports: Vec<mesoflow_graph::PortRef>,
) -> anyhow::Result<Vec<mesoflow_graph::PortRef>> {
    if ports.is_empty() {
        return Ok(ports);
    }
    let mut file = read(path)?;
    apply_sets(&mut file, sets)?;
    Ok(mesoflow_graph::subgraph::through_all(&file, ports))
}

pub fn checked(path: &Path, file: &GraphFile, registry: &Registry) -> anyhow::Result<CheckedGraph> {
    check(&path.display().to_string(), file, registry)
        .map_err(|e| invalid(e.to_string().trim_end().to_string()))
}

pub fn load(path: &Path, sets: &[String], registry: &Registry) -> anyhow::Result<CheckedGraph> {
    let mut file = read(path)?;
    apply_sets(&mut file, sets)?;
    known_params(&file, sets, registry)?;
    checked(path, &file, registry)
}

/// A `--set` of a parameter its node's kind does not have is the `--set`'s mistake, said so
/// against it rather than against the graph file (issue 58).
fn known_params(file: &GraphFile, sets: &[String], registry: &Registry) -> anyhow::Result<()> {
    for s in sets {
        let Ok(o) = parse_override(s) else {
            continue;
        };
        let top = o.param.split('.').next().unwrap_or(&o.param);
        let Some(sig) = file
            .node(&o.node)
            .and_then(|d| registry.node(&d.kind))
            .map(|n| n.signature())
        else {
            continue;
        };
        let names = sig.params.get("properties").and_then(|p| p.as_object());
        if names.is_some_and(|n| !n.contains_key(top)) {
            let hint =
                mesoflow_graph::nearest(top, names.into_iter().flatten().map(|(k, _)| k.as_str()))
                    .map(|n| format!(" (did you mean `{n}`?)"))
                    .unwrap_or_default();
            return Err(invalid(format!(
                "--set {s}: node `{}` ({}) has no parameter `{top}`{hint}",
                o.node, sig.kind
            )));
        }
    }
    Ok(())
}
