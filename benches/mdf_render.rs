//! `mdf.tabulate` and `render.mesh` timings (`cargo bench --bench mdf_render -- [--mdf-res 256]
//! [--width 800 --height 600] [--frames 5] [--btf-res 64] [--device cpu|gpu|both]`).
//!
//! MDF: a procedural weave at `--mdf-res`² texels × the 81 UBO2003 views, CPU (rayon, f64 exact
//! traversal) and GPU (wgpu compute, f32), seconds and rays per second.
//! Render: a 64² woven BTF (33 × 33 directions, the graph's capture) on a torus at 800×600:
//! raw BTF, PCA rank 8/16/32, + MDF, + shadows; mean wall time per frame over `--frames` after a
//! warm-up frame (the node's `frame_ms`) and, on a GPU, the timestamp-query time (`gpu_ms`).

use mesoflow_nodes::btf::{capture, pca};
use mesoflow_nodes::heightfield::procedural;
use mesoflow_nodes::mdf::tabulate;
use mesoflow_nodes::mesh::primitive;
use mesoflow_nodes::render::render_mesh::{self, RenderMesh};
use mesoflow_runtime::{Gpu, Inputs, Node, NodeContext, ValueRef};
use std::sync::Arc;

use mesoflow_testkit::args::arg;

fn port(node: &dyn Fn() -> mesoflow_runtime::Outputs, name: &str) -> ValueRef {
    node().get(name).expect("port").clone()
}

/// The graph's woven tile at `size`² texels, `depth` texels deep.
fn weave(size: u32, depth: f64) -> ValueRef {
    let p = procedural::Params {
        pattern: procedural::Pattern::Weave,
        size,
        depth,
        count: 4,
        ..Default::default()
    };
    Arc::new(procedural::generate(&NodeContext::detached(None), &p).unwrap())
}

/// A timing the node reported (NaN where it measured none, e.g. no GPU timestamps).
fn timing(ctx: &NodeContext, name: &str) -> f64 {
    ctx.timings().get(name).copied().unwrap_or(f64::NAN)
}

