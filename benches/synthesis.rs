//! `synthesis.texture` against Embark's `texture-synthesis` crate (`cargo bench --bench synthesis
//! -- [--exemplar FILE.png] [--size 256] [--no-peer]`).
//!
//! The exemplar (default: 128² "stones", raised Voronoi cells lit from the upper left with
//! fractal colour noise, built from `heightfield.procedural`'s patterns, as 8-bit sRGB PNG) is synthesized
//! to `--size`² by both, each timed from the decoded exemplar to the finished image. The quality
//! measure is the same for both outputs, computed here by exhaustive search (not by either
//! program's own search): the mean over a grid of 8 × 8 patches (spacing 4) of the RMS
//! difference per channel to the nearest exemplar patch, on 8-bit values scaled to [0, 1].
//! The peer lives in `benches/texture_synthesis_peer` (its own workspace, built here on demand).
//! Images go to `out/bench_synthesis/`.

use mesoflow_nodes::heightfield::procedural::{unit_height, Params as Pattern, Pattern as Kind};
use mesoflow_nodes::support::formats;
use mesoflow_nodes::synthesis::optimize::{self, Settings};
use mesoflow_nodes::synthesis::patches::{self, Grid, Plane};
use mesoflow_nodes::types::Image;
use rayon::prelude::*;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use mesoflow_testkit::args::arg;

fn load(path: &Path) -> Plane {
    let img = image::open(path).expect("read PNG").to_rgb8();
    Plane {
        width: img.width() as usize,
        height: img.height() as usize,
        channels: 3,
        data: img.into_raw().iter().map(|v| *v as f32 / 255.0).collect(),
    }
}

fn save(plane: &Plane, path: &Path) {
    let bytes: Vec<u8> = plane
        .data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    image::RgbImage::from_raw(plane.width as u32, plane.height as u32, bytes)
        .expect("buffer")
        .save(path)
        .expect("write PNG");
}

/// Mean exact nearest-patch RMS distance of `img`'s 8 × 8 grid patches (spacing 4).
fn energy(img: &Plane, ex: &Plane) -> f64 {
    let grid = Grid::new(img.width, img.height, 8, 4, false);
    let feats = patches::gather(img, &grid);
    let dim = 8 * 8 * img.channels;
    let sum: f64 = (0..grid.len())
        .into_par_iter()
        .map(|q| {
            let m = patches::nearest_exact(ex, 8, &feats[q * dim..(q + 1) * dim]);
            (m.d2 as f64 / dim as f64).sqrt()
        })
        .collect::<Vec<f64>>()
        .iter()
        .sum();
    sum / grid.len() as f64
}

fn quantise(p: &Plane) -> Plane {
    Plane {
        data: p
            .data
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0)
            .collect(),
        ..p.clone()
    }
}

