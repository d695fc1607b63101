//! Accuracy over a family of scenes, never one: `sss.render` with its defaults against the
//! volumetric truth (`render.reference` with the medium) over seeded translucent scenes
//! (`mesoflow_testkit::scenes`: every Jensen preset, spheres and tori, 10–60 mm a unit, lit
//! from the front, the side and behind, η = 1). Per scene: relative RMSE over the truth's
//! coverage with the truth's own noise taken out, bias, the thickness in reduced mean free
//! paths, whether `sss.render` warned that the object is thin, both renders' times and the
//! path tracer's time at ours' error (scaled from its noise, 1/√samples); then
//! the distribution over the thick scenes (median, 90th percentile, worst) with the worst five
//! named (with their truth | ours | difference pictures), and how the thin-object warning sorts
//! the scenes. Every node on the CPU.
//!
//! Each scene is the shipped template `graphs/family_translucent.json` with the scene's `--set`s;
//! the bench writes that command beside each run (`OUT/seed-N/command.sh`) and prints it for the
//! worst five, so any of them can be rendered again by hand.
//!
//! `cargo bench --bench families -- [--first SEED] [--count N] [--held-out] [--width W]
//! [--samples S] [--out DIR] [--set ID.PARAM=VALUE]…` (the `--set`s measure another
//! configuration of the same graph; defaults: seeds 0..12, 64 × 48, 1024 samples a pixel,
//! `target/families`): the development seeds are 0.., the held-out ones `scenes::HELD_OUT`..
//! (`--held-out`), which no one tunes on.

use mesoflow_nodes::sss::material::Preset;
use mesoflow_testkit::scenes::{self, Kind, Scene};
use mesoflow_testkit::{args::arg, cli};
use serde_json::Value;
use std::path::PathBuf;

/// `sss.render` warns under six reduced mean free paths (`sss::render::thickness`).
const THIN: f64 = 6.0;

struct Row {
    scene: Scene,
    paths: f64,
    rel: Option<f64>,
    bias: Option<f64>,
    noise: Option<f64>,
    warned: bool,
    ours_s: f64,
    truth_s: f64,
    /// The `mesoflow run` line that renders this scene.
    command: String,
    /// Its truth | ours | difference picture.
    picture: PathBuf,
}

impl Row {
    /// The path tracer's time to reach ours' error: its noise falls as 1/√samples, so
    /// `samples × (noise / ours)²` samples (never more than its own) take that share of its
    /// time. An estimate from one run; absent where either error is.
    fn equal_error_s(&self) -> Option<f64> {
        let (noise, ours) = (self.noise?, self.rel?);
        (ours > 0.0).then(|| self.truth_s * ((noise / ours).powi(2)).min(1.0))
    }
}

fn metric(report: &Value, id: &str, name: &str) -> Option<f64> {
    cli::node(report, id)["metrics"][name].as_f64()
}

