//! How close to the truth, held in CI: `graphs/truth.json` as the README measures it (the torus
//! under bumps 6 texels high, a ubo81 Lambert BTF, the MDF, 320 × 240, every node on the CPU)
//! and its open plane with and without the MDF, against the true mesostructure rendered by
//! `render.reference`. The bounds are the where this renderer meets them, else a
//! margin over what `cargo bench --bench truth` measured, so that a change that loses accuracy
//! fails here.

mod common;

#[path = "../benches/common/truth_scenes.rs"]
mod truth_scenes;

use common::{mesoflow, report, Scratch};
use serde_json::Value;
use std::path::Path;

fn measure(s: &Scratch, name: &str, sets: &[String]) -> (f64, f64) {
    let graph = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/truth.json");
    let out = s.path(name);
    let mut args: Vec<String> = vec![
        "run".into(),
        graph.display().to_string(),
        "--quiet".into(),
        "--device".into(),
        "cpu".into(),
        "--out-dir".into(),
        out.display().to_string(),
        "--cache-dir".into(),
        s.path("cache").display().to_string(),
        "--output".into(),
        "compare.relative_rmse".into(),
        "--output".into(),
        "compare.iou".into(),
    ];
    for kv in sets {
        args.push("--set".into());
        args.push(kv.clone());
    }
    let r = mesoflow(
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let compare: &Value = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "compare")
        .unwrap();
    let m = |k: &str| compare["metrics"][k].as_f64().unwrap_or(f64::NAN);
    (m("relative_rmse"), m("iou"))
}

#[test]
fn renders_stay_as_close_to_the_true_mesostructure_as_measured() {
    let s = Scratch::new();
    // The torus: the bounds, relative RMSE at most 0.30 (measured 0.266) and silhouette
    // IoU at least 0.99 (measured 0.992; every node on the CPU, so the same bits every run).
    let (rmse, iou) = measure(&s, "torus", &[]);
    eprintln!("torus: relative RMSE {rmse:.4}, IoU {iou:.4}");
    assert!(rmse <= 0.30, "torus relative RMSE {rmse}");
    assert!(iou >= 0.99, "torus IoU {iou}");
    // The open plane: the shell's side carves its edge (IoU measured 0.953 with the MDF, 0.923
    // without; the issue asks 0.97, not met yet), and the parallax-compensated view blend needs
    // the MDF (relative RMSE measured 0.264 with it, 0.385 without).
    let renders = ["truth", "ours"];
    let (with_rmse, with_iou) = measure(
        &s,
        "plane_mdf",
        &truth_scenes::plane_sets(320, true, &renders),
    );
    let (without_rmse, without_iou) =
        measure(&s, "plane", &truth_scenes::plane_sets(320, false, &renders));
    eprintln!(
        "plane: MDF relative RMSE {with_rmse:.4}, IoU {with_iou:.4}; without {without_rmse:.4}, {without_iou:.4}"
    );
    assert!(with_iou >= 0.945, "plane IoU with the MDF {with_iou}");
    assert!(with_iou > without_iou + 0.02, "{with_iou} vs {without_iou}");
    assert!(
        with_rmse <= 0.29,
        "plane relative RMSE with the MDF {with_rmse}"
    );
}
