//! Accuracy over a family of scenes, never one: each renderer with its defaults against an
//! independent truth (`render.reference`) over the seeded scenes of `mesoflow_testkit::scenes`,
//! reported per scene and as a distribution (median, 90th percentile, worst) with the worst five
//! named, each with the command that renders it again and its truth | ours | difference picture.
//! Every node on the CPU.
//!
//! - `--family translucent` (the default, `translucent.rs`): `sss.render` against volumetric
//!   path tracing.
//! - `--family mesostructure` (`mesostructure.rs`): `render.mesh` (BTF + MDF) against the true
//!   displaced geometry.
//!
//! Each scene is the family's shipped template (`graphs/family_<name>.json`) with the scene's
//! `--set`s; the bench writes that command beside each run (`OUT/seed-N/command.sh`).
//!
//! `cargo bench --bench families -- [--family NAME] [--first SEED] [--count N] [--held-out]
//! [--width W] [--samples S] [--out DIR] [--set ID.PARAM=VALUE]…` (the `--set`s measure another
//! configuration of the same graph; defaults: seeds 0..12, the template's resolution and samples,
//! `target/families` or `target/families-<name>`): the development seeds are 0.., the held-out
//! ones `scenes::HELD_OUT`.. (`--held-out`), which no one tunes on. `--widths 160,640` (the
//! translucent family) times each scene again at those widths, ours against the path tracer at
//! ours' error (`translucent.rs`).

mod mesostructure;
mod translucent;

use mesoflow_testkit::scenes::{self, Kind, Scene};
use mesoflow_testkit::{args::arg, cli};
use serde_json::Value;
use std::path::PathBuf;

/// What every family's bench takes from the command line.
#[derive(Clone)]
pub struct Options {
    pub first: u64,
    pub count: u64,
    pub resolution: [u32; 2],
    pub samples: u32,
    pub out: PathBuf,
    /// `--set id.param=value` (repeatable): a configuration to measure in place of the defaults.
    pub extra: Vec<String>,
    /// `--widths W,W,…`: larger images of each scene to time (the translucent family).
    pub widths: Vec<u32>,
}

/// One scene run: its report, the command that makes it, its picture.
pub struct Run {
    pub report: Value,
    pub command: String,
    pub picture: PathBuf,
}

impl Run {
    /// A node's metric, absent where the node did not report it.
    pub fn metric(&self, id: &str, name: &str) -> Option<f64> {
        cli::node(&self.report, id)["metrics"][name].as_f64()
    }

    /// The node's own compute time, which a cache entry keeps (`timings.seconds`), so a rerun
    /// over cached truths still reports what each render took when it was made; absent where
    /// the run did not need the node (its consumers were all cached).
    pub fn seconds(&self, id: &str) -> Option<f64> {
        let n = cli::node(&self.report, id);
        n["timings"]["seconds"].as_f64().or(n["seconds"].as_f64())
    }

    /// Whether `id` warned with a message containing `text`.
    pub fn warned(&self, id: &str, text: &str) -> bool {
        self.report["warnings"].as_array().is_some_and(|w| {
            w.iter()
                .any(|w| w["node"] == id && w["message"].as_str().is_some_and(|m| m.contains(text)))
        })
    }

    /// The relative RMSE of `error` with the truth's own noise (`truth.noise`) taken out: what
    /// is left is ours.
    pub fn relative_rmse(&self) -> Option<f64> {
        let raw = self.metric("error", "relative_rmse")?;
        let noise = self.metric("truth", "noise").unwrap_or(0.0);
        Some((raw * raw - noise * noise).max(0.0).sqrt())
    }
}

/// Runs `scene` as its family's template with the scene's `--set`s and `options.extra`.
pub fn run(scene: &Scene, options: &Options) -> Run {
    run_for(scene, options, &[], "out")
}

