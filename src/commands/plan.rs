//! `mesoflow plan GRAPH --render ID --budget flip=B`: the command line of the planner library
//! (`mesoflow_plan`): parses the arguments, has the library measure the view (its probe, run
//! through the engine and its cache) and decide each stage's model, and writes the planned graph
//! (the same graph with the choices as ordinary parameters and connections) and its plan
//! beside it (`<graph>.plan.json`, [`plan_file`]).

use crate::args::PlanArgs;
use crate::exit::invalid;
use crate::load;
use crate::session::{engine, graph_dir, policy};
use mesoflow_graph::NodeDecl;
use mesoflow_nodes::image::flip;
use mesoflow_nodes::support::raytrace::camera::CameraParams;
use mesoflow_plan as plan;
use mesoflow_runtime::{RunOptions, RunPolicy};
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};

/// `flip=B` → B.
fn parse_budget(text: &str) -> anyhow::Result<f64> {
    let (metric, value) = text
        .split_once('=')
        .ok_or_else(|| invalid(format!("--budget {text}: expected flip=B")))?;
    if metric.trim() != "flip" {
        return Err(invalid(format!(
            "--budget {text}: against the graph's own model the budget is `flip` (mean FLIP over the object's pixels); `rmse` goes with --against truth"
        )));
    }
    let b: f64 = value
        .trim()
        .parse()
        .map_err(|_| invalid(format!("--budget {text}: `{value}` is not a number")))?;
    if !(b.is_finite() && b >= 0.0) {
        return Err(invalid(format!("--budget {text}: must be a number ≥ 0")));
    }
    Ok(b)
}

/// The viewer's pixels per degree: `--ppd`, or `--viewer DIST_M,WIDTH_M` with the render's
/// width in pixels, or FLIP's default.
fn viewer_ppd(args: &PlanArgs, render: &NodeDecl) -> anyhow::Result<f64> {
    if let Some(p) = args.ppd {
        if !(p.is_finite() && p >= 0.5) {
            return Err(invalid(format!("--ppd {p}: must be a number ≥ 0.5")));
        }
        return Ok(p);
    }
    let Some(text) = &args.viewer else {
        return Ok(flip::DEFAULT_PPD);
    };
    let parts: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| invalid(format!("--viewer {text}: expected DIST_M,WIDTH_M")))?;
    let [distance_m, width_m] = parts[..] else {
        return Err(invalid(format!("--viewer {text}: expected DIST_M,WIDTH_M")));
    };
    if !([distance_m, width_m]
        .iter()
        .all(|v| v.is_finite() && *v > 0.0))
    {
        return Err(invalid(format!(
            "--viewer {text}: distance and width must be positive metres"
        )));
    }
    let pixels = render.params["camera"]["resolution"][0]
        .as_u64()
        .map_or(CameraParams::default().resolution[0] as usize, |w| {
            w as usize
        });
    Ok(flip::Viewer {
        distance_m,
        width_m,
    }
    .ppd(pixels))
}

/// `rmse=B` or `flip=B` → whether FLIP, and B, for `--against truth`.
fn parse_truth_budget(text: &str) -> anyhow::Result<(bool, f64)> {
    let (flip, value) = text
        .split_once('=')
        .and_then(|(m, v)| match m.trim() {
            "rmse" => Some((false, v)),
            "flip" => Some((true, v)),
            _ => None,
        })
        .ok_or_else(|| {
            invalid(format!(
                "--budget {text}: --against truth takes rmse=B (the relative RMSE against the truth) or flip=B (the mean FLIP against it)"
            ))
        })?;
    let b: f64 = value
        .trim()
        .parse()
        .map_err(|_| invalid(format!("--budget {text}: `{value}` is not a number")))?;
    if !(b.is_finite() && b > 0.0) {
        return Err(invalid(format!("--budget {text}: must be a number > 0")));
    }
    Ok((flip, b))
}

