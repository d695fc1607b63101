//! The planner proved on the view (issue 41) on `graphs/plan_photo.json`, a scene that is not
//! the calibration's: a torus whose mesostructure is a photograph, the user's rank-16 basis, on
//! the CPU, a FLIP budget of 0.08, four distances. Each plan is run and measured on the full
//! frame against the graph as given. Held: the plan never gives more model than the graph (no
//! raw BTF in place of the basis, no higher rank, no finer level), every plan kept was within
//! the budget on its probe, and the budget acceptance on the full frames (within budget
//! at all but one distance, never beyond 1.5×). The acceptance is one function, whose budget
//! part a planner that always takes the cheapest model fails; its time part
//! (the far half's render at most 0.67× the graph's) is printed with the measured frames, not
//! asserted (no timing asserts in the default tier): BENCHMARKS.md states the last run's.

use crate::common::{mesoflow, metric, report, Run, Scratch};
use serde_json::Value;
use std::path::Path;

const BUDGET: f64 = 0.08;
/// Camera distances from the target: the nearest the graph's own, then 4.5, 11 and 26.
const EYES: [&str; 4] = [
    "[0.0,1.5,2.7]",
    "[0.0,2.1941,3.8713]",
    "[0.0,5.5078,9.4632]",
    "[0.0,13.1549,22.3676]",
];

struct Case {
    eye: &'static str,
    /// FLIP of the planned view against the graph's on the full frame.
    flip: f64,
    /// Frames of the graph's render and the planned one, s.
    full_s: f64,
    view_s: f64,
    plan: Value,
    planned: Value,
}

