//! The scene families (`mesoflow_testkit::scenes`): each family's shipped template with a
//! scene's `--set`s is that scene's graph, for development and held-out seeds alike, so what the
//! bench measures and what a user runs from the printed command are the same graph. With
//! `MESOFLOW_WRITE_TEMPLATES=1` the test first writes each template's nodes from the generator.

use mesoflow_graph::{parse_override, GraphFile, NodeDecl};
use mesoflow_testkit::scenes::{self, Kind};
use std::collections::BTreeMap;
use std::path::Path;

fn nodes(file: &GraphFile) -> BTreeMap<String, NodeDecl> {
    file.nodes.iter().cloned().collect()
}

fn parse(text: &str) -> GraphFile {
    GraphFile::parse(text).unwrap_or_else(|e| panic!("{e:?}"))
}

#[test]
fn the_template_with_a_scenes_sets_is_that_scenes_graph() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for kind in Kind::ALL {
        let path = root.join(kind.template());
        let (resolution, samples) = (kind.resolution(), kind.samples());
        let zero = scenes::family(kind, 0);
        if std::env::var_os("MESOFLOW_WRITE_TEMPLATES").is_some() {
            // Rewrites the template's nodes from the generator (its description kept).
            let text = std::fs::read_to_string(&path).expect("the template");
            let mut file: serde_json::Value = serde_json::from_str(&text).expect("JSON");
            file["nodes"] = zero.graph(resolution, samples)["nodes"].clone();
            let out = serde_json::to_string_pretty(&file).expect("JSON") + "\n";
            std::fs::write(&path, out).expect("write the template");
        }
        let template = parse(&std::fs::read_to_string(&path).expect("the template"));
        assert_eq!(
            nodes(&template),
            nodes(&parse(&zero.graph(resolution, samples).to_string())),
            "as written, {} is seed 0",
            kind.template()
        );
        for seed in (0..24).chain(scenes::HELD_OUT..scenes::HELD_OUT + 8) {
            let scene = scenes::family(kind, seed);
            for (resolution, samples) in [(resolution, samples), ([32, 24], 4)] {
                let mut file = template.clone();
                for set in scene.sets(resolution, samples) {
                    let o = parse_override(&set).unwrap_or_else(|e| panic!("{set}: {e}"));
                    file.apply(&o).unwrap_or_else(|e| panic!("{set}: {e}"));
                }
                let drawn = parse(&scene.graph(resolution, samples).to_string());
                assert_eq!(nodes(&file), nodes(&drawn), "{}", scene.name());
            }
        }
    }
}

