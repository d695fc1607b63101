//! `image.flip` against NVIDIA's `flip-evaluator` on the same 512 × 512 pair, same machine: a
//! scikit-image photograph (the astronaut) against its Gaussian blur (σ = 1.5 px), LDR and HDR,
//! median of five runs each. The peer runs from `target/peer-venv` (or `MESOFLOW_PEER_PYTHON`);
//! without it the bench says so and stops. `--size W×H` (e.g. `1920x1080`) scales the photograph
//! to that size first (bilinear), then blurs it.
//!
//! `cargo bench --bench flip [-- --size 1920x1080]`

use mesoflow_nodes::image::flip::{evaluate, Mode, Params};
use mesoflow_nodes::types::{srgb_to_linear, Image};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const PEER: &str = r#"
import sys, time, numpy as np, flip_evaluator as flip
from skimage import data
from scipy.ndimage import gaussian_filter
from skimage.transform import resize
a = data.astronaut().astype(np.float32) / 255
w, h = int(sys.argv[2]), int(sys.argv[3])
if (w, h) != (512, 512):
    a = resize(a, (h, w, 3), order=1, anti_aliasing=False).astype(np.float32)
b = gaussian_filter(a, (1.5, 1.5, 0))
np.save(sys.argv[1] + "/a.npy", a); np.save(sys.argv[1] + "/b.npy", b)
for mode in ["LDR", "HDR"]:
    ts = []
    for _ in range(5):
        t = time.perf_counter(); _, mean, _ = flip.evaluate(a, b, mode, applyMagma=False); ts.append(time.perf_counter() - t)
    print(mode, sorted(ts)[2], mean)
"#;

/// The peer takes LDR images sRGB-encoded and HDR ones linear: decode for LDR only.
fn read(path: &Path, decode: bool) -> Image {
    let bytes = std::fs::read(path).expect("npy written by the peer script");
    let npy = npyz::NpyFile::new(&bytes[..]).expect("npy");
    let shape: Vec<usize> = npy.shape().iter().map(|d| *d as usize).collect();
    let data: Vec<f32> = npy.into_vec().expect("f32 npy");
    Image {
        width: shape[1],
        height: shape[0],
        channels: shape[2],
        data: if decode {
            data.into_iter().map(srgb_to_linear).collect()
        } else {
            data
        },
    }
}

fn main() {
    let python = std::env::var_os("MESOFLOW_PEER_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("target/peer-venv/bin/python")
        });
    let size: String = mesoflow_testkit::args::arg("--size", "512x512".to_string());
    let (w, h) = size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .expect("--size W x H, e.g. 1920x1080");
    let dir = tempfile::tempdir().expect("temp dir");
    let peer = Command::new(&python)
        .args([
            "-c",
            PEER,
            dir.path().to_str().unwrap(),
            &w.to_string(),
            &h.to_string(),
        ])
        .output();
    let Some(peer) = peer.ok().filter(|o| o.status.success()) else {
        eprintln!(
            "no peer Python at {} (flip-evaluator, scikit-image, scipy); run .ci/run once",
            python.display()
        );
        return;
    };
    let text = String::from_utf8_lossy(&peer.stdout);
    println!(
        "mode  mesoflow_s  flip_evaluator_s  peer/ours  mesoflow_mean  flip_evaluator_mean  ({w}×{h}, {} threads)",
        rayon::current_num_threads()
    );
    for (mode, line) in [Mode::Ldr, Mode::Hdr].into_iter().zip(text.lines()) {
        let decode = mode == Mode::Ldr;
        let (a, b) = (
            read(&dir.path().join("a.npy"), decode),
            read(&dir.path().join("b.npy"), decode),
        );
        let p = Params {
            mode,
            ..Default::default()
        };
        let mut ts = Vec::new();
        let mut mean = 0.0;
        for _ in 0..5 {
            let t = Instant::now();
            mean = evaluate(&a, &b, None, &p, |_, _| {})
                .expect("flip")
                .stats
                .mean;
            ts.push(t.elapsed().as_secs_f64());
        }
        ts.sort_by(f64::total_cmp);
        let f: Vec<&str> = line.split_whitespace().collect();
        let peer_s: f64 = f[1].parse().unwrap_or(f64::NAN);
        println!(
            "{:4}  {:10.4}  {:16}  {:9.2}  {:13.6}  {}",
            f[0],
            ts[2],
            f[1],
            peer_s / ts[2],
            mean,
            f[2]
        );
    }
}
