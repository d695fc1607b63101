//! The translucent family: `sss.render` with its defaults against the volumetric truth
//! (`render.reference` with the medium) over seeded translucent scenes (every Jensen preset,
//! spheres and tori, 10–60 mm a unit, lit from the front, the side and behind, η = 1). Per
//! scene: relative RMSE over the truth's coverage with the truth's own noise taken out, bias,
//! the thickness in reduced mean free paths, whether `sss.render` warned that the object is
//! thin, both renders' times (ours' first frame, `sss.lighting` and `sss.render`, and another view
//! of the scene from the cached lighting, `sss.render` alone) and the path tracer's time at ours' error (scaled from its noise,
//! 1/√samples); then the distribution over the thick scenes with the worst five named, and how
//! the thin-object warning sorts the scenes.

use super::{distribution, equal_error_seconds, f3, percent, run, run_for, Options};
use mesoflow_nodes::sss::material::Preset;
use mesoflow_testkit::scenes::{self, translucent::Scene, Kind};
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
    /// The first frame: `sss.lighting` and `sss.render`.
    ours_s: f64,
    /// Another view of the same scene: `sss.render` from the cached lighting.
    view_s: f64,
    truth_s: f64,
    /// The truth's samples a pixel.
    samples: u32,
    /// The `mesoflow run` line that renders this scene.
    command: String,
    /// Its truth | ours | difference picture.
    picture: PathBuf,
}

impl Row {
    fn equal_error_s(&self) -> Option<f64> {
        equal_error_seconds(self.truth_s, self.samples, self.noise, self.rel)
    }
}

pub fn bench(options: &Options) {
    println!(
        "| seed | scene | mean free paths | relative RMSE | bias | truth noise | thin warning | ours, s | a view from the cache, s | truth, s | truth at ours' error, s |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let mut rows = Vec::new();
    for seed in options.first..options.first + options.count {
        let scenes::Scene::Translucent(scene) = scenes::family(Kind::Translucent, seed) else {
            unreachable!("the translucent family draws translucent scenes")
        };
        let preset: Preset =
            serde_json::from_value(Value::from(scene.preset)).expect("a preset name");
        let paths = scenes::translucent::mean_free_paths(&scene, preset.coefficients());
        let r = run(&scenes::Scene::Translucent(scene.clone()), options);
        // Both of ours' nodes' times, also where the render came from the cache whole.
        let times = run_for(
            &scenes::Scene::Translucent(scene.clone()),
            options,
            &["lighting.points", "ours.image"],
            "times",
        );
        let row = Row {
            paths,
            rel: r.relative_rmse(),
            bias: r.metric("error", "bias"),
            noise: r.metric("truth", "noise"),
            warned: r.warned("lighting", "diffusion needs"),
            ours_s: times.seconds("lighting").unwrap_or(f64::NAN)
                + times.seconds("ours").unwrap_or(f64::NAN),
            view_s: times.seconds("ours").unwrap_or(f64::NAN),
            truth_s: r.seconds("truth").unwrap_or(f64::NAN),
            samples: options.samples,
            command: r.command,
            picture: r.picture,
            scene,
        };
        println!(
            "| {seed} | {} | {:.1} | {} | {} | {} | {} | {:.1} | {:.2} | {:.1} | {} |",
            row.scene.name(),
            row.paths,
            f3(row.rel),
            percent(row.bias),
            f3(row.noise),
            if row.warned { "yes" } else { "no" },
            row.ours_s,
            row.view_s,
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
    println!(
        "\nthick scenes (at least {THIN} reduced mean free paths): {}",
        thick.len()
    );
    let rel: Vec<f64> = thick.iter().filter_map(|r| r.rel).collect();
    if distribution("relative RMSE", &rel).is_some() {
        let worst_bias =
            thick
                .iter()
                .filter_map(|r| r.bias)
                .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
        println!("largest bias {}", percent(Some(worst_bias)));
        println!("the worst five:");
        for r in thick.iter().take(5) {
            println!(
                "  {}, bias {}: {}",
                f3(r.rel),
                percent(r.bias),
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
    let (faster, slower): (Vec<&Row>, Vec<&Row>) = rows
        .iter()
        .filter(|r| r.equal_error_s().is_some())
        .partition(|r| r.equal_error_s().is_some_and(|t| r.view_s < t));
    println!(
        "another view from the cached lighting faster than the path tracer at ours' error: {} scenes; slower: {}",
        faster.len(),
        slower.len()
    );
    let shares: Vec<f64> = rows.iter().map(|r| r.view_s / r.ours_s).collect();
    distribution("a view from the cache over the first frame", &shares);
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
