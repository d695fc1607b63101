//! The node reference (`mesoflow docs --out DIR`): one Markdown page per kind, with its ports,
//! parameters (nested groups such as `camera` row by row), defaults, bounds and documentation,
//! and an index, all generated from the catalog. `docs/reference` in the repository is this
//! output; a test regenerates it and fails when the committed pages are stale.

use mesoflow_graph::params::{expected_text, resolve};
use mesoflow_graph::KindSignature;
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// A table cell: one line, pipes escaped.
fn cell(text: &str) -> String {
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}

fn bounds(schema: &Value) -> String {
    let b = |k: &str| schema.get(k).map(Value::to_string);
    match (b("minimum"), b("maximum")) {
        (Some(lo), Some(hi)) => format!(" in [{lo}, {hi}]"),
        (Some(lo), None) => format!(" ≥ {lo}"),
        (None, Some(hi)) => format!(" ≤ {hi}"),
        (None, None) => String::new(),
    }
}

/// The rows of a parameter object: `prefix` + name, type, default, description; an object
/// parameter with properties of its own adds a row for each of them under `name.`.
fn param_rows(
    root: &Value,
    object: &Value,
    defaults: Option<&Value>,
    required: &[&str],
    prefix: &str,
    rows: &mut Vec<[String; 4]>,
) {
    let Some(props) = resolve(root, object)
        .get("properties")
        .and_then(Value::as_object)
    else {
        return;
    };
    for (name, schema) in props {
        let own = resolve(root, schema);
        let default = schema
            .get("default")
            .or_else(|| defaults.and_then(|d| d.get(name)));
        let default_text = match default {
            Some(d) => format!("`{d}`"),
            None if required.contains(&name.as_str()) => "required".into(),
            None => "optional".into(),
        };
        let doc = schema
            .get("description")
            .or_else(|| own.get("description"))
            .and_then(Value::as_str)
            .unwrap_or("");
        let full = format!("{prefix}{name}");
        rows.push([
            format!("`{full}`"),
            cell(&format!("{}{}", expected_text(root, schema), bounds(own))),
            cell(&default_text),
            cell(doc),
        ]);
        if own.get("properties").is_some() && prefix.matches('.').count() < 3 {
            param_rows(root, own, default, &[], &format!("{full}."), rows);
        }
    }
}

/// One kind's page.
pub fn page(s: &KindSignature) -> String {
    let mut out = String::new();
    let device = format!("{:?}", s.device).to_lowercase();
    let _ = writeln!(out, "# `{}`\n", s.kind);
    let _ = writeln!(
        out,
        "Version {} · runs on the {device}{}\n",
        s.version,
        if device == "gpu" {
            " (with a CPU path)"
        } else {
            ""
        }
    );
    let _ = writeln!(out, "{}\n", s.doc.trim());
    let _ = writeln!(out, "## Inputs\n");
    if s.inputs.is_empty() {
        let _ = writeln!(out, "None.\n");
    } else {
        let _ = writeln!(out, "| port | type | | description |\n|---|---|---|---|");
        for i in &s.inputs {
            let req = if i.required { "required" } else { "optional" };
            let _ = writeln!(
                out,
                "| `{}` | `{}` | {req} | {} |",
                i.name,
                i.ty,
                cell(&i.doc)
            );
        }
        out.push('\n');
    }
    let _ = writeln!(out, "## Outputs\n");
    let _ = writeln!(out, "| port | type | description |\n|---|---|---|");
    for o in &s.outputs {
        let _ = writeln!(out, "| `{}` | `{}` | {} |", o.name, o.ty, cell(&o.doc));
    }
    out.push('\n');
    let mut rows = Vec::new();
    param_rows(
        &s.params,
        &s.params,
        None,
        &s.required_params(),
        "",
        &mut rows,
    );
    let _ = writeln!(out, "## Parameters\n");
    if rows.is_empty() {
        let _ = writeln!(out, "None.\n");
    } else {
        let _ = writeln!(
            out,
            "| parameter | type | default | description |\n|---|---|---|---|"
        );
        for r in rows {
            let _ = writeln!(out, "| {} | {} | {} | {} |", r[0], r[1], r[2], r[3]);
        }
        out.push('\n');
    }
    if !s.timings.is_empty() {
        let _ = writeln!(
            out,
            "## Timings\n\nIn the run report, not cached:\n\n| timing | description |\n|---|---|"
        );
        for t in &s.timings {
            let _ = writeln!(out, "| `{}` | {} |", t.name, cell(&t.doc));
        }
        out.push('\n');
    }
    out
}

/// The index: kinds grouped by the part of their name before the first dot.
pub fn index(sigs: &[&KindSignature]) -> String {
    let mut groups: BTreeMap<&str, Vec<&KindSignature>> = BTreeMap::new();
    for s in sigs {
        let group = s.kind.split('.').next().unwrap_or(&s.kind);
        groups.entry(group).or_default().push(s);
    }
    let mut out = String::from(
        "# Node reference\n\nGenerated from the catalog by `mesoflow docs --out docs/reference`; \
         a test fails when these pages are stale. `mesoflow nodes KIND` prints the same in the \
         terminal.\n\n",
    );
    for (group, kinds) in groups {
        let _ = writeln!(
            out,
            "## {group}\n\n| kind | version | device | |\n|---|---|---|---|"
        );
        for s in kinds {
            let first = s.doc.split(". ").next().unwrap_or("").trim_end_matches('.');
            let _ = writeln!(
                out,
                "| [`{k}`]({k}.md) | {} | {} | {}. |",
                s.version,
                format!("{:?}", s.device).to_lowercase(),
                cell(first),
                k = s.kind
            );
        }
        out.push('\n');
    }
    out
}

/// Every page of the reference, by file name.
pub fn pages() -> BTreeMap<String, String> {
    let registry = mesoflow_nodes::registry::builtin();
    let mut sigs: Vec<&KindSignature> = registry.signatures().collect();
    sigs.sort_by(|a, b| a.kind.cmp(&b.kind));
    let mut out = BTreeMap::new();
    out.insert("index.md".to_string(), index(&sigs));
    for s in sigs {
        out.insert(format!("{}.md", s.kind), page(s));
    }
    out
}

/// `mesoflow docs --out DIR`: writes every page, and removes pages of kinds that no longer exist.
pub fn write(dir: &Path) -> anyhow::Result<i32> {
    std::fs::create_dir_all(dir)?;
    let pages = pages();
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if path.extension().is_some_and(|e| e == "md") && !pages.contains_key(name) {
            std::fs::remove_file(&path)?;
        }
    }
    for (name, text) in &pages {
        std::fs::write(dir.join(name), text)?;
    }
    println!("{}: {} pages", dir.display(), pages.len());
    Ok(0)
}