/// `--probe-share`, or `default`, checked.
fn share(args: &PlanArgs, default: f64) -> anyhow::Result<f64> {
    let s = args.probe_share.unwrap_or(default);
    if !(s > 0.0 && s <= 1.0) {
        return Err(invalid(format!(
            "--probe-share {s}: a fraction of the frame in (0, 1]"
        )));
    }
    Ok(s)
}

pub fn plan(args: &PlanArgs) -> anyhow::Result<i32> {
    if args.against.is_some() {
        return against_truth(args);
    }
    own_model(args, None)
}

/// The plan against the graph's own model (a FLIP budget); `fallback` is why, where `--against
/// truth` was asked and the graph cannot make a truth. The plan says which judge it used and why.
fn own_model(args: &PlanArgs, fallback: Option<String>) -> anyhow::Result<i32> {
    let budget = parse_budget(&args.budget)?;
    let engine = engine(&args.cache, &args.graph.path)?;
    let mut file = load::read(&args.graph.path)?;
    load::apply_sets(&mut file, &args.graph.set)?;
    let file = load::flat(&args.graph.path, &file)?;
    load::checked(&args.graph.path, &file, engine.registry())?;
    plan::render_kind(&file, &args.render)
        .map_err(|e| invalid(format!("--render {}: {e}", args.render)))?;
    let decl = file.node(&args.render).cloned().unwrap_or(NodeDecl {
        kind: String::new(),
        params: Map::new(),
        inputs: Default::default(),
    });
    let ppd = viewer_ppd(args, &decl)?;

    // Measure the view (cached like any run), then decide.
    let opts = run_options(args);
    if !args.quiet {
        eprintln!("plan: measuring the view of `{}`", args.render);
    }
    let split = match args.split {
        crate::args::SplitArg::Joint => plan::Split::Joint,
        crate::args::SplitArg::Equal => plan::Split::Equal,
    };
    let name = args.graph.path.display().to_string();
    if !(args.probe_budget.is_finite() && args.probe_budget >= 0.0) {
        return Err(invalid(format!(
            "--probe-budget {}: a number of renders ≥ 0",
            args.probe_budget
        )));
    }
    let probe_share = share(args, plan::PROBE_SHARE)?;
    let probe = (args.probe_budget > 0.0).then_some(plan::ProbeOptions {
        share: probe_share,
        budget: args.probe_budget,
    });
    let planned = plan::plan_view(
        &engine,
        &name,
        &file,
        &args.render,
        plan::Budget { flip: budget, ppd },
        split,
        opts,
        probe,
    )
    .map_err(|e| match e {
        plan::PlanError::Probe(_) => anyhow::anyhow!("{e}"),
        plan::PlanError::MissingMetric(_) | plan::PlanError::Invalid(_) => invalid(e.to_string()),
        _ => anyhow::anyhow!("--render {}: {e}", args.render),
    })?;

    let mut planned_file = planned.plan.file.clone();
    planned_file.description = Some(format!(
        "{} — planned for `{}` at a FLIP budget of {budget}, {ppd:.1} pixels per degree (see {})",
        file.description.clone().unwrap_or_default(),
        args.render,
        plan_name(args)
    ));
    let mut doc = planned.to_json();
    doc["judge"] = json!("model");
    doc["judge_why"] = json!(match &fallback {
        Some(why) => format!(
            "--against truth was asked, but {why}: each stage judged by its FLIP against the graph's own model instead"
        ),
        None => "each stage judged by its FLIP against the graph's own model (--against truth not asked)".into(),
    });
    let (out_path, plan_path) = write_plan(args, &planned_file, doc)?;
    if !args.quiet {
        if let Some(why) = &fallback {
            println!("no truth: {why}; judged against the graph's own model instead");
        }
        for d in &planned.plan.decisions {
            println!("{:4} {} — {}", d.stage, d.choice, d.reason);
        }
        if let Some(t) = planned.predicted_error() {
            println!("predicted FLIP {t:.4} (budget {budget})");
        }
        if let Some(p) = &planned.proof {
            if args.verbose {
                for (i, r) in p.rungs.iter().enumerate() {
                    println!(
                        "probe {i}: {}: FLIP {} frame {} s{}",
                        r.candidate,
                        r.flip.map_or("absent".into(), |f| format!("{f:.4}")),
                        r.frame_s.map_or("absent".into(), |t| format!("{t:.4}")),
                        if p.chosen == Some(i) { " (kept)" } else { "" }
                    );
                }
            }
            println!(
                "tried {}: {} ({:.1} s planning)",
                count(p.rungs.len(), "simplification", "simplifications"),
                p.why,
                p.plan_s
            );
        }
        println!("wrote {} and {}", out_path.display(), plan_path.display());
    }
    Ok(0)
}