/// Heights from normals over the family (docs/guide/relief.md, "Over a family of tiles").
/// Held-out seeds are used once, each set against bounds fixed before its first run, and none
/// has passed: 1 000 000..1 000 012 failed the guide's claims made on one smooth noise tile
/// (the residual weights halve the error with outliers; Frankot–Chellappa at most 20% worse
/// than least squares); 1 000 012..1 000 024 failed Fourier ≤ 1.8× plain (seed 1 000 019,
/// 1.82×); 1 000 024..1 000 036 failed "on smooth tiles with outliers, weighting takes the
/// corruption's share of the error to at most 0.65 of plain's" (seed 1 000 034, 0.68). All 36
/// are spent and join the development seeds 0..12 here, where the three statements that held
/// on every one of those 48 scenes are held (regression bounds, not a held-out result):
/// - with outliers, weighting by the residual lowers the error on every tile;
/// - without outliers it never raises it by more than 1.5% (measured at most +1.0%);
/// - Frankot–Chellappa is at most 2× plain least squares' error (measured up to 1.88×).
#[test]
fn heights_from_normals_over_the_family() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scratch = tempfile::tempdir().expect("a scratch folder");
    let mut failures = Vec::new();
    let mut table = Vec::new();
    for seed in (0..12).chain(scenes::HELD_OUT..scenes::HELD_OUT + 36) {
        let scene = scenes::family(Kind::HeightFromNormals, seed);
        let out = scratch.path().join(format!("seed-{seed}"));
        let report = crate::common::run_graph(
            root,
            Kind::HeightFromNormals.template(),
            &out,
            &scene.sets(Kind::HeightFromNormals.resolution(), 0),
        );
        let error = |id: &str| crate::common::metric(&report, id, "error_texels");
        let (clean, plain) = (error("clean"), error("plain"));
        let (weighted, fourier) = (error("weighted"), error("fourier"));
        let scenes::Scene::HeightFromNormals(s) = &scene else {
            unreachable!("the family draws its own scenes")
        };
        let name = scene.name();
        table.push(format!(
            "{name}: clean {clean:.4}, plain {plain:.4}, weighted {weighted:.4}, fourier {fourier:.4} texels"
        ));
        if s.outliers > 0.0 && weighted >= plain {
            failures.push(format!("{name}: weighted {weighted:.4} ≥ plain {plain:.4}"));
        }
        if s.outliers == 0.0 && weighted > 1.015 * plain {
            failures.push(format!(
                "{name}: weighted {weighted:.4} > plain {plain:.4} + 1.5% without outliers"
            ));
        }
        if fourier > 2.0 * plain {
            failures.push(format!(
                "{name}: fourier {fourier:.4} > 2 × plain {plain:.4}"
            ));
        }
    }
    println!("{}", table.join("\n"));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Ward fits of Cook–Torrance samples over the family (docs/guide/manifolds.md, "Over a family
/// of samples"), a cross-model check: the guide's one-sample bounds (ρd 0.5%, ρs 20%, α 10%)
/// failed on the development seeds 0..12 (up to 0.72%, 27.5%, 12.6%, with eight rust seeds).
/// Bounds set from those twelve before the held-out seeds 1 000 000..1 000 012 were first run
/// (median relative errors ρd ≤ 1%, ρs ≤ 35%, α ≤ 16%; Spearman ≥ 0.99) failed there on ρd
/// (seed 1 000 006, seven rust seeds: 1.20%); that set is spent. What is held over all 24
/// samples seen (regression bounds, not a held-out result): ρd ≤ 1.5%, ρs ≤ 35%, α ≤ 16%,
/// and the degree's Spearman correlation with the truth ≥ 0.99 where the sample marks both
/// ends (measured ≥ 0.9938). A sample that marks no most- or least-weathered pixel has no
/// degree (the run names the missing mask; three of the 24), and is counted, not failed: at
/// most six may be.
#[test]
fn ward_fits_over_the_family() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scratch = tempfile::tempdir().expect("a scratch folder");
    let (mut failures, mut table, mut without_ends) = (Vec::new(), Vec::new(), 0);
    for seed in (0..12).chain(scenes::HELD_OUT..scenes::HELD_OUT + 12) {
        let scene = scenes::family(Kind::WardFit, seed);
        let out = scratch.path().join(format!("seed-{seed}"));
        let (run, report) = crate::common::try_run_graph(
            root,
            Kind::WardFit.template(),
            &out,
            &scene.sets([0, 0], 0),
        );
        let m = |id: &str, k: &str| crate::common::metric(&report, id, k);
        let name = scene.name();
        let (rho_d, rho_s, alpha) = (
            m("fit", "error_rho_d"),
            m("fit", "error_rho_s"),
            m("fit", "error_alpha"),
        );
        let spearman = if run.code == 0 {
            Some(m("degree", "spearman"))
        } else {
            // Only the degree may fail, and only for want of a marked end.
            assert!(
                run.stderr.contains("node `degree`") && run.stderr.contains("no pixel is marked"),
                "{name}: {}",
                run.stderr
            );
            without_ends += 1;
            None
        };
        table.push(format!(
            "{name}: ρd {rho_d:.4}, ρs {rho_s:.4}, α {alpha:.4}, Spearman {}",
            spearman.map_or("absent (no marked end)".into(), |s| format!("{s:.4}"))
        ));
        for (what, value, bound) in [
            ("ρd", rho_d, 0.015),
            ("ρs", rho_s, 0.35),
            ("α", alpha, 0.16),
        ] {
            if value > bound {
                failures.push(format!("{name}: {what} {value:.4} > {bound}"));
            }
        }
        if spearman.is_some_and(|s| s < 0.99) {
            failures.push(format!("{name}: Spearman {spearman:?} < 0.99"));
        }
    }
    println!(
        "{}\nsamples without a marked end: {without_ends}",
        table.join("\n")
    );
    // Measured three of the 24; at most twice that, so that the degree is checked on most
    // samples (a run where every sample failed for want of a mark would otherwise pass).
    assert!(
        without_ends <= 6,
        "{without_ends} of 24 samples without a marked end (measured 3)\n{}",
        table.join("\n")
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