fn main() {
    let device: String = arg("--device", "both".to_string());
    let gpu = match device.as_str() {
        "cpu" => None,
        _ => match Gpu::with_backends(wgpu::Backends::PRIMARY) {
            Ok(g) => Some(Arc::new(g)),
            Err(e) => {
                eprintln!("no GPU: {e}");
                None
            }
        },
    };
    let mut devices: Vec<(String, Option<Arc<Gpu>>)> = Vec::new();
    if device != "gpu" {
        devices.push(("CPU (rayon)".into(), None));
    }
    if let Some(g) = &gpu {
        devices.push((g.describe(), Some(g.clone())));
    }
    let quiet = NodeContext::detached(None);

    // MDF tabulation.
    let mdf_res: u32 = arg("--mdf-res", 256);
    let tile = weave(mdf_res, 6.0 * mdf_res as f64 / 64.0);
    println!("| mdf.tabulate {mdf_res}² × 81 views | seconds | rays/s |\n|---|---|---|");
    for (name, g) in &devices {
        let ctx = NodeContext::detached(g.clone());
        let started = std::time::Instant::now();
        tabulate::Tabulate
            .run(
                &ctx,
                &tabulate::Params::default(),
                &Inputs::new().with("height", tile.clone()),
            )
            .unwrap();
        println!(
            "| {name} | {:.3} | {:.3e} |",
            started.elapsed().as_secs_f64(),
            timing(&ctx, "rays_per_second")
        );
    }

    // Rendering.
    let btf_res: u32 = arg("--btf-res", 64);
    let (w, h): (u32, u32) = (arg("--width", 800), arg("--height", 600));
    let frames: u32 = arg("--frames", 5);
    let tile = weave(btf_res, 6.0);
    let dirs = r#"{"thetas": [0, 20, 40, 60, 80], "phis": [0, 45, 90, 135, 180, 225, 270, 315]}"#;
    let cp: capture::Params = serde_json::from_str(&format!(
        r#"{{"views": {dirs}, "lights": {dirs}, "brdf": "ward", "albedo": [0.62, 0.42, 0.22]}}"#
    ))
    .unwrap();
    let btf = port(
        &|| {
            capture::Capture
                .run(&quiet, &cp, &Inputs::new().with("height", tile.clone()))
                .unwrap()
        },
        "btf",
    );
    let basis = |rank: u32| {
        let p: pca::Params =
            serde_json::from_str(&format!(r#"{{"rank": {rank}, "solver": "randomized"}}"#))
                .unwrap();
        port(
            &|| {
                pca::Pca
                    .run(&quiet, &p, &Inputs::new().with("btf", btf.clone()))
                    .unwrap()
            },
            "basis",
        )
    };
    let mp: tabulate::Params = serde_json::from_str(
        r#"{"views": {"thetas": [0, 15, 30, 45, 60, 70, 80, 85, 88], "phis": [0, 30, 60, 90, 120, 150, 180, 210, 240, 270, 300, 330]}}"#,
    )
    .unwrap();
    let mdf = port(
        &|| {
            tabulate::Tabulate
                .run(&quiet, &mp, &Inputs::new().with("height", tile.clone()))
                .unwrap()
        },
        "mdf",
    );
    let mesh_p = primitive::Params {
        shape: primitive::Shape::Torus,
        size: 0.9,
        minor: 0.38,
        segments: [96, 48],
    };
    let mesh: ValueRef = Arc::new(primitive::build(&mesh_p).unwrap());
    let (b8, b16, b32) = (basis(8), basis(16), basis(32));
    let cases: Vec<(&str, ValueRef, bool, bool)> = vec![
        ("BTF raw", btf.clone(), false, false),
        ("BTF PCA rank 8", b8, false, false),
        ("BTF PCA rank 16", b16.clone(), false, false),
        ("BTF PCA rank 32", b32, false, false),
        ("BTF raw + MDF", btf.clone(), true, false),
        ("BTF PCA 16 + MDF", b16.clone(), true, false),
        ("BTF raw + MDF + shadows", btf.clone(), true, true),
        ("BTF PCA 16 + MDF + shadows", b16, true, true),
    ];
    println!(
        "\n| render.mesh torus {w}×{h} | {} |",
        devices
            .iter()
            .map(|d| format!("{} ms (fps)", d.0))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!("|---|{}", "---|".repeat(devices.len()));
    for (name, material, with_mdf, shadows) in cases {
        let mut cells = Vec::new();
        for (_, g) in &devices {
            let ctx = NodeContext::detached(g.clone());
            let mut p: render_mesh::Params = serde_json::from_str(&format!(
                r#"{{"camera": {{"eye": [0.0, 1.5, 2.7], "target": [0.0, -0.1, 0.0], "fov": 42, "resolution": [{w}, {h}]}},
                    "tiling": [12, 5], "shell": 0.1}}"#
            ))
            .unwrap();
            p.use_mdf = with_mdf;
            p.shadows = shadows;
            // The CPU path is the reference, not a real-time renderer: one frame is enough.
            p.frames = if g.is_some() { frames } else { 1 };
            let inputs = Inputs::new()
                .with("mesh", mesh.clone())
                .with("btf", material.clone())
                .with("mdf", mdf.clone());
            RenderMesh.run(&ctx, &p, &inputs).unwrap();
            let ms = timing(&ctx, "frame_ms");
            let gpu_ms = timing(&ctx, "gpu_ms");
            cells.push(if g.is_some() {
                format!("{ms:.1} ({:.2}); GPU {gpu_ms:.1}", 1e3 / ms)
            } else {
                format!("{ms:.1} ({:.2})", 1e3 / ms)
            });
        }
        println!("| {name} | {} |", cells.join(" | "));
    }
}
