//! `validate`, `nodes`, `schema` and `dot`: commands that read graphs and kinds without running.

use crate::exit::invalid;
use crate::load;
use mesoflow_graph::KindSignature;
use mesoflow_runtime::{NodeStatus, RunReport};
use serde_json::{json, Value};
use std::path::Path;

pub fn validate(path: &Path, set: &[String]) -> anyhow::Result<i32> {
    let registry = mesoflow_nodes::registry::builtin();
    let graph = load::load(path, set, &registry)?;
    // Input files as a run would look for them: a missing one is an error here, not at run time.
    let base = crate::session::graph_dir(path);
    let mut missing = Vec::new();
    for cn in &graph.nodes {
        let Some(node) = registry.node(&cn.kind) else {
            continue;
        };
        let Ok(prepared) = node.prepare(&cn.params) else {
            continue;
        };
        for f in node.files(&prepared, &base).unwrap_or_default() {
            if !f.exists() {
                missing.push(format!(
                    "node `{}` ({}): its input file {} does not exist (a relative path resolves against the graph's folder, {})",
                    cn.id,
                    cn.kind,
                    f.display(),
                    base.display()
                ));
            }
        }
    }
    if !missing.is_empty() {
        return Err(invalid(format!(
            "{}: {}",
            path.display(),
            missing.join("\n")
        )));
    }
    println!(
        "{}: ok, {} nodes; default outputs: {}",
        path.display(),
        graph.nodes.len(),
        graph.sinks().join(", ")
    );
    Ok(0)
}

/// The `nodes --json` object of one kind (a stable interface: add fields, never rename).
fn kind_json(s: &KindSignature) -> Value {
    json!({
        "kind": s.kind,
        "version": s.version,
        "device": s.device,
        "doc": s.doc,
        "inputs": s.inputs.iter().map(|i| json!({"name": i.name, "type": i.ty, "required": i.required, "doc": i.doc})).collect::<Vec<_>>(),
        "outputs": s.outputs.iter().map(|o| json!({"name": o.name, "type": o.ty, "doc": o.doc})).collect::<Vec<_>>(),
        "params": s.params,
    })
}

/// The columns text is wrapped to.
const COLUMNS: usize = 100;

/// `text` word-wrapped to [`COLUMNS`], the first line starting at column `first` (what precedes
/// it is the caller's) and every further line indented by `indent` spaces.
fn wrap(text: &str, first: usize, indent: usize) -> String {
    let mut out = String::new();
    let mut col = first;
    // Whether the current line holds a word yet: a word after another is preceded by a space,
    // whichever column the line started at.
    let mut words = false;
    for word in text.split_whitespace() {
        let w = word.chars().count();
        if words && col + 1 + w > COLUMNS {
            out.push('\n');
            out.push_str(&" ".repeat(indent));
            col = indent;
            words = false;
        }
        if words {
            out.push(' ');
            col += 1;
        }
        out.push_str(word);
        col += w;
        words = true;
    }
    out
}

