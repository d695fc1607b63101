//! The planner's proof (`graphs/plan_verify.json`), charted: runs the verification sweep
//! (`common/plan_sweep.rs`) with the joint and the equal budget split at FLIP's default 67
//! pixels per degree, and with the joint split for viewers at 30 and 120, and writes
//! `sweep.csv` (joint), `sweep_equal.csv`, `sweep_ppd30.csv`, `sweep_ppd120.csv` and the charts
//! `flip_vs_distance`,
//! `speedup_vs_distance` and `calibration` (SVG and PNG) to the output folder, and prints the
//! misses.
//!
//! `cargo bench --bench plan_verify -- [--out DIR] [--width W]`

#[path = "common/args.rs"]
mod args;
#[allow(dead_code)]
#[path = "../src/chart.rs"]
mod chart;
#[path = "common/cli.rs"]
mod cli;
#[path = "common/plan_sweep.rs"]
mod plan_sweep;

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
