//! Isomap timings against scikit-learn (`cargo bench --bench manifold -- [--n 5000] [--k 10]
//! [--landmark-n 250000] [--landmarks 1000] [--no-peer]`).
//!
//! 1. `--n` points of an S-curve sheet in 3-D (seeded), written to NPY; mesoflow's kNN + Isomap
//!    (best of 3), then `benches/isomap_peer.py` (scikit-learn's `Isomap`, best of 3) on the same
//!    file in the same session; the Procrustes disparity between the two embeddings and both
//!    reconstruction errors.
//! 2. Landmark Isomap on `--landmark-n` points with `--landmarks` landmarks: seconds per stage.
//! 3. With `--crossover`: brute force against the k-d tree for kNN, 3-D and 5-D points (5-D:
//!    appearance vectors), best of 3 each — where `knn::TREE_FROM` comes from.

use mesoflow_nodes::manifold::{isomap, knn};
use mesoflow_nodes::support::rng;
use mesoflow_nodes::types::PointSet;
use std::time::Instant;

use mesoflow_testkit::args::arg;

/// scikit-learn's `make_s_curve` shape, from our own seeded randomness.
fn s_curve(n: usize) -> PointSet {
    let data = (0..n as u64)
        .flat_map(|i| {
            let t = 3.0 * std::f64::consts::PI * (rng::unit(rng::hash(11, &[i])) - 0.5);
            let y = 2.0 * rng::unit(rng::hash(12, &[i]));
            [t.sin(), y, t.signum() * (t.cos() - 1.0)]
        })
        .collect();
    PointSet { n, dims: 3, data }
}

fn main() {
    let n: usize = arg("--n", 5000);
    let k: usize = arg("--k", 10);
    let x = s_curve(n);
    let dir = std::env::temp_dir().join("mesoflow_isomap_bench");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("points.npy");
    std::fs::write(
        &path,
        mesoflow_nodes::support::formats::encode_npy(&[n, 3], &x.data).expect("npy"),
    )
    .expect("write");
    let p = isomap::Params::default();
    let mut best = (f64::INFINITY, 0.0, 0.0, 0.0, 0.0);
    let mut ours = None;
    for _ in 0..3 {
        let start = Instant::now();
        let g = knn::knn(&x, k).expect("knn");
        let t_knn = start.elapsed().as_secs_f64();
        let r = isomap::isomap(&x, &g, &p).expect("isomap");
        let total = start.elapsed().as_secs_f64();
        if total < best.0 {
            best = (
                total,
                t_knn,
                r.reconstruction_error,
                r.paths_seconds,
                r.mds_seconds,
            );
        }
        ours = Some(r.embedding.data);
    }
    let ours = ours.expect("ran");
    println!(
        "mesoflow: {n} points, k = {k}: {:.3} s (kNN {:.3} s, paths {:.3} s, MDS {:.3} s); reconstruction_error {:.6e}",
        best.0, best.1, best.3, best.4, best.2
    );
    if !std::env::args().any(|a| a == "--no-peer") {
        let out = dir.join("sklearn.npy");
        let run = std::process::Command::new("python3")
            .args([
                "benches/isomap_peer.py",
                &path.display().to_string(),
                "--k",
                &k.to_string(),
                "--out",
                &out.display().to_string(),
            ])
            .output();
        match run {
            Ok(o) if o.status.success() => {
                print!("{}", String::from_utf8_lossy(&o.stdout));
                let theirs = mesoflow_nodes::points::read::read(&out).expect("sklearn npy");
                println!(
                    "Procrustes disparity mesoflow vs scikit-learn: {:.3e}",
                    isomap::procrustes(&ours, &theirs.data, 2)
                );
            }
            Ok(o) => println!("peer failed: {}", String::from_utf8_lossy(&o.stderr)),
            Err(e) => println!("peer not run: {e}"),
        }
    }
    if std::env::args().any(|a| a == "--crossover") {
        crossover(k);
    }
    let big: usize = arg("--landmark-n", 250_000);
    if big > 0 {
        let landmarks: u32 = arg("--landmarks", 1000);
        let x = s_curve(big);
        let start = Instant::now();
        let g = knn::knn(&x, k).expect("knn");
        let t_knn = start.elapsed().as_secs_f64();
        let r = isomap::isomap(
            &x,
            &g,
            &isomap::Params {
                landmarks,
                ..Default::default()
            },
        )
        .expect("landmark isomap");
        println!(
            "landmark Isomap: {big} points, {landmarks} landmarks: {:.3} s (kNN {:.3} s, paths {:.3} s, MDS + placement {:.3} s); residual variance {:.3e}",
            start.elapsed().as_secs_f64(),
            t_knn,
            r.paths_seconds,
            r.mds_seconds,
            r.residual_variance
        );
    }
}

/// Brute force against the k-d tree at growing n, best of 3.
fn crossover(k: usize) {
    use mesoflow_nodes::manifold::kdtree::KdTree;
    use rayon::prelude::*;
    for dims in [3usize, 5] {
        for n in [250usize, 500, 1000, 2000, 4000, 8000] {
            let data: Vec<f64> = (0..(n * dims) as u64)
                .map(|i| rng::unit(rng::hash(21, &[i])))
                .collect();
            let x = PointSet { n, dims, data };
            let best = |f: &dyn Fn()| {
                (0..3)
                    .map(|_| {
                        let t = Instant::now();
                        f();
                        t.elapsed().as_secs_f64()
                    })
                    .fold(f64::INFINITY, f64::min)
            };
            let brute = best(&|| {
                std::hint::black_box(knn::brute(&x, k));
            });
            let tree = best(&|| {
                let t = KdTree::build(&x);
                let rows: Vec<_> = (0..n)
                    .into_par_iter()
                    .map(|i| t.nearest(&x, i, k))
                    .collect();
                std::hint::black_box(rows);
            });
            println!(
                "kNN {dims}-D uniform, n = {n}, k = {k}: brute {brute:.5} s, k-d tree {tree:.5} s"
            );
        }
    }
}
