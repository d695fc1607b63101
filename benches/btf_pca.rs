//! `btf.pca` on a captured BTF (`cargo bench --bench btf_pca -- [--res N] [--rank K]
//! [--q 2,4] [--npy FILE] [--skip-exact]`): captures an 81×81-direction BTF of a procedural weave at N²
//! texels (default 128), then times the randomized and exact solvers, with the peak resident
//! memory of each solve (VmHWM, reset before it) and the BTF bytes processed per second.
//! `--npy FILE` also writes the BTF as the T×C matrix (NPY, float32, C order, shape (C, T): read
//! it as `np.load(FILE).T`) for the scikit-learn peer in `benches/peer_randomized_svd.py`.

use mesoflow_nodes::btf::{capture, directions, pca};
use mesoflow_nodes::heightfield::procedural;
use mesoflow_nodes::types::{Btf, HeightField};
use mesoflow_runtime::{Inputs, Node, NodeContext, Value};
use npyz::WriterBuilder;
use std::io::Write;
use std::sync::Arc;
use std::time::Instant;

use mesoflow_testkit::args::arg;

fn flag(name: &str) -> bool {
    std::env::args().any(|a| a == name)
}

/// Peak resident set since the last reset, bytes (Linux; 0 elsewhere).
fn peak_rss() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

fn reset_peak() {
    // Writing 5 to clear_refs resets VmHWM to the current RSS (Linux ≥ 4.0).
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn main() {
    let res: usize = arg("--res", 128);
    let rank: u32 = arg("--rank", 16);
    let qs: Vec<u32> = arg("--q", "2".to_string())
        .split(',')
        .filter_map(|v| v.parse().ok())
        .collect();
    let npy = Some(arg("--npy", String::new())).filter(|s| !s.is_empty());
    let ctx = NodeContext::detached(None);

    let p = procedural::Params {
        pattern: procedural::Pattern::Weave,
        size: res as u32,
        depth: 4.0,
        ..Default::default()
    };
    let hf = HeightField::from_fn(res, res, |x, y| {
        (p.depth * procedural::unit_height(&p, x as f64 / res as f64, y as f64 / res as f64)) as f32
    });
    let params = capture::Params {
        views: directions::DirectionSet::Named(directions::Named::Ubo81),
        lights: directions::DirectionSet::Named(directions::Named::Ubo81),
        brdf: mesoflow_nodes::reflectance::models::Model::Ward,
        albedo: [0.55, 0.4, 0.3],
        ..Default::default()
    };
    let t0 = Instant::now();
    let out = capture::Capture
        .run(&ctx, &params, &Inputs::new().with("height", Arc::new(hf)))
        .expect("capture");
    let capture_s = t0.elapsed().as_secs_f64();
    let btf = out
        .get("btf")
        .unwrap()
        .as_any()
        .downcast_ref::<Btf>()
        .unwrap()
        .clone();
    drop(out);
    let bytes = btf.data.len() as f64 * 4.0;
    println!(
        "BTF: {} pairs × {res}² texels × RGB = {:.2} GB f32; capture {capture_s:.2} s; threads {}",
        btf.pairs.len(),
        bytes / 1e9,
        rayon::current_num_threads()
    );
    if let Some(path) = &npy {
        let shape = btf.as_array().unwrap().shape;
        let (c, t) = (shape[0] * shape[1], shape[2] * shape[3]);
        let mut w = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&[c as u64, t as u64])
            .writer(std::io::BufWriter::new(
                std::fs::File::create(path).expect("npy"),
            ))
            .begin_nd()
            .expect("npy header");
        w.extend(btf.data.iter().copied()).expect("npy data");
        w.finish().expect("npy finish");
        println!("wrote {path}: shape ({c}, {t}) float32; X = np.load(path).T is texels × columns");
    }
    let input = Inputs::new().with("btf", Arc::new(btf));
    println!("\n| solver | rank | seconds | GB/s | peak RSS / BTF bytes | RMSE |");
    println!("|---|---|---|---|---|---|");
    let mut solvers: Vec<(pca::Solver, u32, String)> = qs
        .iter()
        .map(|&q| {
            (
                pca::Solver::Randomized,
                q,
                format!("randomized (p=10, q={q})"),
            )
        })
        .collect();
    if !flag("--skip-exact") {
        solvers.push((pca::Solver::Exact, 0, "exact".into()));
    }
    for (solver, q, name) in solvers {
        reset_peak();
        let t = Instant::now();
        let o = pca::Pca
            .run(
                &ctx,
                &pca::Params {
                    solver,
                    rank: Some(rank),
                    power_iterations: q,
                    ..Default::default()
                },
                &input,
            )
            .expect("pca");
        let s = t.elapsed().as_secs_f64();
        let peak = peak_rss();
        let rmse = o.get("rmse").unwrap().as_scalar().unwrap();
        println!(
            "| {name} | {rank} | {s:.2} | {:.2} | {:.2} | {rmse:.6} |",
            bytes / s / 1e9,
            peak as f64 / bytes,
        );
        std::io::stdout().flush().ok();
    }
}
