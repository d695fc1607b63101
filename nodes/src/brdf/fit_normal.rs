//! Ward parameters and the normal of one pixel refined together by Levenberg–Marquardt: seven
//! unknowns (ρd RGB, ρs, α, and the normal as surface slopes (p, q), n ∝ (−p, −q, 1), which
//! stays smooth for every normal facing the viewer). The Ward columns of the Jacobian are
//! analytic (as in `fit_ward.rs`), the two slope columns central differences.

use super::lm;
use crate::reflectance::ward::clamp_ward;
use crate::reflectance::ward::PairGeometry;
use crate::types::{DirectionPair, WARD_PARAMS};
use std::f64::consts::PI;

const N: usize = WARD_PARAMS + 2;
/// Step of the slope differences: error O(h²) ≈ 1e-12, rounding ≈ 1e-16 / h ≈ 1e-10.
const H: f64 = 1e-6;
/// Slopes beyond this (tilt ≈ 84°) are clamped: the pixel would face away from most lights.
const MAX_SLOPE: f64 = 10.0;

fn normal(p: f64, q: f64) -> [f64; 3] {
    let len = (p * p + q * q + 1.0).sqrt();
    [-p / len, -q / len, 1.0 / len]
}

fn geometry(pairs: &[DirectionPair], p: f64, q: f64) -> Vec<PairGeometry> {
    let n = normal(p, q);
    pairs
        .iter()
        .map(|pair| PairGeometry::with_normal(pair, n))
        .collect()
}

/// Model value of channel c under one pair's geometry.
fn model(g: &PairGeometry, x: &[f64], c: usize) -> f64 {
    g.cos_i.max(0.0) * (x[c] / PI + x[3] * g.lobe(x[4]).0)
}

fn cost(pairs: &[DirectionPair], obs: &[f32], z: &[f64; N]) -> f64 {
    let geo = geometry(pairs, z[5], z[6]);
    let mut sum = 0.0;
    for (k, g) in geo.iter().enumerate() {
        for c in 0..3 {
            sum += (model(g, z, c) - obs[k * 3 + c] as f64).powi(2);
        }
    }
    sum
}

/// From parameters `x` and normal `n0` (n0_z > 0); returns parameters, unit normal, converged.
pub fn refine_with_normal(
    pairs: &[DirectionPair],
    obs: &[f32],
    x: [f64; WARD_PARAMS],
    n0: [f64; 3],
    iterations: u32,
    tol: f64,
    alpha_min: f64,
) -> ([f64; WARD_PARAMS], [f64; 3], bool) {
    let mut z = [0.0; N];
    z[..WARD_PARAMS].copy_from_slice(&x);
    let nz = n0[2].max(1e-3);
    z[5] = (-n0[0] / nz).clamp(-MAX_SLOPE, MAX_SLOPE);
    z[6] = (-n0[1] / nz).clamp(-MAX_SLOPE, MAX_SLOPE);
    let scale: f64 = obs.iter().map(|v| (*v as f64).powi(2)).sum();
    let (z, ok) = lm::minimise(
        z,
        iterations,
        tol,
        scale,
        |z| cost(pairs, obs, z),
        |z| normal_equations(pairs, obs, z),
        |z| {
            clamp_ward(z, alpha_min);
            z[5] = z[5].clamp(-MAX_SLOPE, MAX_SLOPE);
            z[6] = z[6].clamp(-MAX_SLOPE, MAX_SLOPE);
        },
    );
    let mut x = [0.0; WARD_PARAMS];
    x.copy_from_slice(&z[..WARD_PARAMS]);
    (x, normal(z[5], z[6]), ok)
}

/// JᵀJ and Jᵀr at z.
fn normal_equations(
    pairs: &[DirectionPair],
    obs: &[f32],
    z: &[f64; N],
) -> ([[f64; N]; N], [f64; N]) {
    let geo = geometry(pairs, z[5], z[6]);
    let shifted = [
        geometry(pairs, z[5] + H, z[6]),
        geometry(pairs, z[5] - H, z[6]),
        geometry(pairs, z[5], z[6] + H),
        geometry(pairs, z[5], z[6] - H),
    ];
    let mut a = [[0.0; N]; N];
    let mut g = [0.0; N];
    for (k, geo_k) in geo.iter().enumerate() {
        let ci = geo_k.cos_i.max(0.0);
        let (s, ds) = geo_k.lobe(z[4]);
        for c in 0..3 {
            let r = model(geo_k, z, c) - obs[k * 3 + c] as f64;
            let mut j = [0.0; N];
            j[c] = ci / PI;
            j[3] = ci * s;
            j[4] = ci * z[3] * ds;
            j[5] = (model(&shifted[0][k], z, c) - model(&shifted[1][k], z, c)) / (2.0 * H);
            j[6] = (model(&shifted[2][k], z, c) - model(&shifted[3][k], z, c)) / (2.0 * H);
            for u in 0..N {
                g[u] += j[u] * r;
                for v in 0..N {
                    a[u][v] += j[u] * j[v];
                }
            }
        }
    }
    (a, g)
}
