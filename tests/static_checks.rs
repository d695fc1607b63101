//! `mesoflow validate` on broken graphs: each static-check error exits with code 2 and names the
//! file, the node and the parameter or port.

use crate::common::*;

fn validate(text: &str) -> Run {
    let s = Scratch::new();
    let g = s.write("g.json", text);
    let r = mesoflow(&["validate", g.to_str().unwrap()], s.dir.path());
    assert_eq!(
        r.code, 2,
        "expected exit code 2, got {}: {}{}",
        r.code, r.stdout, r.stderr
    );
    assert!(
        r.stderr.contains("g.json"),
        "the message names the file: {}",
        r.stderr
    );
    r
}

fn graph(nodes: &str) -> String {
    format!(r#"{{"mesoflow": 1, "nodes": {{ {nodes} }} }}"#)
}

const SURFACE: &str = r#""surface": {"kind": "heightfield.procedural", "params": {"size": 16}}"#;

#[test]
fn json_syntax_error_gives_line_and_column() {
    let r =
        validate("{\n  \"mesoflow\": 1,\n  \"nodes\": {\n    \"a\": {\"kind\": \"x\",}\n  }\n}\n");
    assert!(r.stderr.contains("line 4, column 23"), "{}", r.stderr);
}

#[test]
fn unknown_kind_suggests_the_nearest() {
    let r = validate(&graph(r#""surface": {"kind": "heightfield.procedual"}"#));
    assert!(
        r.stderr
            .contains("node `surface`: unknown kind `heightfield.procedual`"),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr.contains("did you mean `heightfield.procedural`"),
        "{}",
        r.stderr
    );
}

#[test]
fn bad_node_id() {
    let r = validate(&graph(r#""Surface-1": {"kind": "heightfield.procedural"}"#));
    assert!(
        r.stderr.contains("node id `Surface-1` is invalid"),
        "{}",
        r.stderr
    );
}

#[test]
fn duplicate_id() {
    let r = validate(&graph(&format!("{SURFACE}, {SURFACE}")));
    assert!(
        r.stderr
            .contains("node id `surface` is defined more than once"),
        "{}",
        r.stderr
    );
}

#[test]
fn unknown_parameter_suggests_the_nearest() {
    let r = validate(&graph(
        r#""surface": {"kind": "heightfield.procedural", "params": {"sise": 16}}"#,
    ));
    assert!(
        r.stderr
            .contains("node `surface` (heightfield.procedural): unknown parameter `sise`"),
        "{}",
        r.stderr
    );
    assert!(r.stderr.contains("did you mean `size`"), "{}", r.stderr);
}

#[test]
fn parameter_of_the_wrong_type() {
    let r = validate(&graph(
        r#""surface": {"kind": "heightfield.procedural", "params": {"size": "big"}}"#,
    ));
    assert!(
        r.stderr
            .contains("node `surface`: parameter `size` expects an integer, got string \"big\""),
        "{}",
        r.stderr
    );
    let r = validate(&graph(
        r#""surface": {"kind": "heightfield.procedural", "params": {"pattern": "waeve"}}"#,
    ));
    assert!(
        r.stderr.contains("parameter `pattern` expects one of"),
        "{}",
        r.stderr
    );
    assert!(r.stderr.contains("did you mean `weave`"), "{}", r.stderr);
}

#[test]
fn parameter_out_of_range() {
    let r = validate(&graph(
        r#""surface": {"kind": "heightfield.procedural", "params": {"size": 2}}"#,
    ));
    assert!(
        r.stderr
            .contains("node `surface`: parameter `size` is out of range: 2 is below the minimum 4"),
        "{}",
        r.stderr
    );
}

#[test]
fn missing_required_input() {
    let r = validate(&graph(r#""normals": {"kind": "heightfield.normals"}"#));
    assert!(
        r.stderr
            .contains("node `normals`: required input `height` (HeightField) is not connected"),
        "{}",
        r.stderr
    );
}

#[test]
fn missing_required_parameter() {
    let r = validate(&graph(r#""read": {"kind": "heightfield.read"}"#));
    assert!(
        r.stderr
            .contains("node `read`: required parameter `path` is missing"),
        "{}",
        r.stderr
    );
}

#[test]
fn input_naming_a_missing_node() {
    let r = validate(&graph(&format!(
        r#"{SURFACE}, "normals": {{"kind": "heightfield.normals", "inputs": {{"height": "surfac.height"}}}}"#
    )));
    assert!(
        r.stderr
            .contains("node `normals`: input `height` names node `surfac`, which does not exist"),
        "{}",
        r.stderr
    );
    assert!(r.stderr.contains("did you mean `surface`"), "{}", r.stderr);
}

#[test]
fn input_naming_a_missing_port() {
    let r = validate(&graph(&format!(
        r#"{SURFACE}, "normals": {{"kind": "heightfield.normals", "inputs": {{"height": "surface.heights"}}}}"#
    )));
    assert!(r.stderr.contains("node `normals`: input `height` names `surface.heights`, but `surface` (heightfield.procedural) has no output `heights`"), "{}", r.stderr);
    assert!(r.stderr.contains("did you mean `height`"), "{}", r.stderr);
}

#[test]
fn unknown_input_port() {
    let r = validate(&graph(&format!(
        r#"{SURFACE}, "normals": {{"kind": "heightfield.normals", "inputs": {{"height": "surface.height", "heigth2": "surface.height"}}}}"#
    )));
    assert!(
        r.stderr
            .contains("node `normals` (heightfield.normals): unknown input `heigth2`"),
        "{}",
        r.stderr
    );
}

#[test]
fn port_type_mismatch() {
    let r = validate(&graph(&format!(
        r#"{SURFACE}, "normals": {{"kind": "heightfield.normals", "inputs": {{"height": "surface.preview"}}}}"#
    )));
    assert!(
        r.stderr.contains(
            "`normals` input `height` expects HeightField, got Image from `surface.preview`"
        ),
        "{}",
        r.stderr
    );
}

#[test]
fn cycle_lists_its_nodes() {
    let r = validate(&graph(
        r#""a": {"kind": "scalar.affine", "inputs": {"x": "c.y"}},
           "b": {"kind": "scalar.affine", "inputs": {"x": "a.y"}},
           "c": {"kind": "scalar.affine", "inputs": {"x": "b.y"}}"#,
    ));
    assert!(r.stderr.contains("cycle: a -> b -> c -> a"), "{}", r.stderr);
}

#[test]
fn every_error_of_a_file_is_reported_at_once() {
    let r = validate(&graph(
        r#""surface": {"kind": "heightfield.procedural", "params": {"size": 0, "sise": 3}},
           "normals": {"kind": "heightfield.normals", "inputs": {"height": "surface.preview"}},
           "out": {"kind": "image.wirte"}"#,
    ));
    assert!(r.stderr.contains("4 errors"), "{}", r.stderr);
    for needle in [
        "parameter `size`",
        "`sise`",
        "`normals` input `height`",
        "`image.wirte`",
    ] {
        assert!(r.stderr.contains(needle), "missing {needle}: {}", r.stderr);
    }
}

#[test]
fn set_is_checked_like_the_file() {
    let s = Scratch::new();
    let g = s.write("g.json", &graph(SURFACE));
    let r = mesoflow(
        &["run", g.to_str().unwrap(), "--set", "surface.size=1"],
        s.dir.path(),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("parameter `size` is out of range"),
        "{}",
        r.stderr
    );
    let r = mesoflow(
        &["run", g.to_str().unwrap(), "--set", "surfce.size=8"],
        s.dir.path(),
    );
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("did you mean `surface`"), "{}", r.stderr);
}

#[test]
fn valid_graphs_in_the_repository_validate() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    for entry in std::fs::read_dir(root.join("graphs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "json") {
            let r = mesoflow(&["validate", path.to_str().unwrap()], root);
            assert_eq!(r.code, 0, "{}: {}", path.display(), r.stderr);
        }
    }
}

/// A negative value for a bounded integer reports the documented bounds, not the storage
/// type's (issue 58: "-5 is outside 0..=4294967295" for a size documented in [4, 8192]).
#[test]
fn a_negative_integer_reports_the_documented_bound() {
    let r = validate(
        r#"{"mesoflow": 1, "nodes": {"surface": {"kind": "heightfield.procedural", "params": {"size": -5}}}}"#,
    );
    assert!(
        r.stderr.contains("-5 is below the minimum 4") && !r.stderr.contains("4294967295"),
        "{}",
        r.stderr
    );
}

/// An unknown parameter given by `--set` is reported against the `--set`, not the graph file
/// (issue 58).
#[test]
fn an_unknown_parameter_from_set_is_the_sets_mistake() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {"surface": {"kind": "heightfield.procedural", "params": {"size": 64}}}}"#,
    );
    let r = mesoflow(
        &["validate", g.to_str().unwrap(), "--set", "surface.sise=32"],
        s.dir.path(),
    );
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains("--set surface.sise=32: node `surface` (heightfield.procedural) has no parameter `sise` (did you mean `size`?)"),
        "{}",
        r.stderr
    );
}
