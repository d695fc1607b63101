//! The planner as the arbiter over the held-out scenes of both families (issue 57): each scene
//! planned with `mesoflow plan --against truth --budget rmse=B`, the planned graph run on the full
//! frame against the family's converged truth, beside the graph as given, each model variant and
//! brute force at the samples that meet the budget (`mesoflow_testkit::plan_families`, which
//! states the bounds). Prints a row a scene and budget, then per family and budget the share
//! within budget, the worst miss and every scene that breaks a bound; writes
//! `docs/images/plan_families.json` and the charts `plan_families_error.svg` (planned error
//! against budget) and `plan_families_time.svg` (planned time against the graph's and brute
//! force's).
//!
//! `cargo bench --bench plan_families -- [--family translucent|mesostructure|all] [--count 24]
//! [--first SEED] [--measure rmse|flip] [--budgets 0.1,0.2] [--width W] [--samples S]
//! [--out DIR] [--set ID.P=V]…` (a FLIP run's files and charts end in `_flip`)
//! (seeds from `scenes::HELD_OUT` by default: no one tunes on them; each family's template
//! resolution and truth samples unless given).

use mesoflow::chart::{self, Chart, Series};
use mesoflow_testkit::args::arg;
use mesoflow_testkit::plan_families::{self, Measure, Options, SceneRow, MISS_SLACK};
use mesoflow_testkit::scenes::{self, Kind};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn f3(x: Option<f64>) -> String {
    x.map_or("absent".into(), |v| format!("{v:.3}"))
}

fn f2(x: Option<f64>) -> String {
    x.map_or("absent".into(), |v| format!("{v:.2}"))
}

fn row_json(r: &SceneRow) -> Value {
    let rendered = |x: &plan_families::Rendered| json!({ "name": x.name, "family": x.family, "error": x.error, "seconds": x.seconds });
    json!({
        "family": r.family,
        "seed": r.seed,
        "scene": r.name,
        "given": rendered(&r.given),
        "models": r.models.iter().map(rendered).collect::<Vec<_>>(),
        "budgets": r.budgets.iter().map(|b| json!({
            "budget": b.budget,
            "planned": rendered(&b.planned),
            "brute": rendered(&b.brute),
            "brute_samples": b.brute_samples,
            "plan_seconds": b.plan_seconds,
            "plan_ratio": r.plan_ratio(b),
            "fastest_fit": r.fastest_fit(b).map(rendered),
            "failures": r.failures(b),
        })).collect::<Vec<_>>(),
    })
}

fn summary(rows: &[SceneRow], budgets: &[f64], measure: Measure) {
    for family in ["translucent", "mesostructure"] {
        let of: Vec<&SceneRow> = rows.iter().filter(|r| r.family == family).collect();
        if of.is_empty() {
            continue;
        }
        for &b in budgets {
            let at: Vec<_> = of
                .iter()
                .filter_map(|r| r.budgets.iter().find(|x| x.budget == b).map(|x| (r, x)))
                .collect();
            let within = at.iter().filter(|(_, x)| x.planned.fits(b)).count();
            let worst = at
                .iter()
                .filter_map(|(r, x)| Some((x.planned.error?, r.seed)))
                .max_by(|a, b| a.0.total_cmp(&b.0));
            let brute = at
                .iter()
                .filter(|(_, x)| x.planned.family == "brute force")
                .count();
            println!(
                "{family}, budget {} {b}: within on {within} of {} ({:.0} %; ≥ 95 % asked), worst {} (seed {}; at most {MISS_SLACK}× the budget), brute force planned on {brute}",
                measure.name(),
                at.len(),
                100.0 * within as f64 / at.len().max(1) as f64,
                f3(worst.map(|w| w.0)),
                worst.map_or("none".into(), |w| w.1.to_string()),
            );
            for (r, x) in &at {
                for f in r.failures(x) {
                    println!("  seed {}: {f}", r.seed);
                }
            }
        }
    }
}

/// A chart's point from one scene at one budget, if it has one.
type Pick = dyn Fn(&SceneRow, &plan_families::Budgeted) -> Option<(f64, f64)>;