/// The probes' run options: the command's device, cache and Ctrl-C.
fn run_options(args: &PlanArgs) -> RunOptions {
    RunOptions::new(
        &args.graph.path.display().to_string(),
        graph_dir(&args.graph.path),
        std::env::temp_dir(),
        RunPolicy {
            verify_cache: false,
            ..policy(args.device, &args.cache)
        },
    )
}

/// Where the planned graph goes: `-o`, or `<graph>.planned.json` beside the graph.
fn planned_path(args: &PlanArgs) -> PathBuf {
    args.output.clone().unwrap_or_else(|| {
        let stem = args
            .graph
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "graph".into());
        graph_dir(&args.graph.path).join(format!("{stem}.planned.json"))
    })
}

/// The plan's file name, for the planned graph's description.
fn plan_name(args: &PlanArgs) -> String {
    plan_file(&planned_path(args))
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Where the plan of a planned graph at `planned` goes: beside it, named after it
/// (`torus.planned.json` → `torus.plan.json`, `-o out/near.json` → `out/near.plan.json`), so two
/// plans in one folder do not collide. Python's `Plan.save` follows the same rule.
pub fn plan_file(planned: &Path) -> PathBuf {
    let name = planned
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "graph.json".into());
    let stem = name.strip_suffix(".json").unwrap_or(&name);
    let stem = stem.strip_suffix(".planned").unwrap_or(stem);
    planned.with_file_name(format!("{stem}.plan.json"))
}

/// Writes the planned graph (`-o`, or `<graph>.planned.json` beside the graph) and its plan
/// beside it ([`plan_file`]: the graph's and the planned graph's paths, then `doc`'s fields);
/// returns both paths.
fn write_plan(
    args: &PlanArgs,
    planned: &mesoflow_graph::GraphFile,
    doc: Value,
) -> anyhow::Result<(PathBuf, PathBuf)> {
    let out_path = planned_path(args);
    write(&out_path, &(planned.to_json() + "\n"))?;
    let plan_path = plan_file(&out_path);
    let mut all = json!({
        "graph": args.graph.path.display().to_string(),
        "planned": out_path.display().to_string(),
    });
    if let (Some(o), Value::Object(rest)) = (all.as_object_mut(), doc) {
        o.extend(rest);
    }
    write(
        &plan_path,
        &(serde_json::to_string_pretty(&all).unwrap_or_default() + "\n"),
    )?;
    Ok((out_path, plan_path))
}

