//! The shipped graphs of each capability, run end to end at small sizes (BTF, UBO2003 files,
//! MDF, translucency, Isomap, weathering, Ward fits, the quasi-homogeneous fit).

use crate::common::*;
use std::path::Path;

#[test]
fn btf_pipeline_reports_the_error_it_measures() {
    // btf.pca reports the Eckart–Young RMSE; btf.compare measures the reconstruction. They agree
    // to f32 storage precision of the basis (1e-4 relative is generous).
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let r = mesoflow(
        &[
            "run",
            root.join("graphs/btf_compress.json").to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--set",
            "surface.size=16",
            "--set",
            "surface.count=2",
            "--set",
            "pca.rank=3",
            "--out-dir",
            out.to_str().unwrap(),
        ],
        root,
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let metric = |id: &str, m: &str| metric(&rep, id, m);
    let (reported, measured) = (metric("pca", "rmse"), metric("compare", "rmse"));
    assert!(
        reported > 0.0 && (reported - measured).abs() <= 1e-4 * reported,
        "{reported} vs {measured}"
    );
    assert_eq!(metric("pca", "rank"), 3.0);
    let table = std::fs::read_to_string(out.join("btf_errors.csv")).unwrap();
    assert_eq!(table.lines().count(), 1 + 9 * 9, "a row per direction pair");
    assert!(table.contains(",30,0,"), "degrees print cleanly: {table}");
    assert!(out.join("per_pair_rmse.exr").is_file() && out.join("capture.png").is_file());
}

#[test]
fn ubo2003_files_written_by_one_graph_read_back_bit_exactly_in_another() {
    // btf_capture.json writes EXR files; a second graph captures the same surface, reads the
    // files and compares: EXR holds f32 exactly and the running index keeps the pair order, so
    // the error is exactly zero.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let small = ["--set", "tile.size=16", "--set", "tile.count=2"];
    let mut args = vec![
        "run".to_string(),
        root.join("graphs/btf_capture.json")
            .to_str()
            .unwrap()
            .to_string(),
    ];
    args.extend(small.iter().map(|a| a.to_string()));
    args.extend(["--quiet", "--no-cache", "--out-dir", out.to_str().unwrap()].map(String::from));
    let r = mesoflow(&args.iter().map(String::as_str).collect::<Vec<_>>(), root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let text = std::fs::read_to_string(root.join("graphs/btf_capture.json")).unwrap();
    let mut g: serde_json::Value = serde_json::from_str(&text).unwrap();
    let nodes = g["nodes"].as_object_mut().unwrap();
    nodes.remove("files");
    nodes.remove("preview_png");
    // The copy lives in another folder: its subgraph by its absolute path.
    nodes["tile"]["params"]["path"] = root
        .join("graphs/woven_capture.json")
        .display()
        .to_string()
        .into();
    nodes.insert(
        "read".into(),
        serde_json::json!({ "kind": "btf.read_ubo2003", "params": { "path": "o/ubo2003" } }),
    );
    nodes.insert(
        "compare".into(),
        serde_json::json!({ "kind": "btf.compare",
            "inputs": { "reference": "tile.btf", "btf": "read.btf" } }),
    );
    let graph = s.write("readback.json", &g.to_string());
    let out2 = s.path("o2");
    let mut args = vec!["run".to_string(), graph.to_str().unwrap().to_string()];
    args.extend(small.iter().map(|a| a.to_string()));
    args.extend(["--quiet", "--no-cache", "--out-dir", out2.to_str().unwrap()].map(String::from));
    let r = mesoflow(&args.iter().map(String::as_str).collect::<Vec<_>>(), root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out2);
    let compare = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "compare")
        .unwrap();
    assert_eq!(compare["metrics"]["rmse"], 0.0);
    assert_eq!(compare["metrics"]["max_error"], 0.0);
}

#[test]
fn mdf_render_graph_renders_with_and_without_silhouettes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let dirs = r#"{"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#;
    let mut args: Vec<String> = vec![
        "run".into(),
        root.join("graphs/mdf_render.json").display().to_string(),
        "--quiet".into(),
        "--no-cache".into(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    let mut set = |kv: String| {
        args.push("--set".into());
        args.push(kv);
    };
    set("tile.size=16".into());
    set("tile.count=2".into());
    set(format!("tile.views={dirs}"));
    set(format!("tile.lights={dirs}"));
    set(format!("mdf.views={dirs}"));
    for r in [
        "sphere_plain",
        "sphere_mdf",
        "torus_plain",
        "torus_mdf",
        "torus_reference",
    ] {
        set(format!("{r}.camera.resolution=[48,36]"));
        set(format!("{r}.shadow_resolution=128"));
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = mesoflow(&args, root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let metric = |id: &str, m: &str| metric(&rep, id, m);
    // The MDF carves the outline: fewer pixels show the torus than without it.
    assert!(metric("torus_mdf", "coverage") < metric("torus_plain", "coverage"));
    // Timings are in the report, not among the outputs (they are not cached).
    let node = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "torus_mdf")
        .unwrap();
    assert!(node["timings"]["frame_ms"].as_f64().unwrap() > 0.0);
    assert!(node["metrics"].get("frame_ms").is_none());
    let rmse = metric("error", "rmse");
    assert!(
        rmse.is_finite() && rmse > 0.0,
        "PCA rank 16 of 81 pairs is lossy: {rmse}"
    );
    let row = image::open(out.join("torus_plain_vs_mdf.png")).unwrap();
    assert_eq!((row.width(), row.height()), (48 + 4 + 48, 36));
    let mut f = std::fs::File::open(out.join("weave_mdf.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[9, 16, 16]);
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("weave_mdf.json")).unwrap())
            .unwrap();
    assert_eq!(side["views"].as_array().unwrap().len(), 9);
    assert_eq!(side["views"][1], serde_json::json!([40.0, 0.0]));
}

#[test]
fn sss_models_graph_compares_a_model_with_monte_carlo_and_writes_f64_profiles() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/sss_models.json",
        &out,
        &["reference.photons=20000".into(), "profile.points=64".into()],
    );
    // Ketchup red: the dipole is ~10% high against Monte Carlo (domain notes: ≈12%).
    let e = metric(&rep, "error", "total_error_r");
    assert!((0.04..0.2).contains(&e), "{e}");
    assert!(metric(&rep, "reference", "stderr_r") > 0.0);
    // The NPY contract: (4, n) little-endian f64, radii first.
    let bytes = std::fs::read(out.join("profile.npy")).unwrap();
    let header = String::from_utf8_lossy(&bytes[10..128]).to_string();
    assert!(
        header.contains("'descr': '<f8'") && header.contains("'shape': (4, 64"),
        "{header}"
    );
}

#[test]
fn sss_render_and_qh_render_graphs_render() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let small = |ids: &[&str]| -> Vec<String> {
        ids.iter()
            .flat_map(|id| {
                [
                    format!("{id}.camera.resolution=[32,24]"),
                    format!("{id}.shadow_resolution=128"),
                    format!("{id}.max_points=3000"),
                    // The `body` grid solver is 3-8 s a render here; the octree against brute
                    // force is the same question with either gather (body: every_graph's
                    // family_translucent and the sss.render unit tests).
                    format!("{id}.geometry=exit_normal"),
                ]
            })
            .collect()
    };
    let rep = run_graph(
        root,
        "graphs/sss_render.json",
        &s.path("a"),
        &small(&["marble", "skin", "marble_reference"]),
    );
    // The octree at 0.05 is close to brute force (the sss.render tests bound it).
    assert!(metric(&rep, "marble_error", "rmse") < 0.01);
    assert!(metric(&rep, "skin", "points") <= 3000.0);
    assert!(s.path("a").join("marble_and_skin.png").exists());
    let mut sets = small(&["homogeneous", "qh"]);
    sets.extend([
        "tile.size=16".into(),
        "tile.count=2".into(),
        r#"tile.views={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#.into(),
        r#"tile.lights={"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#.into(),
    ]);
    run_graph(root, "graphs/qh_render.json", &s.path("b"), &sets);
    assert!(s.path("b").join("homogeneous_vs_qh.png").exists());
}

