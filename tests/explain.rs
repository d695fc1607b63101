//! Why a node re-ran: `reason` in `report.json` on every computed node, `run --explain`'s column
//! and `mesoflow explain` without running, for each change type, across processes (every step
//! is a new `mesoflow` process, so the reasons come from the records in the output folder).

use crate::common::{mesoflow, write_npy, Scratch};
use serde_json::Value;
use std::path::Path;

const GRAPH: &str = r#"{"mesoflow": 1, "nodes": {
    "c": {"kind": "scalar.constant", "params": {"value": 1.0}},
    "a": {"kind": "scalar.affine", "inputs": {"x": "c.value"}, "params": {"scale": 2.0}},
    "b": {"kind": "scalar.affine", "inputs": {"x": "a.y"}, "params": {"scale": 3.0}},
    "h": {"kind": "heightfield.read", "params": {"path": "h.npy"}}
}}"#;

fn reasons(out: &Path) -> Vec<(String, String, Option<String>)> {
    crate::common::report(out)["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            (
                n["id"].as_str().unwrap().to_string(),
                n["status"].as_str().unwrap().to_string(),
                n["reason"].as_str().map(String::from),
            )
        })
        .collect()
}

fn reason_of(out: &Path, id: &str) -> Option<String> {
    reasons(out)
        .into_iter()
        .find(|(n, ..)| n == id)
        .and_then(|(_, _, r)| r)
}

#[test]
fn every_computed_node_says_why_it_ran() {
    let s = Scratch::new();
    let g = s.write("g.json", GRAPH);
    write_npy(&s.path("h.npy"), 4, 4, |x, y| (x + y) as f32);
    let out = s.path("out");
    let run = |extra: &[&str]| {
        let (r, _) = crate::common::run(&s, &g, "out", extra);
        assert_eq!(r.code, 0, "{}{}", r.stdout, r.stderr);
    };

    // First run: every node, with no record to compare with.
    run(&[]);
    for (id, status, reason) in reasons(&out) {
        assert_eq!(status, "computed", "{id}");
        assert!(
            reason
                .as_deref()
                .is_some_and(|r| r.starts_with("first run")),
            "{id}: {reason:?}"
        );
    }

    // A parameter: named with both values; downstream, the input and the node that changed it.
    run(&["--set", "c.value=2.5"]);
    assert_eq!(reason_of(&out, "c").unwrap(), "parameter `value` 1.0 → 2.5");
    let b = reason_of(&out, "b").unwrap();
    assert!(
        b.contains("input `x` from `a.y` changed")
            && b.contains("`c`: parameter `value` 1.0 → 2.5"),
        "{b}"
    );
    // The file reader's key did not change: a disk-cache hit, no reason.
    let h = reasons(&out).into_iter().find(|(n, ..)| n == "h").unwrap();
    assert_eq!((h.1.as_str(), h.2.as_deref()), ("disk", None));

    // The same key again in a new process: scalars are kept in memory only, so they re-run and
    // say so.
    run(&["--set", "c.value=2.5"]);
    assert!(
        reason_of(&out, "c")
            .unwrap()
            .contains("kept in memory only"),
        "{:?}",
        reason_of(&out, "c")
    );

    // A file it reads.
    write_npy(&s.path("h.npy"), 4, 4, |x, y| (x * y) as f32);
    run(&["--set", "c.value=2.5"]);
    let h = reason_of(&out, "h").unwrap();
    assert!(
        h.starts_with("file `") && h.contains("h.npy` changed"),
        "{h}"
    );

    // Evicted: the same key, its value gone from the disk cache.
    let r = mesoflow(&["cache", "clear", g.to_str().unwrap()], s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    run(&["--set", "c.value=2.5"]);
    assert!(
        reason_of(&out, "h").unwrap().starts_with("evicted"),
        "{:?}",
        reason_of(&out, "h")
    );

    // --no-cache.
    run(&["--set", "c.value=2.5", "--no-cache"]);
    assert!(reason_of(&out, "h").unwrap().starts_with("--no-cache"));

    // The kind's version: the record says an older version made the key (and the value is
    // gone, so the node runs).
    let records = out.join(".mesoflow-keys.json");
    let mut doc: Value = serde_json::from_str(&std::fs::read_to_string(&records).unwrap()).unwrap();
    let version = doc["nodes"]["h"]["version"].as_u64().unwrap();
    doc["nodes"]["h"]["version"] = (version - 1).into();
    doc["nodes"]["h"]["key"] = "0".repeat(64).into();
    std::fs::write(&records, doc.to_string()).unwrap();
    let r = mesoflow(&["cache", "clear", g.to_str().unwrap()], s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    run(&["--set", "c.value=2.5"]);
    assert_eq!(
        reason_of(&out, "h").unwrap(),
        format!("heightfield.read version {} → {version}", version - 1)
    );

    // `run --explain` puts the reasons in the run table's last column.
    let mut args = vec![
        "run",
        g.to_str().unwrap(),
        "--explain",
        "--out-dir",
        out.to_str().unwrap(),
        "--set",
        "c.value=4",
    ];
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let header = r.stdout.lines().find(|l| l.starts_with("node")).unwrap();
    assert!(header.ends_with("why"), "{}", r.stdout);
    assert!(
        r.stdout
            .lines()
            .any(|l| l.starts_with("c ") && l.ends_with("parameter `value` 2.5 → 4.0")),
        "{}",
        r.stdout
    );

    // `mesoflow explain`: what a run would do, nothing run or written.
    let before = std::fs::read_to_string(out.join("report.json")).unwrap();
    args[0] = "explain";
    args[6] = "c.value=5";
    args.retain(|a| *a != "--explain");
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let line = |id: &str| {
        r.stdout
            .lines()
            .find(|l| l.starts_with(&format!("{id} ")))
            .unwrap_or_else(|| panic!("{}", r.stdout))
            .to_string()
    };
    assert!(line("c").contains(" run ") && line("c").ends_with("parameter `value` 4.0 → 5.0"));
    assert!(line("h").contains(" disk"), "{}", line("h"));
    assert!(r.stdout.contains("3 of 4 nodes would run"), "{}", r.stdout);
    assert_eq!(
        std::fs::read_to_string(out.join("report.json")).unwrap(),
        before
    );
}
