//! The largest eigenpairs of a dense symmetric matrix, as classical MDS needs them: faer's full
//! decomposition for small matrices, and for large ones subspace iteration (a block of k + 8
//! vectors multiplied by the matrix, re-orthonormalised by QR, Rayleigh–Ritz on the block) until
//! the wanted eigenvalues stop moving. The products run on rayon over fixed row panels with
//! faer's sequential GEMM, so the result is the same whatever the thread count.

use crate::support::rng;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use rayon::prelude::*;

/// Below this size the full decomposition is cheaper than iterating.
const DENSE: usize = 600;
const PANEL: usize = 256;

/// The `k` largest eigenvalues (descending) and their unit eigenvectors (n × k, column-major in
/// a `Mat`) of the symmetric n × n matrix `a`.
pub fn top(a: MatRef<f64>, k: usize) -> Result<(Vec<f64>, Mat<f64>), String> {
    let n = a.nrows();
    let k = k.min(n);
    if n <= DENSE {
        return dense(a, k);
    }
    let p = (k + 8).min(n);
    // A fixed pseudo-random start, so the result does not depend on anything but `a`.
    let mut q = Mat::<f64>::from_fn(n, p, |i, j| {
        rng::unit(rng::hash(0x15_0a, &[i as u64, j as u64])) - 0.5
    });
    q = q.qr().compute_thin_Q();
    let mut last = vec![f64::INFINITY; k];
    for _ in 0..2000 {
        let y = product(a, q.as_ref());
        // Rayleigh–Ritz: the small matrix Qᵀ A Q = Qᵀ Y.
        let mut small = Mat::<f64>::zeros(p, p);
        matmul(
            small.as_mut(),
            Accum::Replace,
            q.transpose(),
            y.as_ref(),
            1.0,
            Par::Seq,
        );
        let small = Mat::<f64>::from_fn(p, p, |i, j| 0.5 * (small[(i, j)] + small[(j, i)]));
        let (vals, vecs) = dense(small.as_ref(), p)?;
        let mut rotated = Mat::<f64>::zeros(n, p);
        matmul(
            rotated.as_mut(),
            Accum::Replace,
            q.as_ref(),
            vecs.as_ref(),
            1.0,
            Par::Seq,
        );
        let scale = vals.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        let moved = vals[..k]
            .iter()
            .zip(&last)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f64, f64::max);
        if moved <= 1e-13 * scale {
            return Ok((vals[..k].to_vec(), rotated.subcols(0, k).to_owned()));
        }
        last = vals[..k].to_vec();
        // Next block: A times the Ritz vectors, orthonormalised.
        let mut next = Mat::<f64>::zeros(n, p);
        matmul(
            next.as_mut(),
            Accum::Replace,
            y.as_ref(),
            vecs.as_ref(),
            1.0,
            Par::Seq,
        );
        q = next.qr().compute_thin_Q();
    }
    Err("subspace iteration did not converge in 2000 steps".into())
}

/// A · Q on rayon over fixed panels of rows.
fn product(a: MatRef<f64>, q: MatRef<f64>) -> Mat<f64> {
    let (n, p) = (a.nrows(), q.ncols());
    let panels: Vec<Mat<f64>> = (0..n.div_ceil(PANEL))
        .into_par_iter()
        .map(|b| {
            let r0 = b * PANEL;
            let rows = PANEL.min(n - r0);
            let mut out = Mat::<f64>::zeros(rows, p);
            matmul(
                out.as_mut(),
                Accum::Replace,
                a.subrows(r0, rows),
                q,
                1.0,
                Par::Seq,
            );
            out
        })
        .collect();
    Mat::<f64>::from_fn(n, p, |i, j| panels[i / PANEL][(i % PANEL, j)])
}

fn dense(a: MatRef<f64>, k: usize) -> Result<(Vec<f64>, Mat<f64>), String> {
    let n = a.nrows();
    let evd = a
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| format!("eigendecomposition did not converge: {e:?}"))?;
    let vals: Vec<f64> = (0..n).map(|i| evd.S().column_vector()[i]).collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| vals[y].total_cmp(&vals[x]).then(x.cmp(&y)));
    let vecs = Mat::<f64>::from_fn(n, k, |i, j| evd.U()[(i, order[j])]);
    Ok((order[..k].iter().map(|&i| vals[i]).collect(), vecs))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subspace_iteration_finds_what_the_full_decomposition_finds() {
        // A 700 × 700 matrix with a known spectrum: Q diag(λ) Qᵀ, λ = 100, 50, 20, 1/(i+1)….
        let n = 700;
        let noise = Mat::<f64>::from_fn(n, n, |i, j| {
            rng::unit(rng::hash(5, &[i as u64, j as u64])) - 0.5
        });
        let q = noise.qr().compute_thin_Q();
        let lambda: Vec<f64> = (0..n)
            .map(|i| match i {
                0 => 100.0,
                1 => 50.0,
                2 => 20.0,
                _ => 1.0 / (i as f64 + 1.0),
            })
            .collect();
        let a = Mat::<f64>::from_fn(n, n, |i, j| {
            (0..n).map(|m| q[(i, m)] * lambda[m] * q[(j, m)]).sum()
        });
        let (vals, vecs) = top(a.as_ref(), 3).unwrap();
        for (got, want) in vals.iter().zip([100.0, 50.0, 20.0]) {
            assert!((got - want).abs() < 1e-9 * want, "{got}");
        }
        // Eigenvectors up to sign.
        for j in 0..3 {
            let dot: f64 = (0..n).map(|i| vecs[(i, j)] * q[(i, j)]).sum();
            assert!((dot.abs() - 1.0).abs() < 1e-9, "{dot}");
        }
    }
}
