//! The planner's proof (`graphs/plan_verify.json`), charted: runs the verification sweep
//! (`mesoflow_testkit::plan_sweep`) with the joint and the equal budget split at FLIP's default 67
//! pixels per degree, and with the joint split for viewers at 30 and 120, and writes
//! `sweep.csv` (joint), `sweep_equal.csv`, `sweep_ppd30.csv`, `sweep_ppd120.csv` and the charts
//! `popping.csv` (where a decision changes between neighbouring distances, the FLIP between
//! the two plans' renders from the nearer camera), and the charts `flip_vs_distance`,
//! `speedup_vs_distance` and `calibration` (SVG and PNG) to the output folder, and prints the
//! misses. Then the same sweep on `graphs/plan_qh.json` (a quasi-homogeneous torus with a
//! synthesized entrance function, which the synthesis decision acts on): `sweep_qh.csv`.
//!
//! `cargo bench --bench plan_verify -- [--out DIR] [--width W]`

use mesoflow::chart;
use mesoflow_testkit::{args, cli, plan_sweep};

use plan_sweep::{Row, BUDGETS, DISTANCES, OBJECTS};
use std::fmt::Write as _;
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(args::arg("--out", "out/plan_verify".to_string()));
    let width: u32 = args::arg("--width", 240);
    // The equal split first, for comparison; the joint split (the default) is what is charted.
    let equal = plan_sweep::sweep(&out.join("equal"), width, "equal", None);
    // Viewers at 30 and 120 pixels per degree, planned and measured at their own ppd.
    let viewers: Vec<(u32, Vec<Row>)> = [30u32, 120]
        .into_iter()
        .map(|p| {
            let dir = out.join(format!("ppd{p}"));
            (p, plan_sweep::sweep(&dir, width, "joint", Some(p as f64)))
        })
        .collect();
    let rows = plan_sweep::sweep(&out, width, "joint", None);
    let pops = popping(&out, &rows);
    let far_median = |rows: &[Row]| {
        let mut v: Vec<f64> = rows
            .iter()
            .filter(|r| r.distance >= DISTANCES[DISTANCES.len() / 2 + 1])
            .map(|r| r.full_s / r.view_s)
            .collect();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    let within = |rows: &[Row]| rows.iter().filter(|r| r.flip <= r.budget).count();
    println!(
        "split   within budget   median render time saved, far half\nequal   {:>3} of {}      {:.2}x\njoint   {:>3} of {}      {:.2}x",
        within(&equal),
        equal.len(),
        far_median(&equal),
        within(&rows),
        rows.len(),
        far_median(&rows)
    );
    for (p, v) in &viewers {
        println!(
            "joint, {p} ppd  {:>3} of {}      {:.2}x",
            within(v),
            v.len(),
            far_median(v)
        );
    }
    let table = |rows: &[Row]| {
        let mut csv = String::from("distance,budget,object,flip_mean,predicted,within_budget,full_seconds,view_seconds,speedup,decisions\n");
        for r in rows {
            let _ = writeln!(
                csv,
                "{},{},{},{:.6},{},{},{:.4},{:.4},{:.2},\"{}\"",
                r.distance,
                r.budget,
                r.object,
                r.flip,
                r.predicted.map_or(String::new(), |p| format!("{p:.6}")),
                r.flip <= r.budget,
                r.full_s,
                r.view_s,
                r.full_s / r.view_s,
                r.decisions.replace('"', "'")
            );
        }
        csv
    };
    std::fs::write(out.join("sweep_equal.csv"), table(&equal)).unwrap();
    for (p, v) in &viewers {
        std::fs::write(out.join(format!("sweep_ppd{p}.csv")), table(v)).unwrap();
    }
    let qh = plan_sweep::sweep_qh(&out.join("qh"), width);
    std::fs::write(out.join("sweep_qh.csv"), table(&qh)).unwrap();
    println!(
        "qh (synthesized texture)  {:>3} of {}      {:.2}x",
        within(&qh),
        qh.len(),
        far_median(&qh)
    );
    for r in qh.iter().filter(|r| r.flip > r.budget) {
        println!(
            "qh miss at distance {} budget {}: FLIP {:.4} ({:.2}× the budget)",
            r.distance,
            r.budget,
            r.flip,
            r.flip / r.budget
        );
    }
    let csv = table(&rows);
    std::fs::write(out.join("sweep.csv"), &csv).unwrap();
    print!("{csv}");
    let within = rows.iter().filter(|r| r.flip <= r.budget).count();
    println!("within budget: {within} of {}", rows.len());
    for r in rows.iter().filter(|r| r.flip > r.budget) {
        println!(
            "miss: {} at distance {} budget {}: FLIP {:.4} ({:.2}× the budget)",
            r.object,
            r.distance,
            r.budget,
            r.flip,
            r.flip / r.budget
        );
    }
    let mut pop_csv =
        String::from("object,budget,nearer_distance,flip_between_plans,within_budget\n");
    for (object, b, d, f) in &pops {
        let _ = writeln!(pop_csv, "{object},{b},{d},{f:.6},{}", f <= b);
    }
    std::fs::write(out.join("popping.csv"), &pop_csv).unwrap();
    let calm = pops.iter().filter(|p| p.3 <= p.1).count();
    println!(
        "popping: {calm} of {} switches within the budget; largest {:.2}× it",
        pops.len(),
        pops.iter().map(|p| p.3 / p.1).fold(0.0, f64::max)
    );
    let series = |y: &dyn Fn(&Row) -> f64, with_budgets: bool| {
        let mut v = Vec::new();
        for (object, _, _) in OBJECTS {
            for &b in &BUDGETS {
                v.push(chart::Series {
                    name: format!("{object}, budget {b}"),
                    points: rows
                        .iter()
                        .filter(|r| r.object == object && r.budget == b)
                        .map(|r| (r.distance, y(r)))
                        .collect(),
                    scatter: false,
                });
            }
        }
        if with_budgets {
            for &b in &BUDGETS {
                v.push(chart::Series {
                    name: format!("budget {b}"),
                    points: vec![(DISTANCES[0], b), (DISTANCES[DISTANCES.len() - 1], b)],
                    scatter: false,
                });
            }
        }
        v
    };
    let charts = [
        (
            "flip_vs_distance",
            "measured FLIP of the plan against budget",
            "mean FLIP, planned vs full (object pixels)",
            series(&|r: &Row| r.flip, true),
        ),
        (
            "speedup_vs_distance",
            "render time saved by the plan",
            "render seconds, full / planned",
            series(&|r: &Row| r.full_s / r.view_s, false),
        ),
    ];
    let mut calibration: Vec<chart::Series> = OBJECTS
        .iter()
        .map(|(object, _, _)| chart::Series {
            name: format!("{object}: measured against predicted"),
            points: rows
                .iter()
                .filter(|r| r.object == *object)
                .filter_map(|r| Some((r.predicted?, r.flip)))
                .collect(),
            scatter: true,
        })
        .collect();
    let top = rows
        .iter()
        .flat_map(|r| [r.flip, r.predicted.unwrap_or(0.0)])
        .fold(0.0, f64::max);
    calibration.push(chart::Series {
        name: "measured = predicted".into(),
        points: vec![(0.0, 0.0), (top, top)],
        scatter: false,
    });
    let charts = charts.into_iter().chain([(
        "calibration",
        "the plan's predicted FLIP against the measured",
        "measured FLIP",
        calibration,
    )]);
    for (name, title, y_label, series) in charts {
        let c = chart::Chart {
            title: title.into(),
            x_label: if name == "calibration" {
                "predicted FLIP"
            } else {
                "camera distance (world units)"
            },
            y_label,
            series,
            x_names: None,
        };
        if let Err(e) = chart::write(&out.join(name), &c) {
            eprintln!("chart {name}: {e}");
        }
    }
}