fn frame(report: &Value, id: &str) -> f64 {
    let n = report["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == id)
        .unwrap_or_else(|| panic!("no node {id}"));
    n["timings"]["frame_ms"]
        .as_f64()
        .map_or(f64::NAN, |ms| ms / 1e3)
}

fn run_ok(r: Run) {
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
}

/// Plans `view` at every distance for `budget` (with `extra` arguments), runs the planned
/// graph and measures it.
fn cases(s: &Scratch, name: &str, budget: f64, extra: &[&str]) -> Vec<Case> {
    // The graph and its photograph copied together: a planned graph reads its files from
    // its own folder, so it is written beside the graph (with its plan, named after it).
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs");
    let graphs = s.path("graphs");
    std::fs::create_dir_all(graphs.join("data")).unwrap();
    let graph = graphs.join("plan_photo.json");
    std::fs::copy(root.join("plan_photo.json"), &graph).unwrap();
    std::fs::copy(root.join("data/gravel.png"), graphs.join("data/gravel.png")).unwrap();
    let cache = s.path("cache");
    EYES.iter()
        .enumerate()
        .map(|(i, eye)| {
            let dir = s.path(&format!("{name}/{i}"));
            std::fs::create_dir_all(&dir).unwrap();
            let planned = graphs.join(format!("{name}_{i}.planned.json"));
            let mut args: Vec<String> = vec![
                "plan".into(),
                graph.display().to_string(),
                "--render".into(),
                "view".into(),
                "--budget".into(),
                format!("flip={budget}"),
                "--device".into(),
                "cpu".into(),
                "-o".into(),
                planned.display().to_string(),
                "--cache-dir".into(),
                cache.display().to_string(),
                "--quiet".into(),
            ];
            for id in ["full", "view"] {
                args.push("--set".into());
                args.push(format!("{id}.camera.eye={eye}"));
                args.push("--set".into());
                args.push(format!("{id}.camera.resolution=[160,120]"));
            }
            args.extend(extra.iter().map(|a| a.to_string()));
            run_ok(mesoflow(
                &args.iter().map(String::as_str).collect::<Vec<_>>(),
                &s.path(""),
            ));
            let out = dir.join("out");
            run_ok(mesoflow(
                &[
                    "run",
                    planned.to_str().unwrap(),
                    "--device",
                    "cpu",
                    "--output",
                    "flip.mean",
                    "--output",
                    "full.image",
                    "--output",
                    "view.image",
                    "--quiet",
                    "--out-dir",
                    out.to_str().unwrap(),
                    "--cache-dir",
                    cache.to_str().unwrap(),
                ],
                &s.path(""),
            ));
            let r = report(&out);
            let read = |p: &Path| -> Value {
                serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
            };
            Case {
                eye,
                flip: metric(&r, "flip", "mean"),
                full_s: frame(&r, "full"),
                view_s: frame(&r, "view"),
                plan: read(&graphs.join(format!("{name}_{i}.plan.json"))),
                planned: read(&planned),
            }
        })
        .collect()
}

/// The acceptance over the four distances: within the budget at all but at most one,
/// never beyond 1.5× of it, and over the far half (the two farthest) at most 0.67× the graph's
/// render time. `Err` says which part failed.
fn acceptance(flips: &[f64], time_ratios: &[f64]) -> Result<(), String> {
    let over = flips.iter().filter(|f| **f > BUDGET).count();
    if over > 1 {
        return Err(format!(
            "{over} of {} over the budget: {flips:?}",
            flips.len()
        ));
    }
    if flips.iter().any(|f| *f > 1.5 * BUDGET) {
        return Err(format!("a miss beyond 1.5× the budget: {flips:?}"));
    }
    let far = &time_ratios[time_ratios.len() / 2..];
    let mean = far.iter().sum::<f64>() / far.len() as f64;
    if mean.is_nan() || mean > 0.67 {
        return Err(format!(
            "the far half took {mean:.2}× the graph's time: {time_ratios:?}"
        ));
    }
    Ok(())
}

#[test]
fn plans_proved_on_the_view_stay_within_budget_and_never_add_model() {
    let s = Scratch::new();
    let ours = cases(&s, "proved", BUDGET, &[]);
    for c in &ours {
        println!(
            "eye {}: FLIP {:.4} (probe {:?}), frame {:.4} s against {:.4} s; {}",
            c.eye,
            c.flip,
            c.plan["probed_error"].as_f64(),
            c.view_s,
            c.full_s,
            c.plan["probe"]["why"]
        );
        // Never more model than the graph: the user's rank-16 basis or a simplification of it.
        let view = &c.planned["nodes"]["view"];
        assert_ne!(
            view["inputs"]["btf"], "capture.btf",
            "the raw BTF in place of the basis"
        );
        if let Some(pca) = c.planned["nodes"].get("plan_pca") {
            assert!(pca["params"]["rank"].as_u64().unwrap() <= 16, "{pca}");
        }
        // (A level of detail is never finer than the graph's, the BTF's own level 0: there is
        // nothing to check there.)
        assert!(
            view["inputs"].get("mdf").is_some() || view["params"]["use_mdf"] == false,
            "{view}"
        );
        // What the probes measured is recorded, and the plan kept was within budget on them.
        let probe = &c.plan["probe"];
        assert!(probe["plan_seconds"].as_f64().is_some(), "{probe}");
        assert!(
            probe["resolution"] == serde_json::json!([80, 60]),
            "{probe}"
        );
        let kept = c.plan["probed_error"].as_f64().unwrap();
        assert!(kept <= BUDGET, "kept a plan probed at {kept}: {probe}");
        // The probe stands for the view: its FLIP is near the full frame's (the guide's larger
        // scene measured within 0.001; this smaller one 0.006 at the first eye; held at 0.015).
        eprintln!("eye {}: probe {kept:.4}, full frame {:.4}", c.eye, c.flip);
        assert!(
            (c.flip - kept).abs() <= 0.015,
            "eye {}: the full frame's FLIP {:.4} against the probe's {kept:.4}",
            c.eye,
            c.flip
        );
        for r in probe["rungs"].as_array().unwrap() {
            if r["fits"] == true {
                assert!(r["probed_flip"].as_f64().unwrap() <= BUDGET, "{r}");
            }
        }
    }
    let flips: Vec<f64> = ours.iter().map(|c| c.flip).collect();
    let ratios: Vec<f64> = ours.iter().map(|c| c.view_s / c.full_s).collect();
    let verdict = acceptance(&flips, &ratios);
    println!("the proved planner against the issue's acceptance: {verdict:?}");
    // The budget's part holds; the time part is reported (it depends on the machine's clock).
    if let Err(e) = &verdict {
        assert!(e.contains("far half"), "{e}");
    }

    // A planner that always takes the cheapest model (here: planned for a budget of 1, its FLIP
    // measured on the same frames) fails the budget's part, which ours is held to. (One that
    // never simplifies would fail only the time part, which the machine's clock excuses here:
    // it is not a check of this test.)
    let cheapest = cases(&s, "cheapest", 1.0, &["--probe-budget", "0"]);
    let flips: Vec<f64> = cheapest.iter().map(|c| c.flip).collect();
    let ratios: Vec<f64> = cheapest.iter().map(|c| c.view_s / c.full_s).collect();
    let verdict = acceptance(&flips, &ratios);
    println!("the cheapest model: FLIP {flips:?}: {verdict:?}");
    assert!(verdict.is_err_and(|e| e.contains("budget")));
}
