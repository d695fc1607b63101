//! The planner's verification sweep, shared by `benches/plan_verify.rs` (which charts it) and
//! `tests/plan_verify.rs` (which holds it to the budget): for each camera distance and FLIP
//! budget, plan the BTF view and the translucent view of `graphs/plan_verify.json` with
//! `mesoflow plan`, run the planned graph, and record the measured FLIP of planned against full
//! (over the pixels either shows the object in), the prediction, and the render times (a frame's
//! time for `render.mesh`, the node's for `sss.render`).

use crate::cli::{mesoflow, node, repo};
use serde_json::Value;
use std::path::Path;

/// Frames each BTF render times (`render.mesh`'s `frames`, their mean is `frame_ms`): the far
/// views' time saved is a ratio of two such means.
pub const TIMED_FRAMES: u32 = 5;

pub const DISTANCES: [f64; 7] = [2.0, 3.0, 4.5, 7.0, 11.0, 17.0, 26.0];
pub const BUDGETS: [f64; 4] = [0.02, 0.05, 0.1, 0.25];
pub const OBJECTS: [(&str, &str, &str); 2] = [
    ("btf", "btf_full", "btf_view"),
    ("sss", "sss_full", "sss_view"),
];

/// The cameras' eye at distance `d` from the scene's target, as a graph value.
pub fn eye(d: f64) -> String {
    let target = [0.0, -0.1, 0.0];
    let dir = {
        let v = [0.0f64, 1.6, 2.7];
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|x| x / l)
    };
    let e: Vec<f64> = (0..3).map(|k| target[k] + d * dir[k]).collect();
    format!("[{:.4},{:.4},{:.4}]", e[0], e[1], e[2])
}

pub struct Row {
    pub distance: f64,
    pub budget: f64,
    pub object: &'static str,
    pub flip: f64,
    /// What the plan predicted: the kept plan's FLIP on the probe of the view where it was
    /// proved on one, else the measured model's prediction (absent where it could not say).
    pub predicted: Option<f64>,
    pub full_s: f64,
    pub view_s: f64,
    pub decisions: String,
    /// The device the full render ran on (`cpu` or `gpu`, as the report says).
    pub device: String,
}

/// Runs the sweep at `width` pixels across (height 3/4 of it) into `out`, with its own cache,
/// planning with `split` (`joint` or `equal`) for a viewer at `ppd` pixels per degree (FLIP's
/// default when `None`), the FLIP measured at the same.
pub fn sweep(out: &Path, width: u32, split: &str, ppd: Option<f64>) -> Vec<Row> {
    let root = repo();
    let height = width * 3 / 4;
    std::fs::create_dir_all(out).unwrap();
    let graph = root.join("graphs/plan_verify.json");
    let cache = out.join("cache");
    let mut rows = Vec::new();
    for &d in &DISTANCES {
        let eye = eye(d);
        let mut sets = Vec::new();
        for id in ["btf_full", "btf_view", "sss_full", "sss_view"] {
            sets.push(format!("{id}.camera.eye={eye}"));
            sets.push(format!("{id}.camera.resolution=[{width},{height}]"));
        }
        if let Some(p) = ppd {
            sets.push(format!("btf_flip.ppd={p}"));
            sets.push(format!("sss_flip.ppd={p}"));
        }
        let viewer: Vec<String> = ppd
            .map(|p| vec!["--ppd".to_string(), p.to_string()])
            .unwrap_or_default();
        for &b in &BUDGETS {
            let case = out.join(format!("d{d}_b{b}"));
            std::fs::create_dir_all(&case).unwrap();
            let step = case.join("step.json");
            let planned = case.join("planned.json");
            let budget = format!("flip={b}");
            let mut a: Vec<String> = vec![
                "plan".into(),
                graph.display().to_string(),
                "--render".into(),
                "btf_view".into(),
                "--budget".into(),
                budget.clone(),
                "-o".into(),
                step.display().to_string(),
                "--quiet".into(),
                "--split".into(),
                split.into(),
                "--cache-dir".into(),
                cache.display().to_string(),
            ];
            for s in &sets {
                a.push("--set".into());
                a.push(s.clone());
            }
            a.extend(viewer.iter().cloned());
            mesoflow(&a.iter().map(String::as_str).collect::<Vec<_>>());
            // `mesoflow plan` names the plan after the planned graph (`step.json` → `step.plan.json`).
            let btf_plan = std::fs::read_to_string(case.join("step.plan.json")).unwrap();
            std::fs::rename(case.join("step.plan.json"), case.join("plan_btf.json")).unwrap();
            let mut a: Vec<&str> = vec![
                "plan",
                step.to_str().unwrap(),
                "--render",
                "sss_view",
                "--budget",
                &budget,
                "-o",
                planned.to_str().unwrap(),
                "--quiet",
                "--split",
                split,
                "--cache-dir",
                cache.to_str().unwrap(),
            ];
            a.extend(viewer.iter().map(String::as_str));
            mesoflow(&a);
            let sss_plan = std::fs::read_to_string(case.join("planned.plan.json")).unwrap();
            std::fs::rename(case.join("planned.plan.json"), case.join("plan_sss.json")).unwrap();
            let run_out = case.join("out");
            // Ask for the measures, so that a run served wholly from the cache still reports them.
            // The BTF renders time TIMED_FRAMES frames each: one far view takes a few
            // milliseconds, and a single frame's time on a shared machine moves by a fifth.
            let frames = [
                format!("btf_full.frames={TIMED_FRAMES}"),
                format!("btf_view.frames={TIMED_FRAMES}"),
            ];
            mesoflow(&[
                "run",
                planned.to_str().unwrap(),
                "--set",
                &frames[0],
                "--set",
                &frames[1],
                "--output",
                "btf_flip.mean",
                "--output",
                "sss_flip.mean",
                "--output",
                "btf_full.image",
                "--output",
                "sss_full.image",
                "--output",
                "btf_view.image",
                "--output",
                "sss_view.image",
                "--quiet",
                "--out-dir",
                run_out.to_str().unwrap(),
                "--cache-dir",
                cache.to_str().unwrap(),
            ]);
            let report = read_report(&run_out);
            for ((object, full, view), plan_text) in OBJECTS.iter().zip([&btf_plan, &sss_plan]) {
                let plan: Value = serde_json::from_str(plan_text).unwrap();
                let decisions = decisions(&plan);
                let flip = node(&report, &format!("{object}_flip"))["metrics"]["mean"]
                    .as_f64()
                    .unwrap_or(f64::NAN);
                // Render time: a frame's time where the renderer measures one (`render.mesh`:
                // `frame_ms`, without the node's one-off set-up and read-back), else the node's
                // compute time (`sss.render`: samples, gather and shading).
                let secs = |id: &str| {
                    let t = &node(&report, id)["timings"];
                    t["frame_ms"]
                        .as_f64()
                        .map(|ms| ms / 1e3)
                        .or_else(|| t["seconds"].as_f64())
                        .unwrap_or(f64::NAN)
                };
                rows.push(Row {
                    distance: d,
                    budget: b,
                    object,
                    flip,
                    predicted: plan["probed_error"]
                        .as_f64()
                        .or(plan["predicted_error"].as_f64()),
                    full_s: secs(full),
                    view_s: secs(view),
                    decisions,
                    device: node(&report, full)["device"]
                        .as_str()
                        .unwrap_or("")
                        .to_string(),
                });
            }
            eprintln!("d = {d}, budget {b}: done");
        }
    }
    rows
}