/// [`run`] producing only `outputs` (`ID.PORT`; every sink when empty) into `OUT/seed-N/<folder>`:
/// a node a sink did not need (all its consumers cached) is then still reported, from the cache
/// with the time it took when it was computed.
pub fn run_for(scene: &Scene, options: &Options, outputs: &[&str], folder: &str) -> Run {
    let kind = scene.kind();
    let dir = options.out.join(format!("seed-{}", scene.seed()));
    let mut sets = scene.sets(options.resolution, options.samples);
    sets.extend(options.extra.iter().cloned());
    let template = cli::repo().join(kind.template());
    let mut args: Vec<String> = vec!["run".into(), template.display().to_string()];
    for s in &sets {
        args.push("--set".into());
        args.push(s.clone());
    }
    let command = format!(
        "mesoflow run {} --device cpu {}",
        kind.template(),
        sets.iter()
            .map(|s| format!("--set '{s}'"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    std::fs::create_dir_all(&dir).expect("the scene's folder");
    std::fs::write(dir.join("command.sh"), format!("{command}\n")).expect("write the command");
    for o in outputs {
        args.extend(["--output".to_string(), o.to_string()]);
    }
    args.extend(["--quiet", "--device", "cpu", "--out-dir"].map(String::from));
    args.push(dir.join(folder).display().to_string());
    cli::mesoflow(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let report: Value = serde_json::from_slice(
        &std::fs::read(dir.join(folder).join("report.json")).expect("the run's report"),
    )
    .expect("a report");
    Run {
        report,
        command,
        picture: dir.join("out").join(scenes::PICTURE),
    }
}

/// `x` to three places, or `absent`.
pub fn f3(x: Option<f64>) -> String {
    x.map_or("absent".into(), |v| format!("{v:.3}"))
}

/// A share as a signed percentage, or `absent`.
pub fn percent(x: Option<f64>) -> String {
    x.map_or("absent".into(), |v| format!("{:+.1}%", 100.0 * v))
}

/// The median, 90th percentile and worst of `values` (nearest rank), printed; none when empty.
pub fn distribution(label: &str, values: &[f64]) -> Option<(f64, f64, f64)> {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    if sorted.is_empty() {
        return None;
    }
    let q = |p: f64| sorted[((sorted.len() as f64 - 1.0) * p).round() as usize];
    let d = (q(0.5), q(0.9), sorted[sorted.len() - 1]);
    println!(
        "{label}: median {:.3}, 90th percentile {:.3}, worst {:.3} (over {})",
        d.0,
        d.1,
        d.2,
        sorted.len()
    );
    Some(d)
}

/// The path tracer's time to reach ours' error: its noise falls as 1/√samples, so `samples ×
/// (noise / ours)²` samples take that share of its time — never more than its own samples, and
/// never fewer than one a pixel (below that the scaling means nothing). An estimate from one
/// run that scales the whole node, its BVH build included; absent where either error is.
pub fn equal_error_seconds(
    truth_s: f64,
    samples: u32,
    noise: Option<f64>,
    ours: Option<f64>,
) -> Option<f64> {
    let (noise, ours) = (noise?, ours?);
    if ours <= 0.0 {
        return None;
    }
    let share = (noise / ours)
        .powi(2)
        .clamp(1.0 / samples.max(1) as f64, 1.0);
    Some(truth_s * share)
}

fn main() {
    let family = arg("--family", "translucent".to_string());
    let kind = Kind::ALL
        .into_iter()
        .find(|k| k.name() == family)
        .unwrap_or_else(|| {
            panic!("--family {family}: the families are translucent and mesostructure")
        });
    let held_out = std::env::args().any(|a| a == "--held-out");
    let width: u32 = arg("--width", kind.resolution()[0]);
    let default_out = match kind {
        Kind::Translucent => "target/families".to_string(),
        k => format!("target/families-{}", k.name()),
    };
    let argv: Vec<String> = std::env::args().collect();
    let options = Options {
        first: arg("--first", if held_out { scenes::HELD_OUT } else { 0 }),
        count: arg("--count", 12),
        resolution: [width, width * kind.resolution()[1] / kind.resolution()[0]],
        samples: arg("--samples", kind.samples()),
        out: arg("--out", PathBuf::from(default_out)),
        extra: argv
            .windows(2)
            .filter(|w| w[0] == "--set")
            .map(|w| w[1].clone())
            .collect(),
        widths: arg("--widths", String::new())
            .split(',')
            .filter_map(|w| w.trim().parse().ok())
            .collect(),
    };
    std::fs::create_dir_all(&options.out).expect("the output folder");
    if !options.extra.is_empty() {
        println!("configuration: {}\n", options.extra.join(" "));
    }
    match kind {
        Kind::Translucent => translucent::bench(&options),
        Kind::Mesostructure => mesostructure::bench(&options),
        Kind::HeightFromNormals | Kind::WardFit => {
            eprintln!("the {} family renders nothing to time: tests/families.rs measures it (cargo test --release --test tests families:: -- --nocapture)", kind.name());
            std::process::exit(2);
        }
    }
}