fn charts(rows: &[SceneRow], out: &Path, measure: Measure) {
    let suffix = match measure {
        Measure::Rmse => "",
        Measure::Flip => "_flip",
    };
    let mut made = Vec::new();
    for family in ["translucent", "mesostructure"] {
        let of: Vec<&SceneRow> = rows.iter().filter(|r| r.family == family).collect();
        if of.is_empty() {
            continue;
        }
        let points = |f: &Pick| {
            of.iter()
                .flat_map(|r| r.budgets.iter().filter_map(move |b| f(r, b)))
                .collect::<Vec<_>>()
        };
        let budgets: Vec<f64> = of
            .first()
            .map(|r| r.budgets.iter().map(|b| b.budget).collect())
            .unwrap_or_default();
        made.push((
            format!("plan_families_error_{family}{suffix}"),
            Chart {
                title: format!("{family}: the plan's error against the truth, per budget"),
                x_label: match measure {
                    Measure::Rmse => "budget, relative RMSE",
                    Measure::Flip => "budget, mean FLIP",
                },
                y_label: match measure {
                    Measure::Rmse => "planned render's relative RMSE (full frame)",
                    Measure::Flip => "planned render's mean FLIP (full frame)",
                },
                series: vec![
                    Series {
                        name: "planned (one point a scene)".into(),
                        points: points(&|_, b| Some((b.budget, b.planned.error?))),
                        scatter: true,
                    },
                    Series {
                        name: "the budget".into(),
                        points: budgets.iter().map(|&b| (b, b)).collect(),
                        scatter: false,
                    },
                    Series {
                        name: "the graph as given".into(),
                        points: points(&|r, b| Some((b.budget, r.given.error?))),
                        scatter: true,
                    },
                ],
                x_names: None,
            },
        ));
        made.push((
            format!("plan_families_time_{family}{suffix}"),
            Chart {
                title: format!("{family}: planned time against the graph's and brute force's"),
                x_label: "the graph as given, s",
                y_label: "s on the full frame (CPU, 2 cores)",
                series: vec![
                    Series {
                        name: "planned".into(),
                        points: points(&|r, b| Some((r.given.seconds?, b.planned.seconds?))),
                        scatter: true,
                    },
                    Series {
                        name: "brute force at the budget".into(),
                        points: points(&|r, b| Some((r.given.seconds?, b.brute.seconds?))),
                        scatter: true,
                    },
                    Series {
                        name: "the graph as given".into(),
                        points: {
                            let mut p: Vec<(f64, f64)> = of
                                .iter()
                                .filter_map(|r| r.given.seconds)
                                .map(|s| (s, s))
                                .collect();
                            p.sort_by(|a, b| a.0.total_cmp(&b.0));
                            p
                        },
                        scatter: false,
                    },
                ],
                x_names: None,
            },
        ));
    }
    for (name, c) in made {
        match chart::write(&out.join(&name), &c) {
            Ok(()) => eprintln!(
                "plan_families: {}",
                out.join(format!("{name}.svg")).display()
            ),
            Err(e) => eprintln!("plan_families: {name}: {e}"),
        }
    }
}

fn main() {
    let family = arg("--family", "all".to_string());
    let kinds: Vec<Kind> = match family.as_str() {
        "all" => vec![Kind::Translucent, Kind::Mesostructure],
        "translucent" => vec![Kind::Translucent],
        "mesostructure" => vec![Kind::Mesostructure],
        f => panic!("--family {f}: translucent, mesostructure or all"),
    };
    let first: u64 = arg("--first", scenes::HELD_OUT);
    let count: u64 = arg("--count", 24);
    let measure = Measure::parse(&arg("--measure", "rmse".to_string()))
        .unwrap_or_else(|| panic!("--measure: rmse or flip"));
    let budgets: Vec<f64> = arg("--budgets", "0.1,0.2".to_string())
        .split(',')
        .filter_map(|b| b.trim().parse().ok())
        .collect();
    let out: PathBuf = arg("--out", PathBuf::from("target/plan_families"));
    let argv: Vec<String> = std::env::args().collect();
    let sets: Vec<String> = argv
        .windows(2)
        .filter(|w| w[0] == "--set")
        .map(|w| w[1].clone())
        .collect();
    let mut rows = Vec::new();
    println!("| family | seed | budget | planned | its error | its s | given error | given s | fastest listed within | brute spp | brute s | plan s | plan / longer render |");
    println!("|---|---:|---:|---|---:|---:|---:|---:|---|---:|---:|---:|---:|");
    for kind in kinds {
        let width: u32 = arg("--width", kind.resolution()[0]);
        let o = Options {
            resolution: [width, width * kind.resolution()[1] / kind.resolution()[0]],
            samples: arg("--samples", kind.samples()),
            budgets: budgets.clone(),
            measure,
            out: out.clone(),
            sets: sets.clone(),
        };
        for seed in first..first + count {
            let r = plan_families::scene(kind, seed, &o);
            for b in &r.budgets {
                let fastest = r.fastest_fit(b);
                println!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {} |",
                    r.family,
                    r.seed,
                    b.budget,
                    b.planned.name,
                    f3(b.planned.error),
                    f2(b.planned.seconds),
                    f3(r.given.error),
                    f2(r.given.seconds),
                    fastest.map_or("none".into(), |f| format!(
                        "{} ({} s)",
                        f.name,
                        f2(f.seconds)
                    )),
                    b.brute_samples,
                    f2(b.brute.seconds),
                    b.plan_seconds,
                    f2(r.plan_ratio(b)),
                );
            }
            rows.push(r);
            let doc = json!({
                "command": format!("cargo bench --bench plan_families -- {}", argv[1..].iter().filter(|a| *a != "--bench").cloned().collect::<Vec<_>>().join(" ")),
                "rows": rows.iter().map(row_json).collect::<Vec<_>>(),
            });
            // Written after every scene: a run stopped part-way keeps what it measured.
            std::fs::create_dir_all(&out).expect("the output folder");
            std::fs::write(
                out.join("plan_families.json"),
                serde_json::to_string_pretty(&doc).expect("json"),
            )
            .expect("write the rows");
        }
    }
    println!();
    summary(&rows, &budgets, measure);
    let images = mesoflow_testkit::cli::repo().join("docs/images");
    // One family's run is that family's rows: named after it, so the two runs keep both.
    let suffix = match measure {
        Measure::Rmse => "",
        Measure::Flip => "_flip",
    };
    let name = match family.as_str() {
        "all" => format!("plan_families{suffix}.json"),
        f => format!("plan_families_{f}{suffix}.json"),
    };
    let _ = std::fs::copy(out.join("plan_families.json"), images.join(name));
    charts(&rows, &images, measure);
}
