//! `mesoflow plan GRAPH --render ID --budget flip=B`: measures what the render's view shows (a
//! `scene.footprint` probe on the render's own inputs, run through the engine and its cache),
//! decides each stage's model (`crate::plan`), and writes the planned graph (the same graph with
//! the choices as ordinary parameters and connections) and `plan.json` beside it.

use super::run::{device_mode, engine, graph_dir, require_gpu};
use crate::args::PlanArgs;
use crate::exit::invalid;
use crate::load;
use crate::plan::{self, RenderKind, Scene};
use mesoflow_graph::{GraphFile, NodeDecl};
use mesoflow_nodes::image::flip;
use mesoflow_nodes::render::camera::CameraParams;
use mesoflow_runtime::{RunOptions, SilentObserver};
use serde_json::{json, Map, Value};
use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::Arc;

const PROBE: &str = "plan_probe";

/// `flip=B` → B.
fn parse_budget(text: &str) -> anyhow::Result<f64> {
    let (metric, value) = text
        .split_once('=')
        .ok_or_else(|| invalid(format!("--budget {text}: expected flip=B")))?;
    if metric.trim() != "flip" {
        return Err(invalid(format!(
            "--budget {text}: the only budget metric is `flip` (mean FLIP over the object's pixels)"
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

/// The nodes `id` depends on, and itself.
fn ancestors(file: &GraphFile, id: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![id.to_string()];
    while let Some(n) = stack.pop() {
        if !seen.insert(n.clone()) {
            continue;
        }
        if let Some(d) = file.node(&n) {
            for from in d.inputs.values() {
                if let Some((up, _)) = from.split_once('.') {
                    stack.push(up.to_string());
                }
            }
        }
    }
    seen
}

/// The probe graph: `scene.footprint` on the render's mesh, BTF and profile, with its camera,
/// tiling, shell and scale, and only the nodes those inputs need.
fn probe_graph(file: &GraphFile, render: &str, kind: RenderKind) -> GraphFile {
    let r = file.node(render).cloned().unwrap_or(NodeDecl {
        kind: String::new(),
        params: Map::new(),
        inputs: Default::default(),
    });
    let mut params = Map::new();
    for k in ["camera", "tiling", "shell", "mm_per_unit"] {
        if let Some(v) = r.params.get(k) {
            params.insert(k.into(), v.clone());
        }
    }
    if kind == RenderKind::Mesh && !r.params.contains_key("mm_per_unit") {
        params.insert("mm_per_unit".into(), json!(10.0));
    }
    if kind == RenderKind::Sss {
        params.remove("tiling");
    }
    let mut inputs = std::collections::BTreeMap::new();
    for (port, from) in [
        ("mesh", r.inputs.get("mesh")),
        ("btf", kind.btf_port().and_then(|p| r.inputs.get(p))),
        ("profile", r.inputs.get("profile")),
    ] {
        if let Some(f) = from {
            inputs.insert(port.to_string(), f.clone());
        }
    }
    let mut out = file.clone();
    let mut keep = BTreeSet::new();
    // One probe more per texture a decision needs measured, on the render's mesh and camera.
    for (i, src) in plan::texture_sources(file, render).iter().enumerate() {
        let id = format!("{PROBE}_texture{i}");
        let mut t = std::collections::BTreeMap::new();
        if let Some(m) = inputs.get("mesh") {
            t.insert("mesh".to_string(), m.clone());
        }
        t.insert("texture".to_string(), src.clone());
        out.nodes.push((
            id.clone(),
            NodeDecl {
                kind: "scene.footprint".into(),
                params: params.clone(),
                inputs: t,
            },
        ));
        keep.extend(ancestors(&out, &id));
    }
    out.nodes.push((
        PROBE.into(),
        NodeDecl {
            kind: "scene.footprint".into(),
            params,
            inputs,
        },
    ));
    keep.extend(ancestors(&out, PROBE));
    out.nodes.retain(|(id, _)| keep.contains(id));
    out
}

pub fn plan(args: &PlanArgs) -> anyhow::Result<i32> {
    let budget = parse_budget(&args.budget)?;
    let engine = engine(&args.cache, &args.graph)?;
    let mut file = load::read(&args.graph)?;
    load::apply_sets(&mut file, &args.set)?;
    load::checked(&args.graph, &file, engine.registry())?;
    let Some(decl) = file.node(&args.render) else {
        let hint = mesoflow_graph::did_you_mean(
            &args.render,
            file.nodes.iter().map(|(id, _)| id.as_str()),
        );
        return Err(invalid(format!(
            "--render {}: no node `{}`{hint}",
            args.render, args.render
        )));
    };
    let Some(kind) = RenderKind::of(&decl.kind) else {
        return Err(invalid(format!(
            "--render {}: a `{}` node; the planner plans render.mesh, sss.render and qh.render",
            args.render, decl.kind
        )));
    };
    let ppd = viewer_ppd(args, decl)?;

    // Measure the view (cached like any run).
    let probe = probe_graph(&file, &args.render, kind);
    let probe_checked = load::checked(&args.graph, &probe, engine.registry())?;
    let mut opts = RunOptions::new(
        &args.graph.display().to_string(),
        graph_dir(&args.graph),
        std::env::temp_dir(),
    );
    opts.device = device_mode(args.device);
    opts.require_gpu = require_gpu();
    opts.use_cache = !args.cache.no_cache;
    opts.cancel = super::run::cancel_flag();
    if !args.quiet {
        eprintln!("plan: measuring the view of `{}`", args.render);
    }
    let report = engine
        .run(&probe_checked, &opts, Arc::new(SilentObserver))
        .map_err(|e| invalid(e.to_string()))?;
    if !report.ok {
        let errors: Vec<String> = report
            .nodes
            .iter()
            .filter_map(|n| n.error.as_ref().map(|e| format!("{}: {e}", n.id)))
            .collect();
        anyhow::bail!("measuring the view failed: {}", errors.join("; "));
    }
    let metrics = report
        .node(PROBE)
        .map(|n| n.metrics.clone())
        .unwrap_or_default();
    let mut scene = Scene::from_metrics(&metrics).map_err(|e| invalid(e.to_string()))?;
    for (i, src) in plan::texture_sources(&file, &args.render)
        .iter()
        .enumerate()
    {
        if let Some(v) = report
            .node(&format!("{PROBE}_texture{i}"))
            .and_then(|n| plan::TextureView::from_metrics(&n.metrics))
        {
            scene.textures.insert(src.clone(), v);
        }
    }

    let chain = kind
        .btf_port()
        .and_then(|port| plan::btf_chain(&file, &args.render, port));
    let split = match args.split {
        crate::args::SplitArg::Joint => plan::Split::Joint,
        crate::args::SplitArg::Equal => plan::Split::Equal,
    };
    let planned = plan::plan(
        &file,
        &args.render,
        kind,
        &scene,
        chain.as_ref(),
        plan::Budget { flip: budget, ppd },
        split,
    )
    .map_err(|e| anyhow::anyhow!("--render {}: {e}", args.render))?;
    // The planned graph must itself be valid.
    load::checked(&args.graph, &planned.file, engine.registry())?;

    let out_path = args.output.clone().unwrap_or_else(|| {
        let stem = args
            .graph
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "graph".into());
        graph_dir(&args.graph).join(format!("{stem}.planned.json"))
    });
    let mut planned_file = planned.file;
    planned_file.description = Some(format!(
        "{} — planned for `{}` at a FLIP budget of {budget}, {ppd:.1} pixels per degree (see plan.json)",
        file.description.clone().unwrap_or_default(),
        args.render
    ));
    write(&out_path, &(planned_file.to_json() + "\n"))?;
    let plan_path = out_path
        .parent()
        .map(|p| p.join("plan.json"))
        .unwrap_or_else(|| PathBuf::from("plan.json"));
    let decisions: Vec<Value> = planned
        .decisions
        .iter()
        .map(|d| {
            let mut o = Map::new();
            o.insert("stage".into(), json!(d.stage));
            o.insert("choice".into(), d.choice.clone());
            o.insert("reason".into(), json!(d.reason));
            if let Some(e) = d.predicted_error {
                o.insert("predicted_error".into(), json!(e));
            }
            if let Some(c) = &d.predicted_cost {
                o.insert("predicted_cost".into(), c.clone());
            }
            Value::Object(o)
        })
        .collect();
    // Stage errors are taken to add; one unknown leaves the total unknown (absent).
    let total: Option<f64> = planned.decisions.iter().map(|d| d.predicted_error).sum();
    let mut doc = json!({
        "graph": args.graph.display().to_string(),
        "planned": out_path.display().to_string(),
        "render": args.render,
        "kind": decl.kind,
        "budget": { "flip": budget, "ppd": ppd },
        "calibrated_ppd": planned.calibrated_ppd,
        "scene": scene.to_json(),
        "decisions": decisions,
        "split": if split == plan::Split::Joint { "joint" } else { "equal" },
        "shares": planned.shares.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<Map<String, Value>>(),
        "calibration": "src/plan_calibration.json (benches/plan_calibrate.rs, a scene of its own); benches/plan_verify.rs measures the plan on graphs/plan_verify.json",
    });
    if let Some(t) = total {
        doc["predicted_error"] = json!(t);
    }
    if !planned.ppd_inside {
        doc["ppd_note"] = json!(format!(
            "{ppd:.1} pixels per degree is beyond the calibrated {:.0}: predictions may be low",
            planned.calibrated_ppd
        ));
    }
    write(
        &plan_path,
        &(serde_json::to_string_pretty(&doc).unwrap_or_default() + "\n"),
    )?;
    if !args.quiet {
        for d in &planned.decisions {
            println!("{:4} {} — {}", d.stage, d.choice, d.reason);
        }
        if let Some(t) = total {
            println!("predicted FLIP {t:.4} (budget {budget})");
        }
        println!("wrote {} and {}", out_path.display(), plan_path.display());
    }
    Ok(0)
}

fn write(path: &std::path::Path, text: &str) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, text).map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))
}
