//! The documentation against the code: the node reference is what `mesoflow docs` generates
//! today, the README stays a newcomer's page, every relative link of the README and the guide
//! leads to a file, and every `mesoflow` command the guide shows names a real subcommand and
//! graph files that validate with the `--set`s it gives.

use crate::common::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn md_files(dir: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            out.insert(name, std::fs::read_to_string(&p).unwrap());
        }
    }
    out
}

#[test]
fn the_committed_node_reference_is_current() {
    let s = Scratch::new();
    let out = s.path("reference");
    let r = mesoflow(&["docs", "--out", out.to_str().unwrap()], s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let fresh = md_files(&out);
    let committed = md_files(&root().join("docs/reference"));
    let stale: Vec<&String> = fresh
        .iter()
        .filter(|(k, v)| committed.get(*k) != Some(v))
        .map(|(k, _)| k)
        .chain(committed.keys().filter(|k| !fresh.contains_key(*k)))
        .collect();
    assert!(
        stale.is_empty(),
        "docs/reference is stale in {stale:?}: run `mesoflow docs --out docs/reference`"
    );
    // One page a kind, and the index names each.
    let kinds = mesoflow(&["nodes", "--json"], s.dir.path());
    let n = serde_json::from_str::<serde_json::Value>(&kinds.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .len();
    assert_eq!(fresh.len(), n + 1);
}

#[test]
fn the_readme_is_a_newcomer_s_page() {
    let text = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = text.lines().count();
    assert!(
        lines < 250,
        "README.md has {lines} lines; the rest belongs in docs/guide"
    );
    // Exactly the two set-up commands, in its first code block.
    let first_block: Vec<&str> = text
        .split("```sh\n")
        .nth(1)
        .unwrap()
        .split("```")
        .next()
        .unwrap()
        .lines()
        .collect();
    assert_eq!(first_block.len(), 2, "{first_block:?}");
    assert!(first_block[0].starts_with("cargo run --release -- run graphs/quickstart.json"));
    assert!(first_block[1].starts_with("scripts/test"));
}

/// The targets of `](…)` links that are neither web addresses nor anchors.
fn relative_links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for part in text.split("](").skip(1) {
        let target = part.split(')').next().unwrap_or("");
        let target = target.split('#').next().unwrap_or("");
        if !target.is_empty() && !target.contains("://") && !target.starts_with("mailto:") {
            out.push(target.to_string());
        }
    }
    out
}

#[test]
fn every_relative_link_of_the_readme_and_the_guide_leads_to_a_file() {
    let mut pages: Vec<PathBuf> = vec![
        root().join("README.md"),
        root().join("docs/architecture.md"),
    ];
    for name in md_files(&root().join("docs/guide")).keys() {
        pages.push(root().join("docs/guide").join(name));
    }
    let mut broken = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        for link in relative_links(&text) {
            let target = page.parent().unwrap().join(&link);
            if !target.exists() {
                broken.push(format!("{}: {link}", page.display()));
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    // Every page of the guide is in its table of contents.
    let summary = std::fs::read_to_string(root().join("docs/guide/SUMMARY.md")).unwrap();
    for name in md_files(&root().join("docs/guide")).keys() {
        assert!(
            name == "SUMMARY.md" || summary.contains(&format!("({name})")),
            "docs/guide/{name} is not in SUMMARY.md"
        );
    }
}

/// The `mesoflow …` command lines of a page's `sh` blocks, continuation lines joined.
fn commands(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for block in text.split("```sh\n").skip(1) {
        let block = block.split("```").next().unwrap_or("");
        let joined = block.replace("\\\n", " ");
        for line in joined.lines() {
            let line = line.split(" #").next().unwrap_or("").trim();
            if let Some(rest) = line.strip_prefix("mesoflow ") {
                out.push(rest.to_string());
            }
        }
    }
    out
}

#[test]
fn every_command_the_guide_shows_names_a_subcommand_and_graphs_that_validate() {
    let s = Scratch::new();
    let subcommands = mesoflow(&["--help"], s.dir.path()).stdout;
    let mut checked = 0;
    let mut problems = Vec::new();
    let mut pages = vec![root().join("README.md")];
    for name in md_files(&root().join("docs/guide")).keys() {
        pages.push(root().join("docs/guide").join(name));
    }
    for page in pages {
        let text = std::fs::read_to_string(&page).unwrap();
        for cmd in commands(&text) {
            let words: Vec<&str> = cmd.split_whitespace().collect();
            let sub = words[0];
            if !subcommands.contains(&format!("  {sub} ")) {
                problems.push(format!(
                    "{}: `mesoflow {cmd}`: no subcommand `{sub}`",
                    page.display()
                ));
                continue;
            }
            // A shipped graph it names must validate with the `--set`s the line gives.
            let Some(graph) = words
                .iter()
                .find(|w| w.starts_with("graphs/") && w.ends_with(".json"))
            else {
                continue;
            };
            let mut args = vec![
                "validate".to_string(),
                root().join(graph).display().to_string(),
            ];
            for (i, w) in words.iter().enumerate() {
                if *w == "--set" {
                    if let Some(v) = words.get(i + 1) {
                        args.push("--set".into());
                        args.push(v.to_string());
                    }
                }
            }
            // The nodes it names (`--render ID`, `--output ID.PORT`) are in that graph.
            let text = std::fs::read_to_string(root().join(graph)).unwrap();
            let nodes = serde_json::from_str::<serde_json::Value>(&text).unwrap()["nodes"].clone();
            for (i, w) in words.iter().enumerate() {
                if *w == "--render" || *w == "--output" {
                    let id = words
                        .get(i + 1)
                        .and_then(|v| v.split('.').next())
                        .unwrap_or("");
                    if nodes.get(id).is_none() {
                        problems.push(format!(
                            "{}: `mesoflow {cmd}`: {graph} has no node `{id}`",
                            page.display()
                        ));
                    }
                }
            }
            let argv: Vec<&str> = args.iter().map(String::as_str).collect();
            let r = mesoflow(&argv, s.dir.path());
            checked += 1;
            if r.code != 0 {
                problems.push(format!(
                    "{}: `mesoflow {cmd}`: {}",
                    page.display(),
                    r.stderr.trim()
                ));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert!(
        checked >= 10,
        "only {checked} commands with a shipped graph were checked"
    );
}