fn describe(s: &KindSignature) -> String {
    let device = format!("{:?}", s.device).to_lowercase();
    let mut out = format!(
        "{} (version {}, {device})\n  {}\n",
        s.kind,
        s.version,
        wrap(&s.doc, 2, 2)
    );
    let props = s.params.get("properties").and_then(Value::as_object);
    // One name column for ports and parameters alike, as wide as the longest name.
    let width = s
        .inputs
        .iter()
        .map(|i| i.name.chars().count())
        .chain(s.outputs.iter().map(|o| o.name.chars().count()))
        .chain(props.into_iter().flatten().map(|(k, _)| k.chars().count()))
        .fold(14, usize::max);
    let row = |name: &str, what: String, doc: &str| {
        let head = format!("  {name:<width$} {what}");
        let col = head.chars().count();
        if doc.is_empty() {
            format!("{head}\n")
        } else if col + 2 + doc.chars().count().min(20) <= COLUMNS {
            format!("{head}  {}\n", wrap(doc, col + 2, width + 3))
        } else {
            format!(
                "{head}\n{}{}\n",
                " ".repeat(width + 3),
                wrap(doc, width + 3, width + 3)
            )
        }
    };
    out.push_str("inputs:\n");
    if s.inputs.is_empty() {
        out.push_str("  (none)\n");
    }
    for i in &s.inputs {
        let opt = if i.required { "" } else { ", optional" };
        out.push_str(&row(&i.name, format!("{}{opt}", i.ty), &i.doc));
    }
    out.push_str("outputs:\n");
    for o in &s.outputs {
        out.push_str(&row(&o.name, o.ty.clone(), &o.doc));
    }
    out.push_str("params:\n");
    let required = s.required_params();
    for (name, schema) in props.into_iter().flatten() {
        let mut ty = mesoflow_graph::params::expected_text(&s.params, schema);
        let bound = |k: &str| schema.get(k).map(|v| v.to_string());
        match (bound("minimum"), bound("maximum")) {
            (Some(lo), Some(hi)) => ty.push_str(&format!(" in [{lo}, {hi}]")),
            (Some(lo), None) => ty.push_str(&format!(" ≥ {lo}")),
            (None, Some(hi)) => ty.push_str(&format!(" ≤ {hi}")),
            (None, None) => {}
        }
        let default = match schema.get("default") {
            Some(d) => format!("default {d}"),
            None if required.contains(&name.as_str()) => "required".into(),
            None => "optional".into(),
        };
        let doc = schema
            .get("description")
            .and_then(Value::as_str)
            .unwrap_or("");
        out.push_str(&format!(
            "  {name:<width$} {}\n",
            wrap(&format!("{ty}; {default}"), width + 3, width + 3)
        ));
        if !doc.is_empty() {
            out.push_str(&format!(
                "{}{}\n",
                " ".repeat(width + 3),
                wrap(doc, width + 3, width + 3)
            ));
        }
    }
    out
}

pub fn nodes(kind: Option<&str>, as_json: bool) -> anyhow::Result<i32> {
    if kind == Some(mesoflow_graph::subgraph::KIND) && !as_json {
        println!(
            "graph — a graph file used as a node (docs/guide/concepts.md, \"Subgraphs\")\n\n\
             parameters\n  path   the graph file, relative to this graph's folder\n  \
             set    {{\"node.param\": value}}: any parameter inside it\n  \
             (name) an exposed parameter: the file's interface.params\n\n\
             inputs and outputs: the file's interface.inputs and interface.outputs; its nodes\n\
             run as if inlined, each under the path `id/node`"
        );
        return Ok(0);
    }
    let registry = mesoflow_nodes::registry::builtin();
    let sigs: Vec<&KindSignature> = registry.signatures().collect();
    // A prefix (`btf`, `render.`) lists its kinds as the whole list does.
    let prefix = kind.map(|k| format!("{}.", k.trim_end_matches('.')));
    let family: Vec<&KindSignature> = match &prefix {
        Some(p) if !sigs.iter().any(|s| Some(s.kind.as_str()) == kind) => sigs
            .iter()
            .copied()
            .filter(|s| s.kind.starts_with(p.as_str()))
            .collect(),
        _ => Vec::new(),
    };
    let listed = kind.is_none() || !family.is_empty();
    let chosen: Vec<&KindSignature> = match kind {
        None => sigs,
        Some(_) if !family.is_empty() => family,
        Some(k) => match sigs.iter().find(|s| s.kind == k) {
            Some(s) => vec![*s],
            None => {
                let hint = mesoflow_graph::nearest(k, sigs.iter().map(|s| s.kind.as_str()))
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                return Err(invalid(format!("unknown node kind `{k}`{hint}")));
            }
        },
    };
    if as_json {
        let arr: Vec<Value> = chosen.iter().map(|s| kind_json(s)).collect();
        println!("{}", serde_json::to_string_pretty(&arr)?);
    } else if !listed {
        print!("{}", describe(chosen[0]));
    } else {
        let width = chosen
            .iter()
            .map(|s| s.kind.chars().count())
            .fold(0, usize::max);
        for s in chosen {
            let head = format!(
                "{:<width$} v{:<3} {:<4}",
                s.kind,
                s.version,
                format!("{:?}", s.device).to_lowercase(),
            );
            let col = head.chars().count() + 1;
            println!("{head} {}", wrap(&s.doc, col, col));
        }
    }
    Ok(0)
}

pub fn schema() -> anyhow::Result<i32> {
    let registry = mesoflow_nodes::registry::builtin();
    println!(
        "{}",
        serde_json::to_string_pretty(&mesoflow_graph::schema::graph_schema(&registry))?
    );
    Ok(0)
}

