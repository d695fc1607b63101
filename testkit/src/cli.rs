//! Running the `mesoflow` binary from a bench and reading its report, shared by `#[path]`
//! inclusion (the planner's calibration and verification).

use serde_json::Value;
use std::process::Command;

/// Runs `mesoflow ARGS`; a failure ends the bench with its stderr.
pub fn mesoflow(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .args(args)
        .output()
        .expect("run mesoflow");
    assert!(
        out.status.success(),
        "mesoflow {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A node's entry in a run report (`null` when absent).
pub fn node<'a>(report: &'a Value, id: &str) -> &'a Value {
    report["nodes"]
        .as_array()
        .and_then(|a| a.iter().find(|n| n["id"] == id))
        .unwrap_or(&Value::Null)
}