/// Popping: where the plan's decisions change between two neighbouring distances, the FLIP
/// between the two plans' renders from the nearer camera (what a viewer moving through the
/// switch sees jump), as (object, budget, nearer distance, FLIP). Runs each farther plan's
/// view from the nearer camera beside the nearer plan, in the sweep's cache.
fn popping(out: &std::path::Path, rows: &[Row]) -> Vec<(&'static str, f64, f64, f64)> {
    use serde_json::{json, Value};
    let mut pops = Vec::new();
    for (object, _, view) in OBJECTS {
        for &b in &BUDGETS {
            for w in DISTANCES.windows(2) {
                let (near, far) = (w[0], w[1]);
                let decisions = |d: f64| {
                    rows.iter()
                        .find(|r| r.object == object && r.budget == b && r.distance == d)
                        .map(|r| r.decisions.clone())
                };
                if decisions(near) == decisions(far) {
                    continue;
                }
                let read = |d: f64| -> Value {
                    let f = out.join(format!("d{d}_b{b}")).join("planned.json");
                    serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap()
                };
                let (mut g, next) = (read(near), read(far));
                // The farther plan's view and what it needs, renamed, from the nearer camera.
                let mut stack = vec![view.to_string()];
                let mut seen = std::collections::BTreeSet::new();
                while let Some(id) = stack.pop() {
                    if !seen.insert(id.clone()) {
                        continue;
                    }
                    let mut n = next["nodes"][&id].clone();
                    if let Some(inputs) = n.get_mut("inputs").and_then(Value::as_object_mut) {
                        for v in inputs.values_mut() {
                            let from = v.as_str().unwrap_or("").to_string();
                            if let Some((up, port)) = from.split_once('.') {
                                stack.push(up.to_string());
                                *v = json!(format!("next_{up}.{port}"));
                            }
                        }
                    }
                    g["nodes"][format!("next_{id}")] = n;
                }
                g["nodes"][format!("next_{view}")]["params"]["camera"]["eye"] =
                    serde_json::from_str(&plan_sweep::eye(near)).unwrap();
                g["nodes"]["pop_flip"] = json!({ "kind": "image.flip",
                    "inputs": { "reference": format!("{view}.image"), "test": format!("next_{view}.image") },
                    "params": { "object_only": true } });
                let dir = out.join(format!("pop_{object}_d{near}_b{b}"));
                std::fs::create_dir_all(&dir).unwrap();
                let graph = dir.join("graph.json");
                std::fs::write(&graph, serde_json::to_string_pretty(&g).unwrap()).unwrap();
                let run = dir.join("out");
                cli::mesoflow(&[
                    "run",
                    graph.to_str().unwrap(),
                    "--output",
                    "pop_flip.mean",
                    "--quiet",
                    "--out-dir",
                    run.to_str().unwrap(),
                    "--cache-dir",
                    out.join("cache").to_str().unwrap(),
                ]);
                let report: Value = serde_json::from_str(
                    &std::fs::read_to_string(run.join("report.json")).unwrap(),
                )
                .unwrap();
                let flip = cli::node(&report, "pop_flip")["metrics"]["mean"]
                    .as_f64()
                    .unwrap_or(f64::NAN);
                pops.push((object, b, near, flip));
            }
        }
    }
    pops
}
