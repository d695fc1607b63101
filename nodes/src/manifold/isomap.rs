//! `manifold.isomap`: Isomap (Tenenbaum et al. 2000) — geodesic distances by shortest paths
//! over the kNN graph, then classical MDS of B = −½ H D² H (H the centring matrix), the top
//! eigenvectors scaled by √λ. With `landmarks` = m > 0, landmark Isomap (de Silva & Tenenbaum
//! 2003): m landmarks drawn with a seed, shortest paths from them only, MDS of the landmarks,
//! and every point placed by distance-based triangulation y = −½ L♯ (δ − δ̄).
//!
//! A disconnected graph is joined as scikit-learn does (each pair of components by its closest
//! pair of points) with a warning. `reconstruction_error` is scikit-learn's:
//! √(‖B‖²_F − Σ λ²) / n over the kept components (on the landmarks' kernel with landmarks);
//! `residual_variance` is Tenenbaum's 1 − R² between geodesic and embedded distances.

use super::eigen;
use super::graph::Graph;
use crate::support::progress::Counter;
use crate::support::rng;
use crate::types::{Embedding, KnnGraph, PointSet};
use faer::{Mat, MatRef};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::Instant;

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Embedding dimensions.
    #[schemars(range(min = 1))]
    pub components: u32,
    /// Landmarks for landmark Isomap; 0 = all points (exact Isomap).
    pub landmarks: u32,
    /// Seed of the landmark choice.
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            components: 2,
            landmarks: 0,
            seed: 1,
        }
    }
}

pub struct Isomap;

impl Node for Isomap {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "manifold.isomap",
            version: 1,
            doc: "Isomap: geodesic distances over the kNN graph (components joined with a warning), classical MDS via faer; landmark Isomap with `landmarks`.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("points", PointSet::TYPE, "the points (to join components)"),
                Port::input("graph", KnnGraph::TYPE, "their kNN graph"),
            ],
            outputs: vec![
                Port::output("embedding", Embedding::TYPE, "n × components"),
                Port::output("reconstruction_error", "Scalar", "scikit-learn's reconstruction error"),
                Port::output("residual_variance", "Scalar", "1 − R² of geodesic vs embedded distances"),
                Port::output("graph_components", "Scalar", "connected components before joining"),
            ],
            disk_cache: true,
        }
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            ("paths_seconds", "time in shortest paths, s"),
            ("mds_seconds", "time in the MDS and placement, s"),
        ]
    }
    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let points = inputs.get::<PointSet>("points")?;
        let graph = inputs.get::<KnnGraph>("graph")?;
        if graph.n != points.n {
            return Err(NodeError::input(
                "graph",
                format!("{} vertices for {} points", graph.n, points.n),
            ));
        }
        let r = isomap_with(points, graph, p, &Counter::new(ctx, 0))?;
        for w in &r.warnings {
            ctx.warn(w.clone());
        }
        ctx.timing("paths_seconds", r.paths_seconds);
        ctx.timing("mds_seconds", r.mds_seconds);
        Ok(Outputs::new()
            .with("embedding", r.embedding)
            .with("reconstruction_error", Scalar(r.reconstruction_error))
            .with("residual_variance", Scalar(r.residual_variance))
            .with("graph_components", Scalar(r.graph_components as f64)))
    }
}

pub struct Isomapped {
    pub embedding: Embedding,
    pub reconstruction_error: f64,
    pub residual_variance: f64,
    pub graph_components: usize,
    pub warnings: Vec<String>,
    /// Seconds in the shortest paths and in the MDS (kernel, eigenpairs, placement).
    pub paths_seconds: f64,
    pub mds_seconds: f64,
}

