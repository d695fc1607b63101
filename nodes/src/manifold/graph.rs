//! The undirected weighted graph behind geodesic distances: built from a kNN graph (an edge
//! wherever either end lists the other), its connected components, the joining of components
//! as scikit-learn's Isomap does it (each pair of components linked by its closest pair of
//! points), and Dijkstra from one source or from a set of sources.

use crate::types::{KnnGraph, PointSet};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The priority queue of [`Compact::dijkstra_with`]: smallest distance (as bits) first, ties
/// by smaller vertex.
pub type Heap = BinaryHeap<Reverse<(u64, u32)>>;

pub struct Graph {
    /// Per vertex: (neighbour, edge length), sorted by neighbour, no duplicates.
    pub adj: Vec<Vec<(u32, f64)>>,
}

impl Graph {
    pub fn from_knn(g: &KnnGraph) -> Graph {
        let mut adj: Vec<Vec<(u32, f64)>> = vec![Vec::new(); g.n];
        for i in 0..g.n {
            for s in 0..g.k {
                let j = g.neighbors[i * g.k + s] as usize;
                let d = g.distances[i * g.k + s];
                adj[i].push((j as u32, d));
                adj[j].push((i as u32, d));
            }
        }
        for list in &mut adj {
            list.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
            list.dedup_by_key(|e| e.0);
        }
        Graph { adj }
    }

    pub fn len(&self) -> usize {
        self.adj.len()
    }

    pub fn is_empty(&self) -> bool {
        self.adj.is_empty()
    }

    /// Component label per vertex (labels in order of their smallest vertex) and their count.
    pub fn components(&self) -> (Vec<usize>, usize) {
        let mut label = vec![usize::MAX; self.len()];
        let mut count = 0;
        for s in 0..self.len() {
            if label[s] != usize::MAX {
                continue;
            }
            let mut stack = vec![s];
            label[s] = count;
            while let Some(v) = stack.pop() {
                for &(w, _) in &self.adj[v] {
                    if label[w as usize] == usize::MAX {
                        label[w as usize] = count;
                        stack.push(w as usize);
                    }
                }
            }
            count += 1;
        }
        (label, count)
    }

    fn add_edge(&mut self, a: usize, b: usize, d: f64) {
        self.adj[a].push((b as u32, d));
        self.adj[b].push((a as u32, d));
    }

    /// Links every pair of components by its closest pair of points (Euclidean); returns the
    /// number of components there were.
    pub fn join_components(&mut self, points: &PointSet) -> usize {
        let (label, count) = self.components();
        if count <= 1 {
            return count;
        }
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
        for (v, &c) in label.iter().enumerate() {
            members[c].push(v);
        }
        let dist = |a: usize, b: usize| {
            points
                .point(a)
                .iter()
                .zip(points.point(b))
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
                .sqrt()
        };
        for ca in 0..count {
            for cb in ca + 1..count {
                let mut best = (f64::INFINITY, 0, 0);
                for &a in &members[ca] {
                    for &b in &members[cb] {
                        let d = dist(a, b);
                        if d < best.0 {
                            best = (d, a, b);
                        }
                    }
                }
                self.add_edge(best.1, best.2, best.0);
            }
        }
        count
    }

    /// Shortest-path lengths from `sources` (all at distance 0) to every vertex; +∞ where
    /// unreachable.
    pub fn dijkstra(&self, sources: &[usize]) -> Vec<f64> {
        self.compact().dijkstra(sources)
    }

    /// The same edges in flat arrays, for many shortest-path searches.
    pub fn compact(&self) -> Compact {
        let mut offsets = Vec::with_capacity(self.len() + 1);
        let mut targets = Vec::new();
        let mut lengths = Vec::new();
        offsets.push(0);
        for list in &self.adj {
            for &(w, d) in list {
                targets.push(w);
                lengths.push(d);
            }
            offsets.push(targets.len());
        }
        Compact {
            offsets,
            targets,
            lengths,
        }
    }
}

/// Compressed adjacency: vertex v's edges are `offsets[v]..offsets[v + 1]`.
pub struct Compact {
    offsets: Vec<usize>,
    targets: Vec<u32>,
    lengths: Vec<f64>,
}

impl Compact {
    pub fn dijkstra(&self, sources: &[usize]) -> Vec<f64> {
        self.dijkstra_with(sources, &mut Heap::new())
    }

    /// Dijkstra with a caller-owned heap, so many searches on one thread reuse its storage.
    ///
    /// Keys are the distances' bit patterns: for non-negative floats they order as the values
    /// do and compare as plain integers. (A radix heap measured slower here: 2.08 s against
    /// 1.54 s for the 5000-point bench's paths.)
    pub fn dijkstra_with(&self, sources: &[usize], heap: &mut Heap) -> Vec<f64> {
        let n = self.offsets.len() - 1;
        let mut dist = vec![f64::INFINITY; n];
        heap.clear();
        for &s in sources {
            dist[s] = 0.0;
            heap.push(Reverse((0.0f64.to_bits(), s as u32)));
        }
        while let Some(Reverse((d, v))) = heap.pop() {
            let v = v as usize;
            let d = f64::from_bits(d);
            if d > dist[v] {
                continue;
            }
            for e in self.offsets[v]..self.offsets[v + 1] {
                let w = self.targets[e] as usize;
                let nd = d + self.lengths[e];
                if nd < dist[w] {
                    dist[w] = nd;
                    heap.push(Reverse((nd.to_bits(), w as u32)));
                }
            }
        }
        dist
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifold::knn::knn;

    #[test]
    fn two_clusters_are_joined_by_their_closest_pair() {
        let points = PointSet {
            n: 6,
            dims: 1,
            data: vec![0.0, 1.0, 2.0, 5.0, 6.0, 7.0],
        };
        let mut g = Graph::from_knn(&knn(&points, 2).unwrap());
        assert_eq!(g.components().1, 2);
        assert_eq!(g.join_components(&points), 2);
        assert_eq!(g.components().1, 1);
        // The joining edge is 2–5 (length 3): along the line, every geodesic is |xi − xj|.
        let d = g.dijkstra(&[0]);
        assert_eq!(d, vec![0.0, 1.0, 2.0, 5.0, 6.0, 7.0]);
        let multi = g.dijkstra(&[0, 5]);
        assert_eq!(multi, vec![0.0, 1.0, 2.0, 2.0, 1.0, 0.0]);
    }
}