#[test]
fn isomap_graph_embeds_the_swiss_roll_as_f64_npy() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(root, "graphs/isomap.json", &out, &[]);
    assert_eq!(metric(&rep, "isomap", "graph_components"), 1.0);
    let rv = metric(&rep, "isomap", "residual_variance");
    assert!((0.0..0.05).contains(&rv), "{rv}");
    let mut f = std::fs::File::open(out.join("embedding.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[2000, 2]);
    assert!(npy.dtype().descr().contains("f8"));
}

#[test]
fn weathering_graph_recovers_the_degree_of_the_built_in_sample() {
    // Spearman against the true degree, from the command line, on a 32² sample; every pixel's
    // fit converges. Measured 0.9985 here (0.9983 at the graph's 64², the guide's 0.998); the
    // bound 0.994 is within 4× of that distance from 1 (the issue asked 0.95).
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/weathering.json",
        &out,
        &["sample.size=32".to_string()],
    );
    let rho = metric(&rep, "degree", "spearman");
    assert!(rho >= 0.994, "{rho}");
    assert_eq!(metric(&rep, "fit", "not_converged"), 0.0);
    assert!(out.join("degree_true_vs_recovered.png").exists());
    for dir in ["weathering", "deweathering"] {
        assert!(out.join(dir).join("frame_007.png").exists());
        let gif = std::fs::read(out.join(dir).join("frame.gif")).unwrap();
        assert_eq!(&gif[..6], b"GIF89a");
    }
    assert!(metric(&rep, "evolve", "mean_degree") > metric(&rep, "deweather", "mean_degree"));
    assert!(metric(&rep, "fit", "error_rho_d") < 1e-3);
    let mut f = std::fs::File::open(out.join("ward_maps.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[32, 32, 5]);
    assert!(npy.dtype().descr().contains("f8"));
}

#[test]
fn a_ward_fit_of_a_cook_torrance_sample_is_a_cross_model_check() {
    // The Ward fit of a Ward-rendered sample is a solver check (the data come from the model
    // fitted). Rendered with Cook–Torrance (Beckmann, Fresnel, masking–shadowing) the Ward fit
    // cannot match exactly: how far its parameters land and whether the degree survives is the
    // accuracy a user of real captures can expect. Bounds: about twice what a 32² sample
    // measured (ρd 0.19%, ρs 11%, α 5.4%, Spearman 0.9986), quoted in docs/guide/manifolds.md.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/weathering.json",
        &out,
        &[
            "sample.size=32".to_string(),
            "sample.reflectance=cook_torrance".to_string(),
        ],
    );
    let m = |id: &str, k: &str| metric(&rep, id, k);
    assert!(
        m("fit", "error_rho_d") < 0.005,
        "{}",
        m("fit", "error_rho_d")
    );
    assert!(m("fit", "error_rho_s") < 0.2, "{}", m("fit", "error_rho_s"));
    assert!(m("fit", "error_alpha") < 0.1, "{}", m("fit", "error_alpha"));
    assert!(
        m("fit", "error_rho_s") > 0.01,
        "not a solver check: the models differ"
    );
    assert!(
        m("degree", "spearman") >= 0.99,
        "{}",
        m("degree", "spearman")
    );
}

#[test]
fn weathering_transfer_graph_lays_the_degree_onto_a_larger_guided_target() {
    // The saved pipeline end to end: the synthesized degree map has the target's size, its
    // energy fell during the finest stage, it follows the guide (rust gathers where the ramp is
    // high: the bottom third's mean degree above the top third's), and the transferred maps and
    // the weathering frames exist.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(root, "graphs/weathering_transfer.json", &out, &[]);
    assert!(metric(&rep, "degree", "spearman") >= 0.95);
    assert!(metric(&rep, "synth", "energy") < metric(&rep, "synth", "energy_start"));
    let mut f = std::fs::File::open(out.join("target_degree.npy")).unwrap();
    let npy = npyz::NpyFile::new(&mut f).unwrap();
    assert_eq!(npy.shape(), &[128, 192, 1]);
    let d: Vec<f32> = npy.into_vec().unwrap();
    let third = |rows: std::ops::Range<usize>| {
        let n = rows.len() * 192;
        rows.map(|y| d[y * 192..(y + 1) * 192].iter().sum::<f32>())
            .sum::<f32>()
            / n as f32
    };
    let (top, bottom) = (third(0..42), third(86..128));
    assert!(bottom > top + 0.3, "top {top}, bottom {bottom}");
    let mut f = std::fs::File::open(out.join("target_ward_maps.npy")).unwrap();
    assert_eq!(npyz::NpyFile::new(&mut f).unwrap().shape(), &[128, 192, 5]);
    assert!(out.join("target_weathering").join("frame_005.png").exists());
    assert!(out.join("target_guide_degree_appearance.png").exists());
    let m = metric(&rep, "evolve", "mean_degree");
    assert!(m > metric(&rep, "transfer", "mean_degree"), "{m}");
}

#[test]
fn weathering_graph_fits_a_bumpy_sample_with_photometric_normals() {
    // A relief tilting pixels up to 25° (sample.bumps): the photometric-stereo normals and the
    // joint refinement bring the fit back to the flat sample's accuracy (measured at 64²:
    // normal median 0.001°, parameter medians < 1e-6, Spearman 0.998; the flat fit on the same
    // data: 19% / 26% / 59%, Spearman 0.957). At this test's 32²: 0.00104°, at most 2.0e-8 and
    // 0.9985. Bounds within 4× of those: 0.004°, 1e-6 (the guide's figure), Spearman 0.994 (a
    // quarter of the measured 0.0015 short of 1).
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/weathering.json",
        &out,
        &[
            "sample.size=32".to_string(),
            "sample.bumps=0.08".to_string(),
            "fit.normals=photometric".to_string(),
        ],
    );
    assert!(metric(&rep, "fit", "error_normal_deg") < 0.004);
    for m in ["error_rho_d", "error_rho_s", "error_alpha"] {
        assert!(metric(&rep, "fit", m) < 1e-6, "{m}");
    }
    assert!(metric(&rep, "degree", "spearman") >= 0.994);
    assert_eq!(metric(&rep, "fit", "normal_fallbacks"), 0.0);
}