/// Shortest-path rows from each source, in parallel, in source order.
/// One Dijkstra per source, counted on `watch`; once it is stopped the remaining searches are
/// skipped (empty rows: the caller returns `Cancelled`).
fn geodesics(g: &Graph, sources: &[usize], watch: &Counter) -> Vec<Vec<f64>> {
    let c = g.compact();
    sources
        .par_iter()
        .map_init(crate::manifold::graph::Heap::new, |heap, &s| {
            if watch.stopped() {
                return Vec::new();
            }
            let row = c.dijkstra_with(&[s], heap);
            watch.add(1);
            row
        })
        .collect()
}

/// Double centring of −½ D² for the m × m landmark distances, column-major (column j is
/// landmark j's own search, read contiguously). Columns run in parallel; each column's sum is
/// its own, so the result does not depend on the thread count. The two directions of a path
/// may round differently: the eigensolvers read the matrix as symmetric (faer's lower
/// triangle; subspace iteration symmetrises its small projection), and column means stand for
/// row means.
fn kernel(rows: &[Vec<f64>], landmarks: &[usize]) -> Vec<f64> {
    let m = landmarks.len();
    let mut b = vec![0.0; m * m];
    let mean: Vec<f64> = b
        .par_chunks_mut(m)
        .zip(rows)
        .map(|(col, row)| {
            let mut s = 0.0;
            for (v, &l) in col.iter_mut().zip(landmarks) {
                *v = -0.5 * row[l] * row[l];
                s += *v;
            }
            s / m as f64
        })
        .collect();
    let all = mean.iter().sum::<f64>() / m as f64;
    b.par_chunks_mut(m).zip(&mean).for_each(|(col, mj)| {
        for (v, mi) in col.iter_mut().zip(&mean) {
            *v += all - mi - mj;
        }
    });
    b
}

pub fn isomap(points: &PointSet, knn: &KnnGraph, p: &Params) -> Result<Isomapped, NodeError> {
    isomap_with(points, knn, p, &Counter::none())
}

