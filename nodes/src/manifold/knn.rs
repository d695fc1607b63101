//! `manifold.knn`: the exact k-nearest-neighbour graph of a point set (Euclidean), with ties
//! broken by index, so the graph is the same whatever the thread count or method: brute force on
//! rayon for small sets, a k-d tree (built once, queried in parallel) from `TREE_FROM` points on,
//! where brute force's n² distances dominate (BENCHMARKS.md has the crossover).
//!
//! Appearance vectors are compared as given: the caller weights and normalises them (per-pixel
//! BRDF parameters are put on comparable scales by the node that builds them).

use crate::types::{KnnGraph, PointSet};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Neighbours per point.
    #[schemars(range(min = 1))]
    pub k: u32,
}

impl Default for Params {
    fn default() -> Self {
        Params { k: 10 }
    }
}

pub struct Knn;

impl Node for Knn {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "manifold.knn",
            version: 1,
            doc:
                "Exact k-nearest-neighbour graph (Euclidean, ties by index), brute force on rayon.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("points", PointSet::TYPE, "the points")],
            outputs: vec![Port::output(
                "graph",
                KnnGraph::TYPE,
                "each point's k nearest others",
            )],
            disk_cache: true,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let points = inputs.get::<PointSet>("points")?;
        let graph = knn(points, p.k as usize).map_err(|m| NodeError::param("k", m))?;
        Ok(Outputs::new().with("graph", graph))
    }
}

/// From this many points on, the k-d tree (measured: it is 2–24× faster than brute force from
/// 500 points on in 3-D and 5-D, even at 250; BENCHMARKS.md).
pub const TREE_FROM: usize = 256;

pub fn knn(points: &PointSet, k: usize) -> Result<KnnGraph, String> {
    let n = points.n;
    if k == 0 || k >= n {
        return Err(format!("{k} neighbours of {n} points: need 1 ≤ k < n"));
    }
    if n >= TREE_FROM {
        let tree = super::kdtree::KdTree::build(points);
        let rows: Vec<(Vec<u32>, Vec<f64>)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let found = tree.nearest(points, i, k);
                (
                    found.iter().map(|e| e.1).collect(),
                    found.iter().map(|e| e.0.sqrt()).collect(),
                )
            })
            .collect();
        return Ok(assemble(n, k, rows));
    }
    Ok(assemble(n, k, brute(points, k)))
}

fn assemble(n: usize, k: usize, rows: Vec<(Vec<u32>, Vec<f64>)>) -> KnnGraph {
    let mut graph = KnnGraph {
        n,
        k,
        neighbors: Vec::with_capacity(n * k),
        distances: Vec::with_capacity(n * k),
    };
    for (nb, dist) in rows {
        graph.neighbors.extend(nb);
        graph.distances.extend(dist);
    }
    graph
}

/// Each point's k nearest others by brute force: (indices, distances), nearest first.
pub fn brute(points: &PointSet, k: usize) -> Vec<(Vec<u32>, Vec<f64>)> {
    let n = points.n;
    (0..n)
        .into_par_iter()
        .map(|i| {
            let a = points.point(i);
            let mut d: Vec<(f64, u32)> = (0..n)
                .filter(|&j| j != i)
                .map(|j| {
                    let b = points.point(j);
                    let s: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                    (s, j as u32)
                })
                .collect();
            let order = |x: &(f64, u32), y: &(f64, u32)| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1));
            d.select_nth_unstable_by(k - 1, order);
            d.truncate(k);
            d.sort_by(order);
            (
                d.iter().map(|e| e.1).collect(),
                d.iter().map(|e| e.0.sqrt()).collect(),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbours_on_a_line_and_ties_by_index() {
        // 0, 1, 2, 5, 6, 7 on a line: the two nearest of 2 are 1 (distance 1) and 0 (2);
        // of 0 they are 1 and 2. Point 1's two neighbours at equal distance come in index order.
        let points = PointSet {
            n: 6,
            dims: 1,
            data: vec![0.0, 1.0, 2.0, 5.0, 6.0, 7.0],
        };
        let g = knn(&points, 2).unwrap();
        assert_eq!(&g.neighbors[4..6], &[1, 0]);
        assert_eq!(&g.distances[4..6], &[1.0, 2.0]);
        assert_eq!(&g.neighbors[2..4], &[0, 2]);
        assert!(knn(&points, 6).unwrap_err().contains("k < n"));
    }

    #[test]
    fn the_tree_finds_exactly_what_brute_force_finds() {
        // 3000 points in 5-D on a coarse lattice, so many distances tie: the tree must return
        // the same neighbours in the same order as brute force (ties by index).
        let n = 3000;
        let data = (0..n * 5)
            .map(|i| {
                (crate::support::rng::unit(crate::support::rng::hash(9, &[i as u64])) * 4.0).floor()
            })
            .collect();
        let points = PointSet { n, dims: 5, data };
        let tree = super::super::kdtree::KdTree::build(&points);
        let brute = brute(&points, 7);
        for (i, (nb, d)) in brute.iter().enumerate() {
            let found = tree.nearest(&points, i, 7);
            let tn: Vec<u32> = found.iter().map(|e| e.1).collect();
            assert_eq!(&tn, nb, "point {i}");
            assert!(found
                .iter()
                .zip(d)
                .all(|(a, b)| (a.0.sqrt() - b).abs() == 0.0));
        }
    }
}
