//! From a BTF to editable geometry (issue 17), held from the command line on the saved graphs:
//! height from noisy normals, weighted and not, against the tile the normals came from.

use crate::common::{mesoflow, report, Scratch};
use serde_json::Value;
use std::path::Path;

/// Runs a saved graph with `--set`s and returns each node's metrics by id.
fn metrics(s: &Scratch, graph: &str, sets: &[&str]) -> std::collections::BTreeMap<String, Value> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = s.path(graph);
    let mut args = vec![
        "run".to_string(),
        root.join(format!("graphs/{graph}.json"))
            .display()
            .to_string(),
        "--quiet".into(),
        "--out-dir".into(),
        out.display().to_string(),
        "--cache-dir".into(),
        s.path("cache").display().to_string(),
    ];
    for kv in sets {
        args.extend(["--set".to_string(), kv.to_string()]);
    }
    let r = mesoflow(
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    report(&out)["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| (n["id"].as_str().unwrap().to_string(), n["metrics"].clone()))
        .collect()
}

#[test]
fn weighting_by_residual_keeps_outlier_normals_from_bending_the_height() {
    // The saved graph: a 128² noise tile 8 texels deep, normals by central differences, tilted
    // by σ = 2° and 5% outliers at 30°. Measured (docs/sweeps/height_from_normals/sweep.csv):
    // plain 0.087, weighted 0.035, Fourier 0.104 texels RMS. Bounds: the weighted error below
    // half the plain one and every error below 0.15 texel, so losing the weights or the
    // accuracy fails; the solvers are deterministic, the margin is for other platforms' libm.
    let s = Scratch::new();
    let m = metrics(&s, "height_from_normals", &[]);
    let e = |id: &str| m[id]["error_texels"].as_f64().unwrap();
    let (plain, weighted, fourier) = (e("plain"), e("weighted"), e("fourier"));
    eprintln!("plain {plain:.4}, weighted {weighted:.4}, Fourier {fourier:.4} texels");
    assert!(weighted < 0.5 * plain, "weighted {weighted} plain {plain}");
    for v in [plain, weighted, fourier] {
        assert!(v < 0.15, "{v}");
    }
    // Frankot–Chellappa, unweighted, is worse than least squares here (the guide's "up to 20%":
    // 1.07–1.21× over the sweep, 1.20× on this graph); held between 1× and 1.3×.
    assert!(
        fourier > plain && fourier < 1.3 * plain,
        "Fourier {fourier} plain {plain}"
    );
    // Without noise the three agree with the tile to 0.01 texel (measured 0.006): what is left
    // is the central differences' smoothing of the tile's normals, not the solvers.
    let m = metrics(
        &s,
        "height_from_normals",
        &["noise.sigma_deg=0", "noise.outliers=0"],
    );
    for id in ["plain", "weighted", "fourier"] {
        let v = m[id]["error_texels"].as_f64().unwrap();
        assert!(v < 0.01, "{id}: {v}");
    }
}

#[test]
#[ignore = "slow: graphs/btf_edit.json at full size (the Ward fit of 64² pixels over 8 × 16 directions), 99 s here"]
fn the_chain_on_a_photo_derived_ggx_capture_reports_its_model_error() {
    // graphs/btf_edit.json at full size: a gravel photograph's heights (RMS slope 0.30) captured
    // with GGX + Fresnel (α 0.3), which no Ward lobe contains, so these are model errors, not
    // solver checks. Measured: median normal error 5.03°, height 0.222 texels RMS, the
    // re-capture from what was recovered 0.230 relative RMSE. Bounds: 25% above each, so a
    // change that loses accuracy fails while rounding on another platform does not.
    let s = Scratch::new();
    let m = metrics(&s, "btf_edit", &[]);
    let get = |id: &str, k: &str| m[id][k].as_f64().unwrap_or(f64::NAN);
    let (normal, height, image) = (
        get("fit", "error_normal_deg"),
        get("height", "error_texels"),
        get("model_error", "relative_rmse"),
    );
    eprintln!(
        "normals {normal:.2}°, height {height:.3} texels, re-capture {image:.3} relative RMSE"
    );
    assert!(normal < 5.03 * 1.25, "{normal}");
    assert!(height < 0.222 * 1.25, "{height}");
    assert!(image < 0.230 * 1.25, "{image}");
    // Relief mapping on the sphere (16 linear + 6 binary steps): against render.mesh with the
    // BTF captured from the same height field and maps, measured 0.202 relative RMSE; against
    // itself at 512 + 12 steps (the search's own error), 0.0176. Bounds 25% above.
    let (relief, search) = (
        get("relief_error", "relative_rmse"),
        get("search_error", "relative_rmse"),
    );
    eprintln!("relief against render.mesh {relief:.3}, against its converged search {search:.4}");
    assert!(relief < 0.202 * 1.25, "{relief}");
    assert!(search < 0.0176 * 1.25, "{search}");
}

/// The default tier's run of the same chain: 3 × 4 view and light directions, 50 fit
/// iterations, 32 × 24 renders (the sizes tests/every_graph.rs uses).
const SMALL: &[&str] = &[
    r#"capture.views={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#,
    r#"capture.lights={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#,
    r#"recovered.views={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#,
    r#"recovered.lights={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#,
    r#"mdf.views={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#,
    "fit.iterations=50",
    "exact.camera.resolution=[32,24]",
    "exact.shadow_resolution=128",
    "relief.camera.resolution=[32,24]",
    "relief_converged.camera.resolution=[32,24]",
];

/// The small chain's figures as measured on this machine (2026-12-06), each bound 25% above.
const BOUND_N: f64 = 13.09;
const BOUND_H: f64 = 0.519;
const BOUND_I: f64 = 1.383;
const BOUND_R: f64 = 0.431;
const BOUND_S: f64 = 0.0226;

#[test]
fn the_chain_at_small_size_reports_its_model_error() {
    // The full-size figures are held by the slow test above; this holds the same chain at the
    // default tier's sizes, with bounds from this size's own measurement: normals 13.09°,
    // height 0.519 texels, re-capture 1.383, relief against render.mesh 0.431, against its
    // converged search 0.0226 (3 × 4 directions fit poorly: a regression check of the chain,
    // not an accuracy claim). Bounds 25% above each (as above: a loss of
    // accuracy fails, another platform's rounding does not).
    let s = Scratch::new();
    let m = metrics(&s, "btf_edit", SMALL);
    let get = |id: &str, k: &str| m[id][k].as_f64().unwrap_or(f64::NAN);
    let got = [
        ("normals (°)", get("fit", "error_normal_deg"), BOUND_N),
        ("height (texels)", get("height", "error_texels"), BOUND_H),
        ("re-capture", get("model_error", "relative_rmse"), BOUND_I),
        ("relief", get("relief_error", "relative_rmse"), BOUND_R),
        ("search", get("search_error", "relative_rmse"), BOUND_S),
    ];
    for (what, v, measured) in got {
        eprintln!("{what}: {v:.4} (measured {measured})");
        assert!(v < measured * 1.25, "{what}: {v}, measured {measured}");
    }
}