/// [`isomap`] with progress (one unit per shortest-path search) and cancellation.
pub fn isomap_with(
    points: &PointSet,
    knn: &KnnGraph,
    p: &Params,
    watch: &Counter,
) -> Result<Isomapped, NodeError> {
    let n = points.n;
    let k = p.components as usize;
    if k == 0 || k >= n {
        return Err(NodeError::param(
            "components",
            format!("{k} components of {n} points: need 1 ≤ components < n"),
        ));
    }
    let mut warnings = Vec::new();
    let mut g = Graph::from_knn(knn);
    let graph_components = g.join_components(points);
    if graph_components > 1 {
        warnings.push(format!(
            "the kNN graph (k = {}) has {graph_components} connected components; joined each pair by its closest points as scikit-learn does — raise k for a connected graph",
            knn.k
        ));
    }
    let m = match p.landmarks as usize {
        0 => n,
        l if l >= n => n,
        l if l <= k => {
            return Err(NodeError::param(
                "landmarks",
                format!("{l} landmarks cannot span {k} components: need more than {k}"),
            ))
        }
        l => l,
    };
    // Geodesic rows (m × n f64), the m × m kernel and the eigensolver's copy of it.
    let (mu, nu) = (m as u64, n as u64);
    let bytes = crate::support::memory::product(&[mu, nu, 8])
        .saturating_add(crate::support::memory::product(&[2, mu, mu, 8]));
    crate::support::memory::check_param(
        bytes,
        &format!("Isomap of {n} points with {m} landmarks (all points without `landmarks`)"),
        "landmarks",
    )?;
    let landmarks: Vec<usize> = if m == n {
        (0..n).collect()
    } else {
        // A seeded random subset, in index order (de Silva & Tenenbaum: random is adequate).
        let mut order: Vec<(u64, usize)> = (0..n)
            .map(|i| (rng::hash(p.seed, &[i as u64]), i))
            .collect();
        order.sort_unstable();
        let mut chosen: Vec<usize> = order[..m].iter().map(|e| e.1).collect();
        chosen.sort_unstable();
        chosen
    };
    let t0 = Instant::now();
    watch.grow(landmarks.len() as u64);
    let rows = geodesics(&g, &landmarks, watch);
    if watch.stopped() {
        return Err(NodeError::Cancelled);
    }
    let paths_seconds = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let b = kernel(&rows, &landmarks);
    let (vals, vecs) =
        eigen::top(MatRef::from_column_major_slice(&b, m, m), k).map_err(NodeError::Failed)?;
    if let Some(c) = vals
        .iter()
        .position(|v| *v <= 1e-12 * vals[0].abs().max(1e-300))
    {
        warnings.push(format!(
            "component {c} has a non-positive eigenvalue ({:.3e}): the geodesic distances do not support {k} dimensions (the embedding is degenerate there; k may be short-circuiting the manifold)",
            vals[c]
        ));
    }
    let sqrt: Vec<f64> = vals.iter().map(|v| v.max(0.0).sqrt()).collect();
    let mut data = vec![0.0; n * k];
    if m == n {
        for i in 0..n {
            for c in 0..k {
                data[i * k + c] = vecs[(i, c)] * sqrt[c];
            }
        }
    } else {
        // Triangulation: y_i = −½ L♯ (δ_i − δ̄), L♯ rows v_c / √λ_c, δ squared distances to the
        // landmarks, δ̄ their mean over the landmarks.
        let mean: Vec<f64> = rows
            .par_iter()
            .map(|row| landmarks.iter().map(|&l| row[l] * row[l]).sum::<f64>() / m as f64)
            .collect();
        let scale: Vec<f64> = sqrt
            .iter()
            .map(|s| if *s > 0.0 { -0.5 / s } else { 0.0 })
            .collect();
        // Chunks of points in parallel; inside, landmark by landmark so each search's row is
        // read contiguously. The sum over landmarks runs in landmark order for every point.
        data.par_chunks_mut(4096 * k)
            .enumerate()
            .for_each(|(chunk, out)| {
                let first = chunk * 4096;
                let count = out.len() / k;
                for (j, row) in rows.iter().enumerate() {
                    for t in 0..count {
                        let r = row[first + t];
                        let delta = r * r - mean[j];
                        for c in 0..k {
                            out[t * k + c] += vecs[(j, c)] * delta;
                        }
                    }
                }
                for t in 0..count {
                    for c in 0..k {
                        out[t * k + c] *= scale[c];
                    }
                }
            });
    }
    // A sign per component, so the output does not depend on the eigensolver's: the entry of
    // largest magnitude is positive.
    for c in 0..k {
        let big =
            (0..n)
                .map(|i| data[i * k + c])
                .fold(0.0f64, |a, v| if v.abs() > a.abs() { v } else { a });
        if big < 0.0 {
            for i in 0..n {
                data[i * k + c] = -data[i * k + c];
            }
        }
    }
    let mds_seconds = t1.elapsed().as_secs_f64();
    // Per-column sums in parallel, added in column order: the same bits for any thread count.
    let norm2: f64 = b
        .par_chunks(m)
        .map(|col| col.iter().map(|v| v * v).sum::<f64>())
        .collect::<Vec<f64>>()
        .iter()
        .sum();
    let kept: f64 = vals.iter().map(|v| v * v).sum();
    let reconstruction_error = (norm2 - kept).max(0.0).sqrt() / m as f64;
    let residual_variance = residual_variance(&rows, &landmarks, &data, k);
    Ok(Isomapped {
        embedding: Embedding {
            n,
            components: k,
            data,
            eigenvalues: vals,
        },
        reconstruction_error,
        residual_variance,
        graph_components,
        warnings,
        paths_seconds,
        mds_seconds,
    })
}