fn main() {
    let held_out = std::env::args().any(|a| a == "--held-out");
    let first: u64 = arg("--first", if held_out { scenes::HELD_OUT } else { 0 });
    let count: u64 = arg("--count", 12);
    let width: u32 = arg("--width", scenes::TEMPLATE_RESOLUTION[0]);
    let samples: u32 = arg("--samples", scenes::TEMPLATE_SAMPLES);
    let out: PathBuf = arg("--out", PathBuf::from("target/families"));
    std::fs::create_dir_all(&out).expect("the output folder");
    let resolution = [width, width * 3 / 4];
    // `--set id.param=value` (repeatable): a configuration to measure in place of the defaults.
    let argv: Vec<String> = std::env::args().collect();
    let extra: Vec<String> = argv
        .windows(2)
        .filter(|w| w[0] == "--set")
        .map(|w| w[1].clone())
        .collect();
    if !extra.is_empty() {
        println!("configuration: {}\n", extra.join(" "));
    }
    println!(
        "| seed | scene | mean free paths | relative RMSE | bias | truth noise | thin warning | ours, s | truth, s | truth at ours' error, s |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    let mut rows = Vec::new();
    for seed in first..first + count {
        let scene = scenes::family(Kind::Translucent, seed);
        let preset: Preset =
            serde_json::from_value(Value::from(scene.preset)).expect("a preset name");
        let paths = scenes::mean_free_paths(&scene, preset.coefficients());
        let run = out.join(format!("seed-{seed}"));
        // The shipped template with the scene's `--set`s: the command a user reruns.
        let mut sets = scene.sets(resolution, samples);
        sets.extend(extra.iter().cloned());
        let template = cli::repo().join(scenes::TEMPLATE);
        let mut args: Vec<String> = vec!["run".into(), template.display().to_string()];
        for s in &sets {
            args.push("--set".into());
            args.push(s.clone());
        }
        let command = format!(
            "mesoflow run {} {}",
            scenes::TEMPLATE,
            sets.iter()
                .map(|s| format!("--set '{s}'"))
                .collect::<Vec<_>>()
                .join(" ")
        );
        std::fs::create_dir_all(&run).expect("the scene's folder");
        std::fs::write(run.join("command.sh"), format!("{command}\n")).expect("write the command");
        args.extend(["--quiet", "--device", "cpu", "--out-dir"].map(String::from));
        args.push(run.join("out").display().to_string());
        cli::mesoflow(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let report: Value = serde_json::from_slice(
            &std::fs::read(run.join("out").join("report.json")).expect("the run's report"),
        )
        .expect("a report");
        let raw = metric(&report, "error", "relative_rmse");
        let noise = metric(&report, "truth", "noise");
        // The truth's noise taken out: what is left is ours.
        let rel = raw.map(|r| (r * r - noise.unwrap_or(0.0).powi(2)).max(0.0).sqrt());
        let warned = report["warnings"].as_array().is_some_and(|w| {
            w.iter().any(|w| {
                w["node"] == "ours"
                    && w["message"]
                        .as_str()
                        .is_some_and(|m| m.contains("diffusion needs"))
            })
        });
        // The node's own compute time, which a cache entry keeps (`timings.seconds`), so a
        // rerun over cached truths still reports what each render took when it was made.
        let secs = |id: &str| {
            let n = cli::node(&report, id);
            n["timings"]["seconds"]
                .as_f64()
                .or(n["seconds"].as_f64())
                .unwrap_or(f64::NAN)
        };
        let row = Row {
            paths,
            rel,
            bias: metric(&report, "error", "bias"),
            noise,
            warned,
            ours_s: secs("ours"),
            command,
            picture: run.join("out").join(scenes::PICTURE),
            truth_s: secs("truth"),
            scene,
        };
        let f = |v: Option<f64>| v.map_or("absent".into(), |v| format!("{v:.3}"));
        println!(
            "| {seed} | {} | {:.1} | {} | {} | {} | {} | {:.1} | {:.1} | {} |",
            row.scene.name(),
            row.paths,
            f(row.rel),
            row.bias
                .map_or("absent".into(), |b| format!("{:+.1}%", 100.0 * b)),
            f(row.noise),
            if row.warned { "yes" } else { "no" },
            row.ours_s,
            row.truth_s,
            row.equal_error_s()
                .map_or("absent".into(), |t| format!("{t:.2}"))
        );
        rows.push(row);
    }
    summary(&rows);
}

fn summary(rows: &[Row]) {
    let mut thick: Vec<&Row> = rows.iter().filter(|r| r.paths >= THIN).collect();
    thick.sort_by(|a, b| {
        b.rel
            .unwrap_or(f64::INFINITY)
            .total_cmp(&a.rel.unwrap_or(f64::INFINITY))
    });
    let mut sorted: Vec<f64> = thick.iter().filter_map(|r| r.rel).collect();
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| sorted[((sorted.len() as f64 - 1.0) * p).round() as usize];
    println!(
        "\nthick scenes (at least {THIN} reduced mean free paths): {}",
        thick.len()
    );
    if !sorted.is_empty() {
        let biases: Vec<f64> = thick.iter().filter_map(|r| r.bias).collect();
        let worst_bias = biases
            .iter()
            .copied()
            .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
        println!(
            "relative RMSE: median {:.3}, 90th percentile {:.3}, worst {:.3}; largest bias {:+.1}%",
            q(0.5),
            q(0.9),
            sorted[sorted.len() - 1],
            100.0 * worst_bias
        );
        println!("the worst five:");
        for r in thick.iter().take(5) {
            println!(
                "  {:.3}, bias {:+.1}%: {}",
                r.rel.unwrap_or(f64::NAN),
                100.0 * r.bias.unwrap_or(f64::NAN),
                r.scene.name()
            );
            println!("    {}", r.command);
            println!("    picture: {}", r.picture.display());
        }
    }
    let (faster, slower): (Vec<&Row>, Vec<&Row>) = rows
        .iter()
        .filter(|r| r.equal_error_s().is_some())
        .partition(|r| r.equal_error_s().is_some_and(|t| r.ours_s < t));
    println!(
        "ours faster than the path tracer at ours' error: {} scenes; slower: {} (the path tracer on the same CPU, its time scaled from its noise)",
        faster.len(),
        slower.len()
    );
    let noisiest = rows.iter().filter_map(|r| r.noise).fold(0.0f64, f64::max);
    println!(
        "the truths' largest noise estimate: {noisiest:.3} (a third of the 0.15 bound is 0.05)"
    );
    let thin = rows.len() - thick.len();
    let thin_warned = rows.iter().filter(|r| r.paths < THIN && r.warned).count();
    let thick_warned = thick.iter().filter(|r| r.warned).count();
    println!(
        "thin scenes: {thin}, warned {thin_warned}; thick scenes warned: {thick_warned} of {}",
        thick.len()
    );
}