fn main() {
    let size: usize = arg("--size", 256);
    let dir = Path::new("out/bench_synthesis");
    std::fs::create_dir_all(dir).expect("output folder");
    let ex_path = match std::env::args().position(|a| a == "--exemplar") {
        Some(i) => std::path::PathBuf::from(std::env::args().nth(i + 1).expect("--exemplar FILE")),
        None => {
            let path = dir.join("exemplar.png");
            std::fs::write(&path, formats::encode_png(&stones(128), 8).expect("encode"))
                .expect("write exemplar");
            path
        }
    };
    let ex = load(&ex_path);
    println!(
        "exemplar {} ({} × {}), output {size}²",
        ex_path.display(),
        ex.width,
        ex.height
    );
    let settings = Settings {
        width: size,
        height: size,
        levels: 3,
        stop: 0,
        sizes: vec![32, 16, 8],
        iterations: 4,
        exponent: 0.8,
        periodic: false,
        rounds: 4,
        seed: 1,
    };
    let mut best = f64::INFINITY;
    let mut ours = None;
    for _ in 0..3 {
        let start = Instant::now();
        let out =
            optimize::synthesize::<()>(&ex, 3, None, &settings, |_, _| Ok(())).expect("synthesis");
        best = best.min(start.elapsed().as_secs_f64());
        ours = Some(out);
    }
    let ours = ours.expect("ran");
    let ours_q = quantise(&ours.image);
    save(&ours_q, &dir.join("mesoflow.png"));
    let t = Instant::now();
    let e_ours = energy(&ours_q, &ex);
    println!(
        "mesoflow synthesis.texture: {best:.3} s (best of 3); energy {e_ours:.4} (own search: {:.4}); measure {:.1} s",
        ours.energy,
        t.elapsed().as_secs_f64()
    );
    if !std::env::args().any(|a| a == "--no-peer") {
        let manifest = "benches/texture_synthesis_peer/Cargo.toml";
        let status = Command::new("cargo")
            .args(["build", "--release", "--quiet", "--manifest-path", manifest])
            .status()
            .expect("cargo");
        assert!(status.success(), "building the peer failed");
        let bin = "benches/texture_synthesis_peer/target/release/texture-synthesis-peer";
        let out_path = dir.join("texture-synthesis.png");
        let mut times = Vec::new();
        for _ in 0..3 {
            let out = Command::new(bin)
                .args([
                    ex_path.to_str().expect("path"),
                    out_path.to_str().expect("path"),
                    &size.to_string(),
                    &size.to_string(),
                    "1",
                ])
                .output()
                .expect("run the peer");
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            times.push(
                String::from_utf8_lossy(&out.stdout)
                    .trim()
                    .parse::<f64>()
                    .expect("seconds"),
            );
        }
        let peer = load(&out_path);
        let e_peer = energy(&peer, &ex);
        let t_peer = times.iter().copied().fold(f64::INFINITY, f64::min);
        println!("texture-synthesis 0.8: {t_peer:.3} s (best of 3); energy {e_peer:.4}");
        println!(
            "ratio (mesoflow / peer): time {:.2}, energy {:.2}",
            best / t_peer,
            e_ours / e_peer
        );
    }
    // The identity: the exemplar against itself scores 0; a resized exemplar is a blur baseline.
    let blur = quantise(&ex.resize(ex.width / 4, ex.height / 4).resize(size, size));
    println!(
        "baseline: the exemplar upscaled 4× from a quarter: energy {:.4}",
        energy(&blur, &ex)
    );
}

/// Stones: raised cells lit from the upper left, their colour varied by fractal noise; a
/// stochastic texture with structure at the patch scale and detail below it. Linear RGB.
fn stones(n: usize) -> Image {
    let cells = Pattern {
        pattern: Kind::Cells,
        count: 6,
        width: 0.25,
        seed: 4,
        ..Pattern::default()
    };
    let noise = Pattern {
        pattern: Kind::Noise,
        count: 4,
        octaves: 5,
        persistence: 0.6,
        seed: 9,
        ..Pattern::default()
    };
    let mut data = Vec::with_capacity(n * n * 3);
    let d = 1.0 / n as f64;
    for y in 0..n {
        for x in 0..n {
            let (u, v) = ((x as f64 + 0.5) * d, 1.0 - (y as f64 + 0.5) * d);
            let h = unit_height(&cells, u, v);
            let (hx, hy) = (
                unit_height(&cells, u + d, v) - h,
                unit_height(&cells, u, v + d) - h,
            );
            let shade = (0.75 - 3.0 * hx + 3.0 * hy).clamp(0.1, 1.2);
            let t = unit_height(&noise, u, v);
            let base = [0.35 + 0.3 * t, 0.28 + 0.2 * t, 0.2 + 0.08 * t];
            let k = (0.15 + 0.85 * h) * shade;
            data.extend(base.map(|b| (b * k) as f32));
        }
    }
    Image {
        width: n,
        height: n,
        channels: 3,
        data,
    }
}
