//! Light that leaves one part of the object and enters another (a concave object's inner sides
//! see each other): the exitance M of every irradiance sample is gathered as for a pixel, leaves
//! as a diffuse radiance M/π, and lands on the samples that see it, found by casting cosine-
//! distributed rays from each sample into the hemisphere above it (the radiance at a ray's hit is
//! its nearest sample's). Their diffuse transmittance 1 − Fdr lets it in, where it adds to the
//! sample's own transmitted irradiance. Each bounce repeats this from the last one's light.

use crate::sss::points::SamplePoint;
use crate::support::geometry::rotate;
use crate::support::geometry::{add, dot, mul, V3};
use crate::support::raytrace::tracer::Tracer;
use crate::support::rng::Stream;
use rayon::prelude::*;
use std::collections::HashMap;

/// Rays per sample and bounce.
pub(super) const RAYS: u64 = 256;
/// Samples the bounces are computed on, at most.
pub(super) const MOST_POINTS: usize = 8192;

/// The samples on a hash grid, for the nearest one to a point (world units).
pub(super) struct Nearest {
    points: Vec<V3>,
    cell: f64,
    grid: HashMap<[i64; 3], Vec<usize>>,
}

impl Nearest {
    pub(super) fn new(points: &[SamplePoint], spacing: f64) -> Nearest {
        Nearest::at(points.iter().map(|s| s.p).collect(), spacing)
    }

    /// The grid over `points` (world units) with cells of `spacing`.
    pub(super) fn at(points: Vec<V3>, spacing: f64) -> Nearest {
        let cell = spacing.max(1e-300);
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, &p) in points.iter().enumerate() {
            grid.entry(Self::key(p, cell)).or_default().push(i);
        }
        Nearest { points, cell, grid }
    }

    /// The members' positions and the cell, as [`Nearest::at`] takes them.
    pub(super) fn parts(&self) -> (&[V3], f64) {
        (&self.points, self.cell)
    }

    fn key(p: V3, cell: f64) -> [i64; 3] {
        p.map(|v| (v / cell).floor() as i64)
    }

    /// The samples within `radius` of `p` (at most two cells away).
    pub(super) fn within(&self, p: V3, radius: f64) -> Vec<usize> {
        let c = Self::key(p, self.cell);
        let reach = (radius / self.cell).ceil().clamp(1.0, 2.0) as i64;
        let mut found = Vec::new();
        for dx in -reach..=reach {
            for dy in -reach..=reach {
                for dz in -reach..=reach {
                    if let Some(list) = self.grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &i in list {
                            let q = self.points[i];
                            let d2: f64 = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum();
                            if d2 <= radius * radius {
                                found.push(i);
                            }
                        }
                    }
                }
            }
        }
        found.sort_unstable();
        found
    }

    /// `values` averaged over each sample's neighbours within two cells: the ray estimates'
    /// noise, not their signal (which varies on the parts' scale).
    pub(super) fn smooth(&self, values: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..self.points.len())
            .into_par_iter()
            .map(|i| {
                let near = self.within(self.points[i], 2.0 * self.cell);
                let mut sum = [0.0; 3];
                for &j in &near {
                    for c in 0..3 {
                        sum[c] += values[j][c];
                    }
                }
                sum.map(|v| v / near.len().max(1) as f64)
            })
            .collect()
    }

    /// The nearest sample within a few cells of `p` (ties to the lower index), if any.
    pub(super) fn find(&self, p: V3) -> Option<usize> {
        let c = Self::key(p, self.cell);
        for reach in 1..=3i64 {
            let mut best: Option<(f64, usize)> = None;
            for dx in -reach..=reach {
                for dy in -reach..=reach {
                    for dz in -reach..=reach {
                        let Some(list) = self.grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                            continue;
                        };
                        for &i in list {
                            let q = self.points[i];
                            let d2: f64 = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum();
                            if best.is_none_or(|(b, j)| d2 < b || (d2 == b && i < j)) {
                                best = Some((d2, i));
                            }
                        }
                    }
                }
            }
            if let Some((_, i)) = best {
                return Some(i);
            }
        }
        None
    }
}

/// Ray `k` of sample `i`: cosine-distributed about its normal `n` (cos θ = √u), from `seed`.
fn direction(seed: u64, i: usize, k: u64, n: V3) -> V3 {
    let mut rng = Stream(crate::support::rng::hash(seed, &[i as u64, k]));
    let cos = rng.unit().sqrt();
    rotate(n, cos, 2.0 * std::f64::consts::PI * rng.unit())
}

/// How far the ray from `from` along `d` goes before it meets a surface's outside; `None` where
/// it leaves or meets an inside (no exitance leaves that way).
fn returns(tracer: &Tracer, from: V3, d: V3) -> Option<f64> {
    let hit = tracer.closest(from, d)?;
    (dot(tracer.triangle(hit.tri).1, d) < 0.0).then_some(hit.t)
}

/// Under this share of returning rays the bounces are skipped: a convex mesh's facets return
/// only rays that graze them (on the sphere of the test `bounces_leave_a_convex_object_alone…`
/// the bounces added 2·10⁻⁴ of its image), and light arriving at a sample is at most its
/// returning share of the brightest exitance.
pub(super) const NEGLIGIBLE: f64 = 1e-3;

/// Samples traced together by [`sees_itself`] before it looks at the count.
const CHUNK: usize = 256;

/// Whether at least [`NEGLIGIBLE`] of the first round's rays (those of [`arriving`] with the
/// same `seed`) meet a surface's outside: whether the object sees itself. Stops at the first
/// chunk of samples that makes it so (a torus: the first), so only an object that does not
/// traces them all; the answer is the same in any order.
pub(super) fn sees_itself(tracer: &Tracer, points: &[SamplePoint], seed: u64) -> bool {
    let enough = (NEGLIGIBLE * (points.len() as u64 * RAYS) as f64).ceil() as u64;
    let mut hits = 0u64;
    for (c, chunk) in points.chunks(CHUNK).enumerate() {
        hits += chunk
            .par_iter()
            .enumerate()
            .map(|(j, s)| {
                let i = c * CHUNK + j;
                let from = add(s.p, mul(s.n, tracer.epsilon));
                (0..RAYS)
                    .filter(|&k| returns(tracer, from, direction(seed, i, k, s.n)).is_some())
                    .count() as u64
            })
            .sum::<u64>();
        if hits >= enough.max(1) {
            return true;
        }
    }
    false
}

/// Per sample the irradiance (per channel, outside the surface) arriving from the other samples'
/// exitance `m` (flux per area leaving, diffuse).
pub(super) fn arriving(
    tracer: &Tracer,
    points: &[SamplePoint],
    nearest: &Nearest,
    m: &[[f64; 3]],
    seed: u64,
) -> Vec<[f64; 3]> {
    let raw: Vec<[f64; 3]> = points
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let mut sum = [0.0; 3];
            let from = add(s.p, mul(s.n, tracer.epsilon));
            for k in 0..RAYS {
                let d = direction(seed, i, k, s.n);
                let Some(t) = returns(tracer, from, d) else {
                    continue;
                };
                if let Some(j) = nearest.find(add(from, mul(d, t))) {
                    // E = π · mean L over cosine-distributed rays, with L = M/π.
                    for c in 0..3 {
                        sum[c] += m[j][c];
                    }
                }
            }
            sum.map(|v| v / RAYS as f64)
        })
        .collect();
    nearest.smooth(&raw)
}
