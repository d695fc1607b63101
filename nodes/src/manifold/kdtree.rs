//! An exact k-d tree over a `PointSet` of any dimension, for k-nearest-neighbour queries that
//! return exactly what brute force returns: candidates ordered by (squared distance, index), and
//! subtrees pruned only when strictly farther than the current k-th, so equal-distance points
//! with smaller indices are never missed. Splits are at the median of the widest coordinate.

use crate::types::PointSet;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

const LEAF: usize = 16;

enum Node {
    Leaf {
        start: usize,
        end: usize,
    },
    Split {
        dim: usize,
        value: f64,
        left: usize,
        right: usize,
    },
}

pub struct KdTree {
    nodes: Vec<Node>,
    order: Vec<u32>,
}

/// Max-heap entry: the worst candidate on top.
#[derive(PartialEq)]
struct Candidate(f64, u32);

impl Eq for Candidate {}

impl Ord for Candidate {
    fn cmp(&self, o: &Self) -> Ordering {
        self.0.total_cmp(&o.0).then(self.1.cmp(&o.1))
    }
}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

impl KdTree {
    pub fn build(points: &PointSet) -> KdTree {
        let mut t = KdTree {
            nodes: Vec::new(),
            order: (0..points.n as u32).collect(),
        };
        t.split(points, 0, points.n);
        t
    }

    fn split(&mut self, points: &PointSet, start: usize, end: usize) -> usize {
        let id = self.nodes.len();
        if end - start <= LEAF {
            self.nodes.push(Node::Leaf { start, end });
            return id;
        }
        let d = points.dims;
        let (mut lo, mut hi) = (vec![f64::INFINITY; d], vec![f64::NEG_INFINITY; d]);
        for &i in &self.order[start..end] {
            for (c, v) in points.point(i as usize).iter().enumerate() {
                lo[c] = lo[c].min(*v);
                hi[c] = hi[c].max(*v);
            }
        }
        let dim = (0..d)
            .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
            .unwrap_or(0);
        if hi[dim] <= lo[dim] {
            // All points coincide: one leaf, however large.
            self.nodes.push(Node::Leaf { start, end });
            return id;
        }
        let mid = start + (end - start) / 2;
        let key = |i: &u32| points.point(*i as usize)[dim];
        self.order[start..end]
            .select_nth_unstable_by(mid - start, |a, b| key(a).total_cmp(&key(b)).then(a.cmp(b)));
        let value = key(&self.order[mid]);
        self.nodes.push(Node::Leaf { start, end });
        let left = self.split(points, start, mid);
        let right = self.split(points, mid, end);
        self.nodes[id] = Node::Split {
            dim,
            value,
            left,
            right,
        };
        id
    }

    /// The k nearest points to point `q` other than itself: (squared distance, index), nearest
    /// first, ties by index.
    pub fn nearest(&self, points: &PointSet, q: usize, k: usize) -> Vec<(f64, u32)> {
        let x = points.point(q);
        let mut heap: BinaryHeap<Candidate> = BinaryHeap::with_capacity(k + 1);
        self.search(points, 0, x, q as u32, k, &mut heap);
        let mut out: Vec<(f64, u32)> = heap.into_iter().map(|c| (c.0, c.1)).collect();
        out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        out
    }

    fn search(
        &self,
        points: &PointSet,
        node: usize,
        x: &[f64],
        skip: u32,
        k: usize,
        heap: &mut BinaryHeap<Candidate>,
    ) {
        match self.nodes[node] {
            Node::Leaf { start, end } => {
                for &i in &self.order[start..end] {
                    if i == skip {
                        continue;
                    }
                    let d: f64 = points
                        .point(i as usize)
                        .iter()
                        .zip(x)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum();
                    let c = Candidate(d, i);
                    if heap.len() < k {
                        heap.push(c);
                    } else if heap.peek().is_some_and(|w| c < *w) {
                        heap.pop();
                        heap.push(c);
                    }
                }
            }
            Node::Split {
                dim,
                value,
                left,
                right,
            } => {
                let diff = x[dim] - value;
                let (near, far) = if diff < 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.search(points, near, x, skip, k, heap);
                // Points on the split plane can sit on either side: visit the far side unless it
                // is strictly beyond the current k-th distance.
                let worst = if heap.len() < k {
                    f64::INFINITY
                } else {
                    heap.peek().map_or(f64::INFINITY, |w| w.0)
                };
                if diff * diff <= worst {
                    self.search(points, far, x, skip, k, heap);
                }
            }
        }
    }
}
