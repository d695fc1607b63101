//! `manifold.knn`: the exact k-nearest-neighbour graph of a point set (Euclidean), by brute
//! force on rayon: each point's distances to all others, the k smallest selected with ties
//! broken by index, so the graph is the same whatever the thread count.
//!
//! Appearance vectors are compared as given: the caller weights and normalises them (per-pixel
//! BRDF parameters are put on comparable scales by the node that builds them).

use crate::types::{KnnGraph, PointSet};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::Instant;

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
            outputs: vec![
                Port::output("graph", KnnGraph::TYPE, "each point's k nearest others"),
                Port::output("seconds", "Scalar", "time to build, s"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let points = inputs.get::<PointSet>("points")?;
        let start = Instant::now();
        let graph = knn(points, p.k as usize).map_err(|m| NodeError::param("k", m))?;
        Ok(Outputs::new()
            .with("graph", graph)
            .with("seconds", Scalar(start.elapsed().as_secs_f64())))
    }
}

pub fn knn(points: &PointSet, k: usize) -> Result<KnnGraph, String> {
    let n = points.n;
    if k == 0 || k >= n {
        return Err(format!("{k} neighbours of {n} points: need 1 ≤ k < n"));
    }
    let rows: Vec<(Vec<u32>, Vec<f64>)> = (0..n)
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
        .collect();
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
    Ok(graph)
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
}