fn colour(s: NodeStatus) -> &'static str {
    match s {
        NodeStatus::Computed => "palegreen",
        NodeStatus::Memory | NodeStatus::Disk => "lightblue",
        NodeStatus::Failed => "salmon",
        NodeStatus::Cancelled => "orange",
    }
}

pub fn dot(graph: &Path, report: Option<&Path>) -> anyhow::Result<i32> {
    let registry = mesoflow_nodes::registry::builtin();
    let graph = load::load(graph, &[], &registry)?;
    let report: Option<RunReport> = match report {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).map_err(|e| invalid(format!("{}: {e}", p.display())))?;
            Some(
                serde_json::from_str(&text)
                    .map_err(|e| invalid(format!("{}: not a run report: {e}", p.display())))?,
            )
        }
        None => None,
    };
    let mut out = String::from("digraph mesoflow {\n  rankdir=LR;\n  node [shape=box, style=\"rounded,filled\", fillcolor=white, fontname=\"Helvetica\"];\n");
    let mut by_parent: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    for n in &graph.nodes {
        let (fill, extra) = match report.as_ref() {
            Some(r) => match r.node(&n.id) {
                Some(nr) => (
                    colour(nr.status),
                    format!("\\n{:?} {:.3}s", nr.status, nr.seconds).to_lowercase(),
                ),
                None if r.skipped.contains(&n.id) => ("grey90", "\\nnot needed".into()),
                None => ("white", String::new()),
            },
            None => ("white", String::new()),
        };
        let (parent, name) = n.id.rsplit_once('/').unwrap_or(("", &n.id));
        by_parent
            .entry(parent.to_string())
            .or_default()
            .push(format!(
                "\"{}\" [label=\"{}\\n{}{}\", fillcolor={}];",
                n.id, name, n.kind, extra, fill
            ));
    }
    // A subgraph's nodes (`p/inner`) drawn inside a box labelled with its id, nested as deep
    // as the graph files nest.
    emit_cluster("", &by_parent, 1, &mut out);
    for n in &graph.nodes {
        for e in &n.inputs {
            out.push_str(&format!(
                "  \"{}\" -> \"{}\" [label=\"{}→{}\"];\n",
                e.from.node, n.id, e.from.port, e.port
            ));
        }
    }
    out.push_str("}\n");
    print!("{out}");
    Ok(0)
}

/// The nodes whose path's folder is `prefix`, then each subgraph below it as a cluster.
fn emit_cluster(
    prefix: &str,
    by_parent: &std::collections::BTreeMap<String, Vec<String>>,
    depth: usize,
    out: &mut String,
) {
    let pad = "  ".repeat(depth);
    for line in by_parent.get(prefix).into_iter().flatten() {
        out.push_str(&format!("{pad}{line}\n"));
    }
    let children: std::collections::BTreeSet<String> = by_parent
        .keys()
        .filter_map(|k| {
            let rest = if prefix.is_empty() {
                Some(k.as_str()).filter(|k| !k.is_empty())
            } else {
                k.strip_prefix(prefix).and_then(|r| r.strip_prefix('/'))
            }?;
            let first = rest.split('/').next()?;
            Some(if prefix.is_empty() {
                first.to_string()
            } else {
                format!("{prefix}/{first}")
            })
        })
        .collect();
    for child in children {
        let label = child.rsplit('/').next().unwrap_or(&child);
        out.push_str(&format!(
            "{pad}subgraph \"cluster_{child}\" {{\n{pad}  label=\"{label} (graph)\";\n{pad}  style=rounded;\n"
        ));
        emit_cluster(&child, by_parent, depth + 1, out);
        out.push_str(&format!("{pad}}}\n"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrapping_keeps_every_space_between_words() {
        // A line that starts left of where the first one did (a parameter's doc continued
        // under its name) still separates its words.
        let text = "one two three four five six seven eight nine ten eleven twelve thirteen \
                    fourteen fifteen sixteen seventeen eighteen nineteen twenty surface reflectance";
        for (first, indent) in [(2, 2), (40, 8), (60, 30)] {
            let wrapped = wrap(text, first, indent);
            assert_eq!(
                wrapped.split_whitespace().collect::<Vec<_>>(),
                text.split_whitespace().collect::<Vec<_>>(),
                "{wrapped}"
            );
            for (k, line) in wrapped.lines().enumerate() {
                let start = if k == 0 { first } else { 0 };
                assert!(start + line.chars().count() <= COLUMNS, "{line}");
            }
        }
    }
}
