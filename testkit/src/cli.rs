//! Running the `mesoflow` binary of this checkout from a test or a bench, and reading its report.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's root folder.
pub fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// The `mesoflow` binary: `MESOFLOW_BIN`, else the one beside the running test or bench
/// (`target/<profile>/mesoflow`; cargo builds it before the root package's tests and benches).
pub fn bin() -> PathBuf {
    if let Some(p) = std::env::var_os("MESOFLOW_BIN") {
        return PathBuf::from(p);
    }
    let exe = std::env::current_exe().expect("the running test's path");
    let mut dir = exe.parent().expect("the test's folder").to_path_buf();
    if dir.ends_with("deps") {
        dir.pop();
    }
    dir.join(format!("mesoflow{}", std::env::consts::EXE_SUFFIX))
}

/// Runs `mesoflow ARGS`; a failure ends the test or bench with its stderr.
pub fn mesoflow(args: &[&str]) -> std::process::Output {
    let out = Command::new(bin())
        .args(args)
        .env_remove("MESOFLOW_CACHE")
        .output()
        .unwrap_or_else(|e| panic!("run {}: {e}", bin().display()));
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

/// Runs `cmd` to its end: its output, or the last line of its stderr where it failed (what the
/// benches report of a peer or a run that did not finish).
pub fn output_or_last_error(cmd: &mut Command) -> Result<std::process::Output, String> {
    let out = cmd.output().map_err(|e| e.to_string())?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(err.lines().last().unwrap_or("failed").to_string());
    }
    Ok(out)
}

/// Runs `benches/mesh_peer.py` (Mitsuba 3 in the peer venv) on `scene`, written as
/// `dir/mitsuba.json`: its JSON line, or why not (no venv, the peer's last error line).
pub fn mesh_peer(dir: &Path, scene: &Value) -> Result<Value, String> {
    let python = repo().join("target/peer-venv/bin/python");
    if !python.exists() {
        return Err("no peer venv (target/peer-venv; .ci/run makes it)".into());
    }
    let path = dir.join("mitsuba.json");
    std::fs::write(&path, scene.to_string()).map_err(|e| e.to_string())?;
    let out = output_or_last_error(
        Command::new(&python)
            .arg(repo().join("benches/mesh_peer.py"))
            .arg(&path),
    )?;
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().unwrap_or("")).map_err(|e| e.to_string())
}