/// `mesoflow plan --against truth`: every candidate measured against the truth the graph makes
/// (`mesoflow_plan::arbiter`).
fn against_truth(args: &PlanArgs) -> anyhow::Result<i32> {
    let (flip, budget) = parse_truth_budget(&args.budget)?;
    let probe_share = share(args, plan::TRUTH_SHARE)?;
    let engine = engine(&args.cache, &args.graph.path)?;
    let mut file = load::read(&args.graph.path)?;
    load::apply_sets(&mut file, &args.graph.set)?;
    let file = load::flat(&args.graph.path, &file)?;
    load::checked(&args.graph.path, &file, engine.registry())?;
    let opts = run_options(args);
    let measure = match (flip, file.node(&args.render)) {
        (true, Some(decl)) => plan::Measure::Flip {
            ppd: viewer_ppd(args, decl)?,
        },
        (true, None) => plan::Measure::Flip {
            ppd: flip::DEFAULT_PPD,
        },
        (false, _) => plan::Measure::RelativeRmse,
    };
    let said = format!("{} {budget}", measure.name());
    if !args.quiet {
        eprintln!(
            "plan: `{}` against the truth at {said}: a pilot and the truth probe, then each candidate",
            args.render
        );
    }
    let name = args.graph.path.display().to_string();
    let a = plan::arbitrate(
        &engine,
        &name,
        &file,
        &args.render,
        &opts,
        plan::TruthOptions {
            budget,
            measure,
            share: probe_share,
        },
    );
    let a = match a {
        Ok(a) => a,
        Err(plan::PlanError::NoTruth(why)) if flip => {
            drop(engine);
            return own_model(args, Some(why));
        }
        Err(plan::PlanError::NoTruth(why)) => {
            return Err(invalid(format!(
                "--render {}: {why}; against the graph's own model the budget is flip=B (with --against truth, a FLIP budget falls back to it)",
                args.render
            )))
        }
        Err(e @ plan::PlanError::Probe(_)) => return Err(anyhow::anyhow!("{e}")),
        Err(e) => return Err(invalid(format!("--render {}: {e}", args.render))),
    };
    let mut planned_file = a.planned.clone();
    planned_file.description = Some(format!(
        "{} — planned for `{}` against the truth at {said} (see {})",
        file.description.clone().unwrap_or_default(),
        args.render,
        plan_name(args)
    ));
    let (out_path, plan_path) = write_plan(args, &planned_file, a.to_json())?;
    if !args.quiet {
        println!(
            "truth probe {}×{}: {} samples a pixel, noise {}",
            a.resolution[0],
            a.resolution[1],
            a.truth_samples,
            a.truth_noise.map_or("absent".into(), |n| format!("{n:.4}"))
        );
        if let Some(n) = &a.probe_note {
            println!("    {n}");
        }
        for (i, c) in a.candidates.iter().enumerate() {
            // By default the planned candidate alone, with its warnings; every one with
            // --verbose.
            if !args.verbose && a.chosen != Some(i) {
                continue;
            }
            if let (None, Some(n)) = (c.probe_s, &c.note) {
                println!("    {}: {n}", c.name);
                continue;
            }
            println!(
                "{:>3} {}: {} {}, {} s on the probe, {} s on the view (estimated){}{}",
                if a.chosen == Some(i) { "->" } else { "" },
                c.name,
                measure.name(),
                c.error.map_or("absent".into(), |e| format!("{e:.3}")),
                c.probe_s.map_or("absent".into(), |t| format!("{t:.2}")),
                c.full_s.map_or("absent".into(), |t| format!("{t:.2}")),
                if c.fits { ", within budget" } else { "" },
                c.note.as_ref().map_or(String::new(), |n| format!(" ({n})"))
            );
            for w in &c.warnings {
                println!("      warning: {w}");
            }
        }
        let phases: Vec<String> = a
            .phases
            .iter()
            .filter(|(_, t)| *t >= 0.05)
            .map(|(k, t)| format!("{k} {t:.1}"))
            .collect();
        let within = a.candidates.iter().filter(|c| c.fits).count();
        let tried = format!(
            "tried {} ({within} within budget)",
            count(a.candidates.len(), "candidate", "candidates")
        );
        match a.plan_time().map(|(_, r)| r) {
            Some(r) => println!(
                "{tried}: {} ({:.1} s planning: {}; {r:.1}× the longer full render of the graph as given and of brute force)",
                a.why,
                a.plan_s,
                phases.join(", ")
            ),
            None => println!(
                "{tried}: {} ({:.1} s planning: {})",
                a.why,
                a.plan_s,
                phases.join(", ")
            ),
        }
        if !args.verbose {
            println!("(every candidate: --verbose, or the plan file)");
        }
        println!("wrote {} and {}", out_path.display(), plan_path.display());
    }
    Ok(0)
}

fn write(path: &std::path::Path, text: &str) -> anyhow::Result<()> {
    mesoflow_runtime::write_atomic(path, text)
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))
}

/// "1 candidate", "4 candidates".
fn count(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}
