//! Subgraphs: a graph file used as a node. Static errors name the path through the nesting; an
//! inner node's key is its key when its file runs alone; `--set` reaches exposed and inner
//! parameters; the report lists inner nodes under their path and says why they re-ran.

use crate::common::{mesoflow, metric, Scratch};
use serde_json::Value;
use std::path::Path;

/// c → a → b, exposing `x` (a's input, fed inside by c), `y` (b's output) and `scale` (a's).
const INNER: &str = r#"{"mesoflow": 2,
  "interface": {"inputs": {"x": "a.x"}, "outputs": {"y": "b.y"}, "params": {"scale": "a.scale"}},
  "nodes": {
    "c": {"kind": "scalar.constant", "params": {"value": 1.0}},
    "a": {"kind": "scalar.affine", "inputs": {"x": "c.value"}, "params": {"scale": 2.0}},
    "b": {"kind": "scalar.affine", "inputs": {"x": "a.y"}, "params": {"scale": 3.0}}
}}"#;

/// Node `id` of a report; absent is a failure (a missing inner node must not compare equal).
fn node<'a>(r: &'a Value, id: &str) -> &'a Value {
    let n = mesoflow_testkit::cli::node(r, id);
    assert!(!n.is_null(), "no node {id} in {r}");
    n
}

/// `mesoflow run GRAPH --quiet --out-dir OUT EXTRA…`, which must succeed; its report.
fn run(s: &Scratch, graph: &Path, out: &str, extra: &[&str]) -> Value {
    let (r, report) = crate::common::run(s, graph, out, extra);
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    report
}

