//! Per-pixel normals by photometric stereo with an ambient term (seed 003 §3):
//! I_k = ρ_amb + ρ (L_k · N) over the lights k of one view, where I is the pixel's intensity
//! (R + G + B). Data selection first: the darkest `drop_dark` share of the lights (attached and
//! cast shadows) and the brightest `drop_bright` share (specular highlights) are left out, as
//! is any light that gives exactly 0. The four unknowns (ρ_amb, ρN) follow by linear least
//! squares; N = ρN / |ρN|.
//!
//! A pixel whose system is singular (too few lights left, lights in a plane, a black pixel) or
//! whose normal points away from the viewer (N_z < 0.1) gets the flat normal and is counted as a
//! fallback, never dropped.

/// Lights kept must determine 4 unknowns.
pub const MIN_LIGHTS: usize = 4;

pub struct Normals {
    pub normals: Vec<[f64; 3]>,
    pub fallbacks: usize,
}

/// `intensity(i, k)` is pixel i's intensity under light k (unit direction `lights[k]`).
pub fn photometric_normals(
    n: usize,
    lights: &[[f64; 3]],
    intensity: impl Fn(usize, usize) -> f64 + Sync,
    drop_dark: f64,
    drop_bright: f64,
) -> Normals {
    use rayon::prelude::*;
    let k = lights.len();
    let lo = (drop_dark * k as f64).floor() as usize;
    let hi = k - (drop_bright * k as f64).floor() as usize;
    let normals: Vec<Option<[f64; 3]>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut order: Vec<(f64, usize)> = (0..k).map(|j| (intensity(i, j), j)).collect();
            order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let kept: Vec<(f64, usize)> = order[lo.min(hi)..hi]
                .iter()
                .copied()
                .filter(|e| e.0 > 0.0)
                .collect();
            if kept.len() < MIN_LIGHTS {
                return None;
            }
            // Normal equations of [1, Lx, Ly, Lz] · [a, b] = I.
            let mut a = [[0.0f64; 4]; 4];
            let mut r = [0.0f64; 4];
            for &(v, j) in &kept {
                let row = [1.0, lights[j][0], lights[j][1], lights[j][2]];
                for u in 0..4 {
                    r[u] += row[u] * v;
                    for w in 0..4 {
                        a[u][w] += row[u] * row[w];
                    }
                }
            }
            let x = solve4(a, r)?;
            let len = (x[1] * x[1] + x[2] * x[2] + x[3] * x[3]).sqrt();
            if !(len.is_finite() && len > 0.0) {
                return None;
            }
            let nrm = [x[1] / len, x[2] / len, x[3] / len];
            (nrm[2] >= 0.1).then_some(nrm)
        })
        .collect();
    let fallbacks = normals.iter().filter(|v| v.is_none()).count();
    Normals {
        normals: normals
            .into_iter()
            .map(|v| v.unwrap_or([0.0, 0.0, 1.0]))
            .collect(),
        fallbacks,
    }
}

/// Gaussian elimination with partial pivoting; `None` when the system is (near) singular.
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    for col in 0..4 {
        let piv = (col..4).max_by(|&p, &q| a[p][col].abs().total_cmp(&a[q][col].abs()))?;
        if a[piv][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        let pivot_row = a[col];
        for row in col + 1..4 {
            let f = a[row][col] / pivot_row[col];
            for (v, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *v -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 4];
    for row in (0..4).rev() {
        let s: f64 = (row + 1..4).map(|c| a[row][c] * x[c]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

/// Angle in degrees between two unit vectors.
pub fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Direction;

    fn lights() -> Vec<[f64; 3]> {
        let mut v = vec![Direction::degrees(0.0, 0.0).vector()];
        for t in [20.0, 40.0, 60.0] {
            for f in [0.0, 72.0, 144.0, 216.0, 288.0] {
                v.push(Direction::degrees(t, f).vector());
            }
        }
        v
    }

    #[test]
    fn lambertian_pixels_with_ambient_give_their_normals_exactly() {
        // I = a + ρ max(0, L · N): with shadows left out the model is exact, so the normal comes
        // back to rounding (1e-9°).
        let ls = lights();
        let truth: Vec<[f64; 3]> = [[0.0f64, 0.0, 1.0], [0.3, -0.1, 0.95], [-0.4, 0.35, 0.85]]
            .iter()
            .map(|v| {
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                [v[0] / l, v[1] / l, v[2] / l]
            })
            .collect();
        let out = photometric_normals(
            truth.len(),
            &ls,
            |i, k| {
                let d: f64 = truth[i].iter().zip(&ls[k]).map(|(a, b)| a * b).sum();
                if d > 0.0 {
                    0.05 + 0.7 * d
                } else {
                    0.0
                }
            },
            0.0,
            0.0,
        );
        assert_eq!(out.fallbacks, 0);
        for (got, want) in out.normals.iter().zip(&truth) {
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-9, "{got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn a_black_pixel_falls_back_to_flat_and_is_counted() {
        let ls = lights();
        let out = photometric_normals(
            2,
            &ls,
            |i, k| if i == 0 { 0.0 } else { 0.5 + 0.5 * ls[k][2] },
            0.1,
            0.1,
        );
        assert_eq!(out.fallbacks, 1);
        assert_eq!(out.normals[0], [0.0, 0.0, 1.0]);
        assert!(
            (out.normals[1][2] - 1.0).abs() < 1e-9,
            "{:?}",
            out.normals[1]
        );
    }
}