/// 1 − R² (Pearson, squared) between geodesic and embedded distances over landmark pairs.
/// Sums per landmark in parallel, combined in landmark order (thread-count independent).
fn residual_variance(rows: &[Vec<f64>], landmarks: &[usize], y: &[f64], k: usize) -> f64 {
    let sums: Vec<[f64; 6]> = (0..landmarks.len())
        .into_par_iter()
        .map(|b| {
            let mut s = [0.0; 6];
            let j = landmarks[b];
            for &i in &landmarks[..b] {
                let x = rows[b][i];
                let yd = (0..k)
                    .map(|c| (y[i * k + c] - y[j * k + c]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                for (t, v) in s.iter_mut().zip([x, yd, x * x, yd * yd, x * yd, 1.0]) {
                    *t += v;
                }
            }
            s
        })
        .collect();
    let mut t = [0.0; 6];
    for s in &sums {
        for (a, b) in t.iter_mut().zip(s) {
            *a += b;
        }
    }
    let [sx, sy, sxx, syy, sxy, count] = t;
    if count == 0.0 {
        return 1.0;
    }
    let cov = sxy / count - sx / count * sy / count;
    let vx = sxx / count - (sx / count).powi(2);
    let vy = syy / count - (sy / count).powi(2);
    if vx <= 0.0 || vy <= 0.0 {
        return 1.0;
    }
    1.0 - cov * cov / (vx * vy)
}

/// scipy's Procrustes disparity: both sets centred and scaled to unit Frobenius norm, the best
/// rotation (and reflection) applied; 1 − (Σ singular values of AᵀB)².
pub fn procrustes(a: &[f64], b: &[f64], k: usize) -> f64 {
    let n = a.len() / k;
    let standard = |x: &[f64]| {
        let mean: Vec<f64> = (0..k)
            .map(|c| (0..n).map(|i| x[i * k + c]).sum::<f64>() / n as f64)
            .collect();
        let centred: Vec<f64> = (0..n * k).map(|t| x[t] - mean[t % k]).collect();
        let norm = centred
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt()
            .max(1e-300);
        centred.iter().map(|v| v / norm).collect::<Vec<f64>>()
    };
    let (sa, sb) = (standard(a), standard(b));
    let m = Mat::<f64>::from_fn(k, k, |r, c| {
        (0..n).map(|i| sa[i * k + r] * sb[i * k + c]).sum()
    });
    let svd = m.thin_svd().expect("a k × k SVD converges");
    let trace: f64 = (0..k).map(|i| svd.S().column_vector()[i]).sum();
    1.0 - trace * trace
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifold::knn::knn;

    fn grid(side: usize, noise: f64) -> PointSet {
        let data = (0..side * side)
            .flat_map(|i| {
                let (x, y) = ((i % side) as f64, (i / side) as f64);
                let e = |s: u64| noise * (rng::unit(rng::hash(s, &[i as u64])) - 0.5);
                [x + e(1), y + e(2)]
            })
            .collect();
        PointSet {
            n: side * side,
            dims: 2,
            data,
        }
    }

    fn dist(p: &[f64], i: usize, j: usize, d: usize) -> f64 {
        (0..d)
            .map(|c| (p[i * d + c] - p[j * d + c]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    #[test]
    fn a_complete_graph_on_a_grid_is_embedded_isometrically() {
        // scikit-learn's test_isomap_simple_grid, re-derived: with k = n − 1 every geodesic is
        // the Euclidean distance, and classical MDS of a planar Euclidean configuration is exact.
        let x = grid(5, 0.0);
        let r = isomap(&x, &knn(&x, 24).unwrap(), &Params::default()).unwrap();
        for i in 0..25 {
            for j in 0..25 {
                let (a, b) = (dist(&x.data, i, j, 2), dist(&r.embedding.data, i, j, 2));
                assert!((a - b).abs() < 1e-9, "{i} {j}: {a} vs {b}");
            }
        }
        // The error is √(‖B‖² − Σλ²)/n: a difference of two sums of ~10⁴ that rounds to
        // ~1e-12 of them, so √(1e-12 · 10⁴)/25 ≈ 4e-6 is as close to 0 as it can show.
        assert!(
            r.reconstruction_error < 1e-5 && r.residual_variance < 1e-12,
            "{} {}",
            r.reconstruction_error,
            r.residual_variance
        );
    }

    /// Floyd–Warshall, independent of the Dijkstra under test.
    fn floyd(x: &PointSet, k: usize) -> Vec<f64> {
        let g = knn(x, k).unwrap();
        let n = x.n;
        let mut d = vec![f64::INFINITY; n * n];
        for i in 0..n {
            d[i * n + i] = 0.0;
            for s in 0..k {
                let j = g.neighbors[i * k + s] as usize;
                let e = g.distances[i * k + s];
                d[i * n + j] = d[i * n + j].min(e);
                d[j * n + i] = d[j * n + i].min(e);
            }
        }
        for m in 0..n {
            for i in 0..n {
                for j in 0..n {
                    let via = d[i * n + m] + d[m * n + j];
                    if via < d[i * n + j] {
                        d[i * n + j] = via;
                    }
                }
            }
        }
        d
    }

    #[test]
    fn the_reconstruction_error_is_the_kernel_distance_of_the_embedding() {
        // scikit-learn's test_isomap_reconstruction_error, re-derived: with K the centred
        // −½G² of the geodesics (here by Floyd–Warshall) and K_iso that of the embedding's own
        // distances, the error is ‖K − K_iso‖_F / n.
        let x = grid(6, 0.3);
        let k = 5;
        let r = isomap(&x, &knn(&x, k).unwrap(), &Params::default()).unwrap();
        let n = x.n;
        let g = floyd(&x, k);
        // −½ H D² H with H = I − 11ᵀ/n, as products of dense matrices (not the node's code).
        let h = Mat::<f64>::from_fn(n, n, |i, j| (i == j) as u8 as f64 - 1.0 / n as f64);
        let center = |f: &dyn Fn(usize, usize) -> f64| {
            let d2 = Mat::<f64>::from_fn(n, n, |i, j| -0.5 * f(i, j) * f(i, j));
            &h * &d2 * &h
        };
        let kg = center(&|i, j| g[i * n + j]);
        let ky = center(&|i, j| dist(&r.embedding.data, i, j, 2));
        let diff: f64 = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| (kg[(i, j)] - ky[(i, j)]).powi(2))
            .sum();
        let want = diff.sqrt() / n as f64;
        assert!(
            (r.reconstruction_error - want).abs() < 1e-9 * want.max(1.0),
            "{} vs {want}",
            r.reconstruction_error
        );
    }

    #[test]
    fn the_same_bits_whatever_the_thread_count() {
        // Landmark Isomap on 900 points uses every parallel stage (paths, kernel, placement,
        // the fixed-order sums).
        let x = grid(30, 0.2);
        let p = Params {
            landmarks: 300,
            ..Params::default()
        };
        let run = |threads| {
            mesoflow_testkit::threads::with_threads(threads, || {
                isomap(&x, &knn(&x, 8).unwrap(), &p).unwrap()
            })
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.embedding.data, b.embedding.data);
        assert_eq!(
            a.reconstruction_error.to_bits(),
            b.reconstruction_error.to_bits()
        );
        assert_eq!(a.residual_variance.to_bits(), b.residual_variance.to_bits());
    }

    #[test]
    fn two_components_are_joined_with_a_warning() {
        // scikit-learn's test_isomap_fit_precomputed / connected-components warning: X = [0, 1,
        // 2, 5, 6, 7], k = 2. Joined at 2–5, the line is embedded as itself (up to a shift).
        let x = PointSet {
            n: 6,
            dims: 1,
            data: vec![0.0, 1.0, 2.0, 5.0, 6.0, 7.0],
        };
        let p = Params {
            components: 1,
            ..Default::default()
        };
        let r = isomap(&x, &knn(&x, 2).unwrap(), &p).unwrap();
        assert_eq!(r.graph_components, 2);
        assert!(
            r.warnings
                .iter()
                .any(|w| w.contains("2 connected components")),
            "{:?}",
            r.warnings
        );
        let y = &r.embedding.data;
        for i in 0..6 {
            assert!(((y[i] - y[0]).abs() - x.data[i]).abs() < 1e-9, "{y:?}");
        }
    }

    #[test]
    fn too_large_a_k_short_circuits_and_the_metrics_show_it() {
        // A swiss roll of 1500 points: with k = 10 the graph follows the sheet, the residual variance is small
        // and the first component orders the roll by its angle; with k = 300 the graph
        // jumps across the layers, the geodesics become straight-line distances through the
        // roll, and both measures degrade. Bounds from the geometry, with margin: a faithful
        // 2-D embedding of the unrolled sheet has residual variance near 0 (< 0.02) and
        // |Spearman| ≈ 1 (> 0.99); short-circuited, the residual variance is at least 5× larger
        // and |Spearman| drops below 0.95.
        use crate::manifold::rank::spearman;
        use crate::points::synthetic::{generate, Params as Synth};
        let (x, truth) = generate(&Synth {
            n: 1500,
            ..Synth::default()
        });
        let angle: Vec<f64> = (0..1500).map(|i| truth.data[i * truth.dims]).collect();
        let run = |k: usize| {
            let r = isomap(&x, &knn(&x, k).unwrap(), &Params::default()).unwrap();
            let first: Vec<f64> = (0..1500).map(|i| r.embedding.data[i * 2]).collect();
            (r.residual_variance, spearman(&first, &angle).abs())
        };
        let (rv_good, rho_good) = run(10);
        let (rv_short, rho_short) = run(300);
        eprintln!("k = 10: {rv_good}, {rho_good}; k = 300: {rv_short}, {rho_short}");
        assert!(
            rv_good < 0.02 && rho_good > 0.99,
            "k = 10: {rv_good}, {rho_good}"
        );
        assert!(
            rv_short > 5.0 * rv_good && rho_short < 0.95,
            "k = 300: {rv_short}, {rho_short}"
        );
    }

    #[test]
    fn a_degenerate_embedding_is_warned_about() {
        // Points on a line with every pair joined: the distances are exactly one-dimensional,
        // so a second component has eigenvalue 0 (to rounding) and the report must say so.
        let x = PointSet {
            n: 12,
            dims: 1,
            data: (0..12).map(|i| i as f64 * 0.5).collect(),
        };
        let r = isomap(&x, &knn(&x, 11).unwrap(), &Params::default()).unwrap();
        assert!(
            r.warnings
                .iter()
                .any(|w| w.contains("non-positive eigenvalue")),
            "{:?}",
            r.warnings
        );
        assert!(r.embedding.data.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn landmark_isomap_agrees_with_isomap() {
        // 2000 points of a rolled sheet in 3-D; 200 landmarks against all 2000. The bound: the
        // triangulation is exact for points whose geodesics the landmark MDS reproduces, so the
        // disparity is the landmarks' own embedding error (measured 1e-5 scale); 1e-3 allows it.
        let n = 2000;
        let data: Vec<f64> = (0..n)
            .flat_map(|i| {
                let (u, v) = (rng::unit(rng::hash(3, &[i])), rng::unit(rng::hash(4, &[i])));
                let t = 1.5 * std::f64::consts::PI * (1.0 + 2.0 * u);
                [t * t.cos(), 21.0 * v, t * t.sin()]
            })
            .collect();
        let x = PointSet {
            n: n as usize,
            dims: 3,
            data,
        };
        let g = knn(&x, 10).unwrap();
        let full = isomap(&x, &g, &Params::default()).unwrap();
        let land = isomap(
            &x,
            &g,
            &Params {
                landmarks: 200,
                ..Default::default()
            },
        )
        .unwrap();
        let d = procrustes(&full.embedding.data, &land.embedding.data, 2);
        eprintln!("Procrustes disparity, 200 landmarks vs all: {d:.2e}");
        assert!(d < 1e-3, "{d}");
    }
}