#[test]
fn qh_fit_graph_recovers_known_coefficients_through_the_monte_carlo_table() {
    // issue 5: σa and σs′ within 5% from a Monte Carlo profile made with known values. The
    // saved graph with fewer photons so the test build stays quick (measured at these counts:
    // about 3% σs′, 1–2% σa); PBD's bias shows in the same run.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let rep = run_graph(
        root,
        "graphs/qh_fit.json",
        &out,
        &[
            "measured.photons=100000".to_string(),
            "fit_mc.photons=200000".to_string(),
            "refit.photons=50000".to_string(),
        ],
    );
    let (es, ea) = (
        metric(&rep, "fit_mc", "error_sigma_s_prime"),
        metric(&rep, "fit_mc", "error_sigma_a"),
    );
    assert!(es < 0.05 && ea < 0.05, "σs′ {es}, σa {ea}");
    assert!(metric(&rep, "fit_pbd", "error_sigma_a") > ea);
}

#[test]
fn a_tile_too_small_for_its_pattern_is_flat_and_says_so() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "nodes": {
            "small": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 16}},
            "fine": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 32}}}}"#,
    );
    let (r, rep) = run(&s, &g, "o", &["--no-cache"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let warnings: Vec<(String, String)> = rep["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| {
            (
                w["node"].as_str().unwrap().to_string(),
                w["message"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    // 8 threads across 16 texels: 2 texels each, every centre at the same phase.
    assert!(
        warnings
            .iter()
            .any(|(n, m)| n == "small" && m.contains("flat")),
        "{warnings:?}"
    );
    assert!(!warnings.iter().any(|(n, _)| n == "fine"), "{warnings:?}");
}

/// A warning the graph names in `expected_warnings` stays in the report, marked, and the run
/// prints one line that counts it instead of the warning; one it does not name still prints.
#[test]
fn a_warning_the_graph_expects_is_kept_in_the_report_and_not_printed() {
    let s = Scratch::new();
    let g = s.write(
        "g.json",
        r#"{"mesoflow": 1, "expected_warnings": {"small": ["flat"]}, "nodes": {
            "small": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 16}},
            "other": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 16}}}}"#,
    );
    // Not quiet: the summary is what is printed.
    let out = s.path("o");
    let args = [
        "run",
        g.to_str().unwrap(),
        "--no-cache",
        "--out-dir",
        out.to_str().unwrap(),
    ];
    let r = mesoflow(&args, s.dir.path());
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let printed = format!("{}{}", r.stdout, r.stderr);
    let small: Vec<&serde_json::Value> = rep["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["node"] == "small")
        .collect();
    assert!(!small.is_empty(), "{rep}");
    assert!(small.iter().all(|w| w["expected"] == true), "{small:?}");
    assert!(!printed.contains("warning: node `small`"), "{printed}");
    assert!(printed.contains("warning: node `other`"), "{printed}");
    assert!(
        printed.contains("the graph expects (its `expected_warnings`)"),
        "{printed}"
    );
    // A node the graph does not name is refused with a did-you-mean.
    let bad = s.write(
        "bad.json",
        r#"{"mesoflow": 1, "expected_warnings": {"smal": ["flat"]}, "nodes": {
            "small": {"kind": "heightfield.procedural", "params": {"pattern": "weave", "size": 16}}}}"#,
    );
    let r = mesoflow(&["run", bad.to_str().unwrap(), "--no-cache"], s.dir.path());
    assert_ne!(r.code, 0);
    assert!(
        r.stderr.contains("names no node `smal`") && r.stderr.contains("`small`"),
        "{}",
        r.stderr
    );
}
