//! Subsurface scattering timings (`cargo bench --bench sss -- [--photons 200000]
//! [--points 10000,100000,1000000] [--width 64 --height 48] [--device cpu|gpu|both] [--no-peer]`).
//!
//! 1. Profiles: a pbrt-style table of 100 albedos × 64 radii (σt′ = 1, η = 1.3) per model,
//!    seconds per table and per profile.
//! 2. Monte Carlo: photons per second for ketchup red (low albedo) and marble red (high albedo),
//!    then the numpy peer `benches/sss_montecarlo.py` on the same photons in the same session
//!    (unless `--no-peer` or numpy is missing), with both totals and standard errors.
//! 3. `sss.render`: a torus of skin1 (20 mm per unit) at `--width`×`--height`, for each requested
//!    number of irradiance samples: octree (threshold 0.05) and brute force on the CPU, brute
//!    force on the GPU; gather seconds and the octree's RMS error against brute force.

use mesoflow_nodes::mesh::primitive;
use mesoflow_nodes::sss::material::{self, Preset};
use mesoflow_nodes::sss::montecarlo;
use mesoflow_nodes::sss::profile::{self, Model};
use mesoflow_nodes::sss::render;
use mesoflow_nodes::support::raytrace::camera::CameraParams;
use mesoflow_nodes::support::raytrace::light::LightParams;
use mesoflow_nodes::types::ScatteringMaterial;
use mesoflow_runtime::Gpu;
use std::time::Instant;

use mesoflow_testkit::args::arg;

fn flag(name: &str) -> bool {
    std::env::args().any(|a| a == name)
}

fn tables() {
    println!("| model | 100 × 64 table, s | per profile, ms |\n|---|---|---|");
    for model in [Model::Dipole, Model::BetterDipole, Model::Pbd] {
        let start = Instant::now();
        for i in 0..100 {
            let alpha = (i as f64 + 0.5) / 100.0;
            let m = ScatteringMaterial {
                sigma_s_prime: [alpha; 3],
                sigma_a: [1.0 - alpha; 3],
                eta: 1.3,
                g: 0.0,
            };
            let p = profile::Params {
                model,
                points: 64,
                ..Default::default()
            };
            // Three channels per call: one table row is a third of it, so time one channel's
            // worth by tabulating all three and dividing.
            std::hint::black_box(profile::tabulate(
                &m,
                &p,
                &mesoflow_nodes::support::progress::Counter::none(),
            ));
        }
        let s = start.elapsed().as_secs_f64() / 3.0;
        println!("| {} | {s:.4} | {:.3} |", model.name(), s * 10.0);
    }
}

fn monte_carlo(photons: u64, peer: bool) {
    println!(
        "\n| Monte Carlo, {photons} photons | mesoflow photons/s | total ± s.e. | numpy photons/s | numpy total ± s.e. |\n|---|---|---|---|---|"
    );
    for (name, preset) in [
        ("ketchup red", Preset::Ketchup),
        ("marble red", Preset::Marble),
    ] {
        let (s, a) = preset.coefficients();
        let m = montecarlo::Medium {
            sigma_s: s[0],
            sigma_a: a[0],
            g: 0.0,
            eta: 1.3,
        };
        let start = Instant::now();
        let t = montecarlo::trace(
            &m,
            &[0.0, 1.0],
            photons,
            1,
            0,
            &mesoflow_nodes::support::progress::Counter::none(),
        );
        let secs = start.elapsed().as_secs_f64();
        let ours = format!(
            "| {name} | {:.0} | {:.5} ± {:.5} |",
            photons as f64 / secs,
            t.total(),
            t.stderr()
        );
        let theirs = if peer {
            std::process::Command::new("python3")
                .args([
                    "benches/sss_montecarlo.py",
                    "--sigma-s",
                    &s[0].to_string(),
                    "--sigma-a",
                    &a[0].to_string(),
                    "--photons",
                    &photons.to_string(),
                ])
                .output()
                .ok()
                .filter(|o| o.status.success())
                .map(|o| String::from_utf8_lossy(&o.stdout).to_string())
        } else {
            None
        };
        // "numpy: N photons in S s = P photons/s (…); total Rd T ± E"
        let peer_cols = theirs
            .and_then(|line| {
                let rate = line.split(" = ").nth(1)?.split(' ').next()?.to_string();
                let total = line.split("total Rd ").nth(1)?.trim().to_string();
                Some(format!(" {rate} | {total} |"))
            })
            .unwrap_or_else(|| " (not run) | |".into());
        println!("{ours}{peer_cols}");
    }
}