/// The same sweep on `graphs/plan_qh.json`: a quasi-homogeneous torus whose entrance function
/// is a synthesized texture (so the synthesis decision is measured too), planned for `qh_view`
/// at FLIP's default viewing condition.
#[allow(dead_code)]
pub fn sweep_qh(out: &Path, width: u32) -> Vec<Row> {
    let root = repo();
    let height = width * 3 / 4;
    std::fs::create_dir_all(out).unwrap();
    let graph = root.join("graphs/plan_qh.json");
    let cache = out.join("cache");
    let mut rows = Vec::new();
    for &d in &DISTANCES {
        let eye = eye(d);
        for &b in &BUDGETS {
            let case = out.join(format!("d{d}_b{b}"));
            std::fs::create_dir_all(&case).unwrap();
            let planned = case.join("planned.json");
            let budget = format!("flip={b}");
            let mut a: Vec<String> = vec![
                "plan".into(),
                graph.display().to_string(),
                "--render".into(),
                "qh_view".into(),
                "--budget".into(),
                budget,
                "-o".into(),
                planned.display().to_string(),
                "--quiet".into(),
                "--cache-dir".into(),
                cache.display().to_string(),
            ];
            for id in ["qh_full", "qh_view"] {
                a.push("--set".into());
                a.push(format!("{id}.camera.eye={eye}"));
                a.push("--set".into());
                a.push(format!("{id}.camera.resolution=[{width},{height}]"));
            }
            mesoflow(&a.iter().map(String::as_str).collect::<Vec<_>>());
            let plan: Value = serde_json::from_str(
                &std::fs::read_to_string(case.join("planned.plan.json")).unwrap(),
            )
            .unwrap();
            let run_out = case.join("out");
            mesoflow(&[
                "run",
                planned.to_str().unwrap(),
                "--output",
                "qh_flip.mean",
                "--output",
                "qh_full.image",
                "--output",
                "qh_view.image",
                "--quiet",
                "--out-dir",
                run_out.to_str().unwrap(),
                "--cache-dir",
                cache.to_str().unwrap(),
            ]);
            let report = read_report(&run_out);
            let decisions = decisions(&plan);
            let secs = |id: &str| {
                node(&report, id)["timings"]["seconds"]
                    .as_f64()
                    .unwrap_or(f64::NAN)
            };
            // The texture's own cost where the plan stopped it early (the full one is computed
            // once for every case, so its time is in the first case's report only).
            rows.push(Row {
                distance: d,
                budget: b,
                object: "qh",
                flip: node(&report, "qh_flip")["metrics"]["mean"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
                predicted: plan["probed_error"]
                    .as_f64()
                    .or(plan["predicted_error"].as_f64()),
                full_s: secs("qh_full"),
                view_s: secs("qh_view"),
                decisions,
                device: node(&report, "qh_full")["device"]
                    .as_str()
                    .unwrap_or("")
                    .to_string(),
            });
            eprintln!("qh: d = {d}, budget {b}: done");
        }
    }
    rows
}

/// A plan's decisions as `stage:choice` pairs, for the sweep's table.
fn decisions(plan: &Value) -> String {
    plan["decisions"]
        .as_array()
        .map(|a| {
            a.iter()
                .map(|d| format!("{}:{}", d["stage"].as_str().unwrap_or(""), d["choice"]))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_default()
}

fn read_report(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}