#[test]
fn a_subgraph_runs_as_if_inlined_with_the_keys_of_its_file() {
    let s = Scratch::new();
    let inner = s.write("inner.json", INNER);
    let outer = s.write(
        "outer.json",
        r#"{"mesoflow": 1, "nodes": {
            "p": {"kind": "graph", "params": {"path": "inner.json"}},
            "twice": {"kind": "scalar.affine", "inputs": {"x": "p.y"}, "params": {"scale": 2.0}}
        }}"#,
    );
    let alone = run(&s, &inner, "alone", &[]);
    let used = run(&s, &outer, "outer", &[]);
    // Every inner node is there under its path, with the key it has when its file runs alone.
    for id in ["c", "a", "b"] {
        assert_eq!(
            node(&used, &format!("p/{id}"))["key"],
            node(&alone, id)["key"],
            "{id}"
        );
    }
    assert_eq!(metric(&used, "twice", "y"), 2.0 * 3.0 * 2.0 * 1.0);
    // An exposed output asked for by name is the inner output it names.
    let r = mesoflow(
        &[
            "run",
            outer.to_str().unwrap(),
            "--quiet",
            "--output",
            "p.y",
            "--out-dir",
            s.path("asked").to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!((r.code, r.stdout.trim()), (0, "p/b.y = 6"), "{}", r.stderr);

    // An exposed parameter and an inner one by its path, from `--set`.
    let r = run(&s, &outer, "outer", &["--set", "p.scale=5"]);
    assert_eq!(metric(&r, "twice", "y"), 2.0 * 3.0 * 5.0);
    assert_eq!(
        node(&r, "p/a")["reason"],
        "parameter `scale` 2.0 → 5.0",
        "why it re-ran, inside the subgraph"
    );
    let r = run(&s, &outer, "outer", &["--set", "p/b.scale=7"]);
    assert_eq!(metric(&r, "twice", "y"), 2.0 * 7.0 * 2.0);

    // An exposed input given from outside replaces c, which fed only it: c is dropped, and a
    // constant of the same value gives the same keys as the file alone.
    let fed = s.write(
        "fed.json",
        r#"{"mesoflow": 1, "nodes": {
            "one": {"kind": "scalar.constant", "params": {"value": 1.0}},
            "p": {"kind": "graph", "params": {"path": "inner.json"}, "inputs": {"x": "one.value"}}
        }}"#,
    );
    let r = run(&s, &fed, "fed", &[]);
    assert!(
        r["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .all(|n| n["id"] != "p/c"),
        "{r}"
    );
    assert_eq!(node(&r, "p/b")["key"], node(&alone, "b")["key"]);

    // Nested: a file that uses inner.json, used in turn; `--set` by the whole path.
    s.write(
        "middle.json",
        r#"{"mesoflow": 2,
          "interface": {"outputs": {"y": "q.y"}, "params": {"scale": "q.scale"}},
          "nodes": {"q": {"kind": "graph", "params": {"path": "inner.json"}}}}"#,
    );
    let top = s.write(
        "top.json",
        r#"{"mesoflow": 1, "nodes": {
            "m": {"kind": "graph", "params": {"path": "middle.json", "scale": 4.0}},
            "end": {"kind": "scalar.affine", "inputs": {"x": "m.y"}, "params": {"scale": 1.0}}
        }}"#,
    );
    let r = run(&s, &top, "top", &["--set", "m/q/b.scale=10"]);
    assert_eq!(metric(&r, "end", "y"), 10.0 * 4.0);
    assert_eq!(node(&r, "m/q/c")["key"], node(&alone, "c")["key"]);

    // `dot` draws each subgraph as a box around its nodes, nested.
    let d = mesoflow(&["dot", top.to_str().unwrap()], s.dir.path());
    assert_eq!(d.code, 0, "{}", d.stderr);
    let (m, q, c) = (
        d.stdout.find("subgraph \"cluster_m\"").unwrap(),
        d.stdout.find("subgraph \"cluster_m/q\"").unwrap(),
        d.stdout.find("\"m/q/c\" [label=\"c").unwrap(),
    );
    assert!(m < q && q < c, "{}", d.stdout);

    // A sweep over an exposed parameter and an inner one by its path, measuring inside.
    let sweep = s.path("sweep");
    let r = mesoflow(
        &[
            "sweep",
            outer.to_str().unwrap(),
            "--quiet",
            "--vary",
            "p.scale=1,2",
            "--vary",
            "p/b.scale=1,10",
            "--measure",
            "twice.y",
            "--measure",
            "p/a.y",
            "--out-dir",
            sweep.to_str().unwrap(),
        ],
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    let csv = std::fs::read_to_string(sweep.join("sweep.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert!(
        rows[0].starts_with("p.scale,p/b.scale,twice.y,p/a.y"),
        "{csv}"
    );
    // scale 2, b 10: 1 × 2 × 10 × 2.
    assert!(rows[4].starts_with("2,10,40,2"), "{csv}");
}

#[test]
fn subgraph_mistakes_are_refused_naming_their_path() {
    let s = Scratch::new();
    s.write("inner.json", INNER);
    let validate = |text: &str| {
        let g = s.write("g.json", text);
        let r = mesoflow(&["validate", g.to_str().unwrap()], s.dir.path());
        assert_eq!(r.code, 2, "{}{}", r.stdout, r.stderr);
        r.stderr
    };
    // An exposed parameter that is not, with the nearest name.
    let e = validate(
        r#"{"mesoflow": 1, "nodes": {"p": {"kind": "graph", "params": {"path": "inner.json", "scael": 2}}}}"#,
    );
    assert!(
        e.contains("p/scael") && e.contains("did you mean `scale`"),
        "{e}"
    );
    // An exposed input or output that is not.
    let e = validate(
        r#"{"mesoflow": 1, "nodes": {
            "one": {"kind": "scalar.constant"},
            "p": {"kind": "graph", "params": {"path": "inner.json"}, "inputs": {"z": "one.value"}},
            "t": {"kind": "scalar.affine", "inputs": {"x": "p.w"}}}}"#,
    );
    assert!(
        e.contains("exposes no input `z`") && e.contains("exposes no output `w`"),
        "{e}"
    );
    // A value the inner kind's schema refuses, set two levels down: the path names it.
    s.write(
        "middle.json",
        r#"{"mesoflow": 2, "interface": {}, "nodes": {"q": {"kind": "graph", "params": {"path": "inner.json"}}}}"#,
    );
    let e = validate(
        r#"{"mesoflow": 1, "nodes": {"m": {"kind": "graph", "params": {"path": "middle.json", "set": {"q/a.scale": "big"}}}}}"#,
    );
    assert!(e.contains("m/q/a") && e.contains("scale"), "{e}");
    // A file that includes itself, directly or through another.
    s.write(
        "loop_a.json",
        r#"{"mesoflow": 1, "nodes": {"b": {"kind": "graph", "params": {"path": "loop_b.json"}}}}"#,
    );
    s.write(
        "loop_b.json",
        r#"{"mesoflow": 1, "nodes": {"a": {"kind": "graph", "params": {"path": "loop_a.json"}}}}"#,
    );
    let r = mesoflow(
        &["validate", s.path("loop_a.json").to_str().unwrap()],
        s.dir.path(),
    );
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains("includes itself")
            && r.stderr.contains("loop_a.json → loop_b.json → loop_a.json"),
        "{}",
        r.stderr
    );
    // A missing file names the folder it was looked for in.
    let e = validate(
        r#"{"mesoflow": 1, "nodes": {"p": {"kind": "graph", "params": {"path": "nosuch.json"}}}}"#,
    );
    assert!(e.contains("p/path") && e.contains("nosuch.json"), "{e}");
    // `interface` is version 2.
    let e = validate(r#"{"mesoflow": 1, "interface": {}, "nodes": {}}"#);
    assert!(e.contains("`interface` needs `\"mesoflow\": 2`"), "{e}");
}