fn renders(counts: &[usize], width: u32, height: u32, gpu: Option<&Gpu>) {
    let torus = primitive::build(&primitive::Params {
        shape: primitive::Shape::Torus,
        size: 0.9,
        minor: 0.38,
        segments: [128, 64],
    })
    .expect("torus");
    let m = material::material(&material::Params {
        preset: Some(Preset::Skin1),
        ..Default::default()
    })
    .expect("skin1");
    let prof = profile::tabulate(
        &m,
        &profile::Params {
            model: profile::Model::Dipole,
            ..Default::default()
        },
        &mesoflow_nodes::support::progress::Counter::none(),
    )
    .profile;
    println!(
        "\n| sss.render {width}×{height}, samples | octree 0.05 CPU, s | brute CPU, s | octree RMS vs brute | brute GPU, s |\n|---|---|---|---|---|"
    );
    for &n in counts {
        let p = |threshold: f64| render::Params {
            camera: CameraParams {
                eye: [0.0, 1.6, 2.9],
                target: [0.0, -0.1, 0.0],
                resolution: [width, height],
                ..Default::default()
            },
            light: LightParams {
                direction: [0.5, 0.5, -1.0],
                position: None,
                intensity: 5.0,
                ..Default::default()
            },
            mm_per_unit: 20.0,
            // Ask for far denser samples than the cap: the cap sets the count.
            spacing: Some(1e-4),
            max_points: n as u32,
            threshold,
            // The gather alone, as Jensen & Buhler render it (the GPU gathers the planar profile).
            ..render::Params::classic()
        };
        let octree = render::render(None, &torus, &m, &prof, &p(0.05)).expect("octree");
        let brute = render::render(None, &torus, &m, &prof, &p(0.0)).expect("brute");
        let num: f64 = octree
            .exitance
            .data
            .iter()
            .zip(&brute.exitance.data)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum();
        let den: f64 = brute
            .exitance
            .data
            .iter()
            .map(|b| (*b as f64).powi(2))
            .sum();
        let rms = |test: &[f32]| {
            let num: f64 = test
                .iter()
                .zip(&brute.exitance.data)
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum();
            (num / den).sqrt()
        };
        // The GPU's sums (f32) against the CPU's brute force (f64): the same sum, so the
        // difference is rounding alone.
        let gpu_s = gpu
            .map(|g| {
                render::render(Some(g), &torus, &m, &prof, &p(0.0))
                    .map(|r| {
                        format!(
                            "{:.3} (RMS vs CPU {:.1e})",
                            r.gather_seconds,
                            rms(&r.exitance.data)
                        )
                    })
                    .unwrap_or_else(|e| format!("error: {e}"))
            })
            .unwrap_or_else(|| "(no GPU)".into());
        println!(
            "| {} | {:.3} | {:.3} | {:.2e} | {gpu_s} |",
            octree.points,
            octree.gather_seconds,
            brute.gather_seconds,
            (num / den).sqrt()
        );
    }
}

fn main() {
    let device: String = arg("--device", "both".to_string());
    let gpu = match device.as_str() {
        "cpu" => None,
        _ => Gpu::with_backends(wgpu::Backends::PRIMARY)
            .map_err(|e| eprintln!("no GPU: {e}"))
            .ok(),
    };
    if let Some(g) = &gpu {
        println!("GPU: {}", g.describe());
    }
    tables();
    monte_carlo(arg("--photons", 200_000), !flag("--no-peer"));
    let counts: Vec<usize> = arg("--points", "10000,100000,1000000".to_string())
        .split(',')
        .filter_map(|v| v.parse().ok())
        .collect();
    renders(
        &counts,
        arg("--width", 64),
        arg("--height", 48),
        gpu.as_ref(),
    );
}
