//! The weathering path as one capture shows it: the sample's pixels ordered by their degree.
//! A(w), the appearance at degree w, is the mean Ward vector (ρd RGB, ρs, ln α) of the
//! `neighbours` pixels whose degree is nearest w; each pixel's offset from A at its own degree is
//! its own variation, which `manifold.evolve` and `manifold.transfer` carry to a new degree.

use crate::types::{BrdfMap, WARD_PARAMS};

/// (ρd RGB, ρs, ln α): the space the path is averaged in.
fn vector(q: &[f64]) -> [f64; 5] {
    [q[0], q[1], q[2], q[3], q[4].max(1e-6).ln()]
}

/// The sample's pixels ordered by degree: the weathering path as the capture shows it.
pub struct Path {
    /// (degree, pixel), ascending.
    order: Vec<(f64, usize)>,
    vectors: Vec<[f64; 5]>,
    degrees: Vec<f64>,
    neighbours: usize,
}

impl Path {
    pub fn new(maps: &BrdfMap, omega: &[f64], neighbours: usize) -> Path {
        let mut order: Vec<(f64, usize)> = omega.iter().copied().zip(0..).collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let vectors = (0..omega.len()).map(|i| vector(maps.pixel(i))).collect();
        Path {
            order,
            vectors,
            degrees: omega.to_vec(),
            neighbours: neighbours.clamp(1, omega.len().max(1)),
        }
    }

    /// The index range in `order` of the `neighbours` pixels of degree nearest w.
    fn window(&self, w: f64) -> (usize, usize) {
        let n = self.order.len();
        // Grow a window from the insertion point towards the nearer side.
        let mut hi = self.order.partition_point(|e| e.0 < w);
        let mut lo = hi;
        while hi - lo < self.neighbours {
            let take_low = lo > 0 && (hi == n || w - self.order[lo - 1].0 <= self.order[hi].0 - w);
            if take_low {
                lo -= 1;
            } else {
                hi += 1;
            }
        }
        (lo, hi)
    }

    /// A(w): the mean vector of the `neighbours` pixels of degree nearest w.
    pub fn at(&self, w: f64) -> [f64; 5] {
        let (lo, hi) = self.window(w);
        let m = hi - lo;
        let mut sum = [0.0; 5];
        for &(_, i) in &self.order[lo..hi] {
            for (s, v) in sum.iter_mut().zip(&self.vectors[i]) {
                *s += v;
            }
        }
        sum.map(|s| s / m as f64)
    }

    /// Ward maps at the target degrees, each pixel keeping its offset from the path.
    pub fn advance(&self, maps: &BrdfMap, omega: &[f64], target: &[f64]) -> BrdfMap {
        let mut data = Vec::with_capacity(maps.data.len());
        for (i, (w, t)) in omega.iter().zip(target).enumerate() {
            data.extend(self.moved(i, *w, *t));
        }
        BrdfMap {
            width: maps.width,
            height: maps.height,
            data,
        }
    }

    /// Ward parameters at degree `to` for sample pixel `i` (of degree `from`): A(to) plus the
    /// pixel's offset v(i) − A(from), ρd and ρs clamped at 0.
    pub fn moved(&self, i: usize, from: f64, to: f64) -> [f64; WARD_PARAMS] {
        let (here, there) = (self.at(from), self.at(to));
        let v = &self.vectors[i];
        let mut q = [0.0; WARD_PARAMS];
        for d in 0..5 {
            q[d] = there[d] + (v[d] - here[d]);
        }
        for rho in &mut q[..4] {
            *rho = rho.max(0.0);
        }
        q[4] = q[4].exp();
        q
    }

    /// The sample pixel among the `neighbours` of degree nearest `w` that `pick` ∈ [0, 1) selects.
    pub fn pixel_near(&self, w: f64, pick: f64) -> usize {
        let (lo, hi) = self.window(w);
        let k = ((pick * (hi - lo) as f64) as usize).min(hi - lo - 1);
        self.order[lo + k].1
    }

    /// The degree of sample pixel `i`.
    pub fn degree_of(&self, i: usize) -> f64 {
        self.degrees[i]
    }
}
