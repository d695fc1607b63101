//! Truncated SVD of one centred block of a BTF matrix: the numerical core of `btf.pca`.
//!
//! A block is a T×n column view (texels × columns) into the BTF's own f32 buffer, seen through a
//! centring (the column mean for the `texels` layout, the texel mean for `directions`). It is
//! never copied whole: every product X·M and Xᵀ·M streams the f32 data through small centred
//! panels (a few MB, f32 or f64) and multiplies them with faer's sequential GEMM. This keeps the
//! peak memory at the BTF plus thin T×l and n×l matrices, and because panel boundaries are fixed
//! (not derived from the thread count) and each output entry is produced by one sequential GEMM in
//! a fixed order, results are bit-identical for any number of threads.
//!
//! Solvers:
//! - **dense** (the smaller side n ≤ [`DENSE_MAX`]): the Gram matrix on the smaller side, accumulated
//!   panel by panel in f64, and faer's symmetric eigendecomposition. All n singular values are
//!   known, so error budgets pick ranks exactly and the discarded energy is the eigenvalue tail.
//! - **subspace iteration** with Rayleigh–Ritz (Halko, Martinsson & Tropp 2011, alg. 4.4): `l = k + p`
//!   Gaussian test vectors, then alternating Xᵀ·Q and X·V passes. `randomized` stops after `q`
//!   power iterations (f32 panels: it is bandwidth-bound and its own error dwarfs f32 rounding);
//!   `exact` on a large matrix runs in f64 until every kept triplet's residual
//!   ‖X vᵢ − σᵢ uᵢ‖ ≤ [`EXACT_TOLERANCE`]·σ₀, i.e. to the truncated SVD within that tolerance.
//!
//! Coefficients are always the projection D = X·V in f64, so for any orthonormal basis V the
//! residual energy is exactly ‖X‖² − ‖D‖² and the reported RMSE is the reconstruction's.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use rayon::prelude::*;

pub use crate::types::Centring;

/// Largest smaller side for which the dense Gram route is used (Gram n² f64 = 8 MiB at 1024).
pub const DENSE_MAX: usize = 1024;
/// Residual bound of the iterative exact solver, relative to the largest singular value.
pub const EXACT_TOLERANCE: f64 = 1e-6;
/// Iteration cap of the iterative exact solver.
pub const EXACT_MAX_ITERATIONS: usize = 500;

/// A T×n column view into a column-major f32 buffer: column j is
/// `data[offset + j·stride ..][..rows]`.
pub struct Block<'a> {
    data: &'a [f32],
    pub rows: usize,
    pub cols: usize,
    offset: usize,
    stride: usize,
    pub centring: Centring,
    /// Column means (n) or row means (T), f64, each summed in order.
    pub mean: Vec<f64>,
    /// ‖X‖², the centred block's energy.
    pub energy: f64,
}

/// How a solve ended.
#[derive(Clone, Debug)]
pub struct Factors {
    /// n×k right singular vectors (the basis over the block's columns).
    pub v: Mat<f64>,
    /// T×k coefficients D = X·V.
    pub d: Mat<f64>,
    /// k singular values, largest first.
    pub sigma: Vec<f64>,
    /// Residual energy ‖X − D Vᵀ‖².
    pub residual: f64,
    /// Set when the iterative exact solver hit its cap: the largest relative residual reached.
    pub unconverged: Option<f64>,
}

/// The number type of the streamed panels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

trait Elem: faer::traits::RealField + Copy + Send + Sync + 'static {
    fn of(x: f64) -> Self;
    fn f64(self) -> f64;
    /// The f32 buffer as this type without a copy, where it is f32.
    fn borrow(v: MatRef<'_, f32>) -> Option<MatRef<'_, Self>>;
}
impl Elem for f32 {
    fn of(x: f64) -> Self {
        x as f32
    }
    fn borrow(v: MatRef<'_, f32>) -> Option<MatRef<'_, f32>> {
        Some(v)
    }
    fn f64(self) -> f64 {
        self as f64
    }
}
impl Elem for f64 {
    fn of(x: f64) -> Self {
        x
    }
    fn borrow(_: MatRef<'_, f32>) -> Option<MatRef<'_, f64>> {
        None
    }
    fn f64(self) -> f64 {
        self
    }
}

/// A panel: a view into the f32 buffer or a centred copy.
enum Panel<'a, E: Elem> {
    View(MatRef<'a, E>),
    Owned(Mat<E>),
}

impl<E: Elem> Panel<'_, E> {
    fn as_ref(&self) -> MatRef<'_, E> {
        match self {
            Panel::View(v) => *v,
            Panel::Owned(m) => m.as_ref(),
        }
    }
}

/// Rows per panel of X·M and columns per panel of Xᵀ·M; fixed so results do not depend on threads.
const ROW_PANEL: usize = 256;
const COL_PANEL: usize = 64;
/// Depth of one panel (the summed dimension), chosen so a panel stays in L2.
const DEPTH_PANEL: usize = 2048;

impl<'a> Block<'a> {
    /// `data` holds column j of the block at `offset + j·stride`, `rows` long.
    pub fn new(
        data: &'a [f32],
        rows: usize,
        cols: usize,
        offset: usize,
        stride: usize,
        centring: Centring,
    ) -> Self {
        assert!(cols == 0 || offset + (cols - 1) * stride + rows <= data.len());
        let mut b = Block {
            data,
            rows,
            cols,
            offset,
            stride,
            centring,
            mean: Vec::new(),
            energy: 0.0,
        };
        b.mean = match centring {
            Centring::Columns => (0..cols)
                .into_par_iter()
                .map(|j| lanes_sum(b.col(j), |v| v as f64) / rows.max(1) as f64)
                .collect(),
            Centring::Texels => {
                let mut m = vec![0f64; rows];
                m.par_chunks_mut(ROW_PANEL)
                    .enumerate()
                    .for_each(|(p, chunk)| {
                        let r0 = p * ROW_PANEL;
                        for j in 0..cols {
                            let c = &b.col(j)[r0..r0 + chunk.len()];
                            for (s, &v) in chunk.iter_mut().zip(c) {
                                *s += v as f64;
                            }
                        }
                        for s in chunk.iter_mut() {
                            *s /= cols.max(1) as f64;
                        }
                    });
                m
            }
        };
        b.energy = (0..cols)
            .into_par_iter()
            .map(|j| match centring {
                Centring::Columns => {
                    let m = b.mean[j];
                    lanes_sum(b.col(j), |v| (v as f64 - m) * (v as f64 - m))
                }
                Centring::Texels => b
                    .col(j)
                    .iter()
                    .zip(&b.mean)
                    .map(|(&v, m)| (v as f64 - m) * (v as f64 - m))
                    .sum::<f64>(),
            })
            .collect::<Vec<_>>()
            .iter()
            .sum();
        b
    }

    pub fn col(&self, j: usize) -> &[f32] {
        let s = self.offset + j * self.stride;
        &self.data[s..s + self.rows]
    }

    #[cfg(test)]
    fn centre(&self, i: usize, j: usize) -> f64 {
        match self.centring {
            Centring::Columns => self.mean[j],
            Centring::Texels => self.mean[i],
        }
    }

    /// A centred copy of the panel, or (f32 only) the uncentred buffer itself.
    fn panel_or_view<E: Elem>(
        &self,
        centred: bool,
        r0: usize,
        nr: usize,
        c0: usize,
        nc: usize,
    ) -> Panel<'_, E> {
        if !centred {
            if let Some(v) = E::borrow(self.view(r0, nr, c0, nc)) {
                return Panel::View(v);
            }
        }
        Panel::Owned(self.panel::<E>(r0, nr, c0, nc))
    }

    /// Centred panel rows r0..r0+nr × columns c0..c0+nc, column-major.
    fn panel<E: Elem>(&self, r0: usize, nr: usize, c0: usize, nc: usize) -> Mat<E> {
        let mut p = Mat::<E>::zeros(nr, nc);
        for j in 0..nc {
            let src = &self.col(c0 + j)[r0..r0 + nr];
            let dst = p.col_as_slice_mut(j);
            match self.centring {
                Centring::Columns => {
                    let m = self.mean[c0 + j];
                    for (d, &v) in dst.iter_mut().zip(src) {
                        *d = E::of(v as f64 - m);
                    }
                }
                Centring::Texels => {
                    for ((d, &v), m) in dst.iter_mut().zip(src).zip(&self.mean[r0..r0 + nr]) {
                        *d = E::of(v as f64 - m);
                    }
                }
            }
        }
        p
    }

    /// X·M (T×l) for M n×l.
    pub fn mul(&self, m: MatRef<'_, f64>, precision: Precision) -> Mat<f64> {
        match precision {
            Precision::F32 => {
                // A·M straight from the f32 buffer (no panel copy), then the rank-one centring.
                let mut y = self.mul_in::<f32>(m, false);
                match self.centring {
                    Centring::Columns => {
                        let mu_m: Vec<f64> = (0..m.ncols())
                            .map(|j| (0..m.nrows()).map(|i| self.mean[i] * m[(i, j)]).sum())
                            .collect();
                        for (j, c) in mu_m.iter().enumerate() {
                            for v in y.col_as_slice_mut(j) {
                                *v -= c;
                            }
                        }
                    }
                    Centring::Texels => {
                        for j in 0..m.ncols() {
                            let s: f64 = (0..m.nrows()).map(|i| m[(i, j)]).sum();
                            for (v, mu) in y.col_as_slice_mut(j).iter_mut().zip(&self.mean) {
                                *v -= mu * s;
                            }
                        }
                    }
                }
                y
            }
            Precision::F64 => self.mul_in::<f64>(m, true),
        }
    }

    /// Xᵀ·Q (n×l) for Q T×l.
    pub fn tmul(&self, q: MatRef<'_, f64>, precision: Precision) -> Mat<f64> {
        match precision {
            Precision::F32 => {
                let mut z = self.tmul_in::<f32>(q, false);
                match self.centring {
                    Centring::Columns => {
                        for j in 0..q.ncols() {
                            let s: f64 = (0..q.nrows()).map(|i| q[(i, j)]).sum();
                            for (v, mu) in z.col_as_slice_mut(j).iter_mut().zip(&self.mean) {
                                *v -= mu * s;
                            }
                        }
                    }
                    Centring::Texels => {
                        for j in 0..q.ncols() {
                            let c: f64 = (0..q.nrows()).map(|i| self.mean[i] * q[(i, j)]).sum();
                            for v in z.col_as_slice_mut(j) {
                                *v -= c;
                            }
                        }
                    }
                }
                z
            }
            Precision::F64 => self.tmul_in::<f64>(q, true),
        }
    }

    /// The uncentred f32 submatrix rows r0.., columns c0.., as a strided view (no copy).
    fn view(&self, r0: usize, nr: usize, c0: usize, nc: usize) -> MatRef<'_, f32> {
        let start = self.offset + c0 * self.stride + r0;
        let len = if nc == 0 {
            0
        } else {
            (nc - 1) * self.stride + nr
        };
        MatRef::from_column_major_slice_with_stride(
            &self.data[start..start + len],
            nr,
            nc,
            self.stride,
        )
    }

    fn mul_in<E: Elem>(&self, m: MatRef<'_, f64>, centred: bool) -> Mat<f64> {
        let l = m.ncols();
        let me = Mat::<E>::from_fn(m.nrows(), l, |i, j| E::of(m[(i, j)]));
        let starts: Vec<usize> = (0..self.rows).step_by(ROW_PANEL).collect();
        let parts: Vec<Mat<E>> = starts
            .par_iter()
            .map(|&r0| {
                let nr = ROW_PANEL.min(self.rows - r0);
                let mut out = Mat::<E>::zeros(nr, l);
                for c0 in (0..self.cols).step_by(DEPTH_PANEL) {
                    let nc = DEPTH_PANEL.min(self.cols - c0);
                    let p = self.panel_or_view::<E>(centred, r0, nr, c0, nc);
                    matmul(
                        out.as_mut(),
                        Accum::Add,
                        p.as_ref(),
                        me.as_ref().subrows(c0, nc),
                        E::of(1.0),
                        Par::Seq,
                    );
                }
                out
            })
            .collect();
        let mut y = Mat::<f64>::zeros(self.rows, l);
        for (&r0, part) in starts.iter().zip(&parts) {
            for j in 0..l {
                for i in 0..part.nrows() {
                    y[(r0 + i, j)] = part[(i, j)].f64();
                }
            }
        }
        y
    }

    fn tmul_in<E: Elem>(&self, q: MatRef<'_, f64>, centred: bool) -> Mat<f64> {
        let l = q.ncols();
        let qe = Mat::<E>::from_fn(q.nrows(), l, |i, j| E::of(q[(i, j)]));
        let starts: Vec<usize> = (0..self.cols).step_by(COL_PANEL).collect();
        let parts: Vec<Mat<E>> = starts
            .par_iter()
            .map(|&c0| {
                let nc = COL_PANEL.min(self.cols - c0);
                let mut out = Mat::<E>::zeros(nc, l);
                for r0 in (0..self.rows).step_by(DEPTH_PANEL) {
                    let nr = DEPTH_PANEL.min(self.rows - r0);
                    let p = self.panel_or_view::<E>(centred, r0, nr, c0, nc);
                    matmul(
                        out.as_mut(),
                        Accum::Add,
                        p.as_ref().transpose(),
                        qe.as_ref().subrows(r0, nr),
                        E::of(1.0),
                        Par::Seq,
                    );
                }
                out
            })
            .collect();
        let mut z = Mat::<f64>::zeros(self.cols, l);
        for (&c0, part) in starts.iter().zip(&parts) {
            for j in 0..l {
                for i in 0..part.nrows() {
                    z[(c0 + i, j)] = part[(i, j)].f64();
                }
            }
        }
        z
    }

    /// The Gram matrix on the smaller side (XᵀX when n ≤ T, else XXᵀ), f64, panel by panel in a
    /// fixed order; parallel over column strips of the result.
    fn gram(&self) -> Mat<f64> {
        let by_columns = self.cols <= self.rows;
        let n = self.cols.min(self.rows);
        let mut g = Mat::<f64>::zeros(n, n);
        let long = if by_columns { self.rows } else { self.cols };
        const STRIP: usize = 32;
        for s0 in (0..long).step_by(DEPTH_PANEL) {
            let ns = DEPTH_PANEL.min(long - s0);
            // P is n × ns with G += P Pᵀ.
            let p: Mat<f64> = if by_columns {
                self.panel::<f64>(s0, ns, 0, self.cols)
                    .transpose()
                    .to_owned()
            } else {
                self.panel::<f64>(0, self.rows, s0, ns)
            };
            let strips: Vec<(usize, Mat<f64>)> = (0..n)
                .step_by(STRIP)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|j0| {
                    let nj = STRIP.min(n - j0);
                    let mut out = Mat::<f64>::zeros(n, nj);
                    matmul(
                        out.as_mut(),
                        Accum::Replace,
                        p.as_ref(),
                        p.as_ref().subrows(j0, nj).transpose(),
                        1.0,
                        Par::Seq,
                    );
                    (j0, out)
                })
                .collect();
            for (j0, strip) in strips {
                for j in 0..strip.ncols() {
                    for i in 0..n {
                        g[(i, j0 + j)] += strip[(i, j)];
                    }
                }
            }
        }
        g
    }
}

/// All singular values (largest first) and a rank-k factorization by the dense Gram route.
/// Returns the factors and σ² of every component (for error budgets).
pub fn dense(x: &Block, pick: &dyn Fn(&[f64]) -> usize) -> Result<(Factors, Vec<f64>), String> {
    let n = x.cols.min(x.rows);
    let evd = x
        .gram()
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| format!("eigendecomposition did not converge: {e:?}"))?;
    let eig: Vec<f64> = (0..n)
        .map(|i| evd.S().column_vector()[i].max(0.0))
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| eig[b].total_cmp(&eig[a]).then(a.cmp(&b)));
    let lambda: Vec<f64> = order.iter().map(|&i| eig[i]).collect();
    let k = pick(&lambda);
    let vecs = evd.U();
    // Components with σ² below this are numerically zero: their directions are noise.
    let floor = lambda.first().copied().unwrap_or(0.0) * 1e-24;
    let sigma: Vec<f64> = lambda[..k].iter().map(|l| l.sqrt()).collect();
    let (v, d) = if x.cols <= x.rows {
        let v = Mat::<f64>::from_fn(x.cols, k, |j, kk| vecs[(j, order[kk])]);
        let d = x.mul(v.as_ref(), Precision::F64);
        (v, d)
    } else {
        // Gram = XXᵀ: eigenvectors u_k; V = Xᵀ U / σ and D = U σ.
        let u = Mat::<f64>::from_fn(x.rows, k, |i, kk| vecs[(i, order[kk])]);
        let mut v = x.tmul(u.as_ref(), Precision::F64);
        for kk in 0..k {
            let s = sigma[kk];
            for j in 0..x.cols {
                v[(j, kk)] = if lambda[kk] > floor {
                    v[(j, kk)] / s
                } else {
                    0.0
                };
            }
        }
        let d = Mat::<f64>::from_fn(x.rows, k, |i, kk| u[(i, kk)] * sigma[kk]);
        (v, d)
    };
    // The discarded energy from the tail eigenvalues directly (no cancellation against ‖X‖²).
    let residual = lambda[k..].iter().rev().sum::<f64>();
    Ok((
        Factors {
            v,
            d,
            sigma,
            residual,
            unconverged: None,
        },
        lambda,
    ))
}

/// How the iterative solver stops.
#[derive(Clone, Copy, Debug)]
pub enum Stop {
    /// Halko's fixed number of power iterations.
    PowerIterations(usize),
    /// Until every kept triplet's residual is below [`EXACT_TOLERANCE`]·σ₀.
    Converged,
}

/// Rank-k truncated SVD by subspace iteration with `l = k + oversampling` vectors.
pub fn iterative(
    x: &Block,
    k: usize,
    oversampling: usize,
    stop: Stop,
    seed: u64,
    cancelled: &dyn Fn() -> bool,
) -> Result<Factors, String> {
    let n = x.cols.min(x.rows);
    let l = (k + oversampling).min(n).max(k);
    if k == 0 {
        return Ok(Factors {
            v: Mat::zeros(x.cols, 0),
            d: Mat::zeros(x.rows, 0),
            sigma: vec![],
            residual: x.energy,
            unconverged: None,
        });
    }
    let precision = match stop {
        Stop::PowerIterations(_) => Precision::F32,
        Stop::Converged => Precision::F64,
    };
    let omega = Mat::<f64>::from_fn(x.cols, l, |i, j| gaussian(seed, i, j));
    let mut y = x.mul(omega.as_ref(), precision);
    let mut iteration = 0;
    let mut unconverged = None;
    let (v, sigma, d_from_iteration) = loop {
        if cancelled() {
            return Err("cancelled".into());
        }
        let q = y.qr().compute_thin_Q();
        let z = x.tmul(q.as_ref(), precision);
        // Z = Xᵀ Q = W S Pᵀ, so Qᵀ X = P S Wᵀ: W are right singular vectors, U = Q P.
        let svd = z
            .thin_svd()
            .map_err(|e| format!("SVD of the sketch did not converge: {e:?}"))?;
        let sigma: Vec<f64> = (0..l).map(|i| svd.S().column_vector()[i]).collect();
        let w = svd.U().subcols(0, k).to_owned();
        match stop {
            Stop::PowerIterations(q_max) => {
                if iteration == q_max {
                    break (w, sigma, None);
                }
                y = x.mul(svd.U(), precision);
            }
            Stop::Converged => {
                y = x.mul(svd.U(), precision);
                // ‖X vᵢ − σᵢ uᵢ‖ with uᵢ = Q pᵢ.
                let u = &q * svd.V();
                let s0 = sigma[0].max(f64::MIN_POSITIVE);
                let worst = (0..k)
                    .map(|i| {
                        (0..x.rows)
                            .map(|r| (y[(r, i)] - sigma[i] * u[(r, i)]).powi(2))
                            .sum::<f64>()
                            .sqrt()
                            / s0
                    })
                    .fold(0f64, f64::max);
                if worst <= EXACT_TOLERANCE || sigma[0] == 0.0 {
                    let d = y.subcols(0, k).to_owned();
                    break (w, sigma, Some(d));
                }
                if iteration + 1 >= EXACT_MAX_ITERATIONS {
                    unconverged = Some(worst);
                    let d = y.subcols(0, k).to_owned();
                    break (w, sigma, Some(d));
                }
            }
        }
        iteration += 1;
    };
    let d = match d_from_iteration {
        Some(d) => d,
        None => {
            // f64 even for `randomized`: with f32 the kept energy carries ~1e-6 relative error,
            // which is most of a small residual, and the reported RMSE would be wrong.
            x.mul(v.as_ref(), Precision::F64)
        }
    };
    let kept: f64 = (0..k)
        .map(|kk| (0..x.rows).map(|r| d[(r, kk)] * d[(r, kk)]).sum::<f64>())
        .sum();
    Ok(Factors {
        v,
        d,
        sigma: sigma[..k].to_vec(),
        residual: (x.energy - kept).max(0.0),
        unconverged,
    })
}

/// Σ f(v) in a fixed order with eight independent accumulators, which lets the compiler
/// vectorise what a single running sum (a dependency chain) cannot.
pub fn lanes_sum(values: &[f32], f: impl Fn(f32) -> f64) -> f64 {
    let mut acc = [0f64; 8];
    let chunks = values.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for k in 0..8 {
            acc[k] += f(c[k]);
        }
    }
    let tail: f64 = rest.iter().map(|&v| f(v)).sum();
    acc.iter().sum::<f64>() + tail
}

/// A standard normal sample, a pure function of (seed, i, j) (Box–Muller on two hashed uniforms).
fn gaussian(seed: u64, i: usize, j: usize) -> f64 {
    let h = crate::support::rng::hash(seed, &[i as u64, j as u64]);
    let u1 = 1.0 - crate::support::rng::unit(h); // (0, 1]: ln is finite
    let u2 = crate::support::rng::unit(crate::support::rng::mix(h));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A T×n matrix with a known spectrum: orthonormal factors from faer's QR of hashed noise.
    fn synthetic(t: usize, n: usize, sigma: &[f64]) -> Vec<f32> {
        let r = sigma.len();
        let a = Mat::<f64>::from_fn(t, r, |i, j| gaussian(1, i, j));
        let b = Mat::<f64>::from_fn(n, r, |i, j| gaussian(2, i, j));
        let (u, v) = (a.qr().compute_thin_Q(), b.qr().compute_thin_Q());
        let mut out = vec![0f32; t * n];
        for j in 0..n {
            for i in 0..t {
                out[j * t + i] = (0..r)
                    .map(|k| u[(i, k)] * sigma[k] * v[(j, k)])
                    .sum::<f64>() as f32;
            }
        }
        out
    }

    fn brute_sigma(data: &[f32], t: usize, n: usize, centring: Centring) -> Vec<f64> {
        let m = Mat::<f64>::from_fn(t, n, |i, j| data[j * t + i] as f64);
        let mean_c: Vec<f64> = (0..n)
            .map(|j| m.col(j).iter().sum::<f64>() / t as f64)
            .collect();
        let mean_r: Vec<f64> = (0..t)
            .map(|i| (0..n).map(|j| m[(i, j)]).sum::<f64>() / n as f64)
            .collect();
        let x = Mat::<f64>::from_fn(t, n, |i, j| match centring {
            Centring::Columns => m[(i, j)] - mean_c[j],
            Centring::Texels => m[(i, j)] - mean_r[i],
        });
        let mut s: Vec<f64> = x
            .thin_svd()
            .unwrap()
            .S()
            .column_vector()
            .iter()
            .copied()
            .collect();
        s.sort_by(|a, b| b.total_cmp(a));
        s
    }

    fn values(m: &Mat<f64>) -> Vec<f64> {
        (0..m.ncols())
            .flat_map(|j| m.col_as_slice(j).to_vec())
            .collect()
    }

    #[test]
    fn products_match_a_dense_reference_in_both_centrings() {
        let (t, n) = (300, 70); // not multiples of the panel sizes
        let data: Vec<f32> = (0..t * n)
            .map(|i| crate::support::rng::unit(crate::support::rng::hash(3, &[i as u64])) as f32)
            .collect();
        for centring in [Centring::Columns, Centring::Texels] {
            let x = Block::new(&data, t, n, 0, t, centring);
            let dense = Mat::<f64>::from_fn(t, n, |i, j| data[j * t + i] as f64 - x.centre(i, j));
            let m = Mat::<f64>::from_fn(n, 5, |i, j| gaussian(4, i, j));
            let q = Mat::<f64>::from_fn(t, 5, |i, j| gaussian(5, i, j));
            let (ym, zq) = (&dense * &m, dense.transpose() * &q);
            for (prec, tol) in [(Precision::F64, 1e-12), (Precision::F32, 1e-5)] {
                // f64: summation order only (~n ε); f32: panel rounding, ~√n · 6e-8 relative.
                let y = x.mul(m.as_ref(), prec);
                let z = x.tmul(q.as_ref(), prec);
                assert!(
                    (&y - &ym).norm_max() <= tol * ym.norm_max(),
                    "{centring:?} {prec:?}"
                );
                assert!(
                    (&z - &zq).norm_max() <= tol * zq.norm_max(),
                    "{centring:?} {prec:?}"
                );
            }
            let energy: f64 = dense.squared_norm_l2();
            assert!((x.energy - energy).abs() <= 1e-12 * energy);
        }
    }

    #[test]
    fn iterative_exact_agrees_with_dense_and_brute_force() {
        // 20 components with a slowly decaying spectrum (ratio 0.8), the hard case for subspace
        // iteration, plus a column offset the centring must remove.
        let (t, n) = (400, 120);
        let spectrum: Vec<f64> = (0..20).map(|i| 10.0 * 0.8f64.powi(i)).collect();
        let mut data = synthetic(t, n, &spectrum);
        for j in 0..n {
            for i in 0..t {
                data[j * t + i] += 0.5 + 0.01 * j as f32;
            }
        }
        let x = Block::new(&data, t, n, 0, t, Centring::Columns);
        let brute = brute_sigma(&data, t, n, Centring::Columns);
        let (dense_f, lambda) = dense(&x, &|_| 6).unwrap();
        let it = iterative(&x, 6, 6, Stop::Converged, 9, &|| false).unwrap();
        assert!(it.unconverged.is_none());
        for k in 0..6 {
            // Reference: faer's SVD of the dense centred matrix (f32 input, so 1e-6 relative).
            assert!(
                (dense_f.sigma[k] - brute[k]).abs() <= 1e-6 * brute[0],
                "dense σ{k}"
            );
            assert!(
                (it.sigma[k] - brute[k]).abs() <= 1e-6 * brute[0],
                "iterative σ{k}"
            );
            assert!((lambda[k].sqrt() - brute[k]).abs() <= 1e-6 * brute[0]);
        }
        let ey: f64 = brute[6..].iter().map(|s| s * s).sum();
        // Eckart–Young: both residuals are the discarded energy (1e-4 relative, the bound).
        assert!(
            (dense_f.residual - ey).abs() <= 1e-4 * ey,
            "{} vs {ey}",
            dense_f.residual
        );
        assert!(
            (it.residual - ey).abs() <= 1e-4 * ey,
            "{} vs {ey}",
            it.residual
        );
    }

    #[test]
    fn randomized_is_near_optimal_and_survives_rank_deficiency() {
        let (t, n) = (500, 90);
        let spectrum: Vec<f64> = (0..30).map(|i| 5.0 * 0.7f64.powi(i)).collect();
        let data = synthetic(t, n, &spectrum);
        let x = Block::new(&data, t, n, 0, t, Centring::Columns);
        let brute = brute_sigma(&data, t, n, Centring::Columns);
        for k in [4, 8, 16] {
            let f = iterative(&x, k, 10, Stop::PowerIterations(2), 0, &|| false).unwrap();
            let ey: f64 = brute[k..].iter().map(|s| s * s).sum();
            // Halko et al. with p = 10, q = 2 on a geometric spectrum: within 2% in RMSE, and
            // never below the optimum (beyond rounding).
            let ratio = (f.residual / ey).sqrt();
            assert!((1.0 - 1e-6..1.02).contains(&ratio), "k {k}: ratio {ratio}");
        }
        // Rank 3 data asked for rank 8 (l = 18 > rank): no NaN, the residual is ~0.
        let low = synthetic(t, n, &[3.0, 2.0, 1.0]);
        let x = Block::new(&low, t, n, 0, t, Centring::Columns);
        let f = iterative(&x, 8, 10, Stop::PowerIterations(2), 0, &|| false).unwrap();
        assert!(values(&f.v).iter().all(|v| v.is_finite()));
        assert!(values(&f.d).iter().all(|v| v.is_finite()));
        assert!(f.residual <= 1e-8 * x.energy, "{}", f.residual);
        let f = iterative(&x, 8, 10, Stop::Converged, 0, &|| false).unwrap();
        assert!(f.sigma.iter().all(|s| s.is_finite()));
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let (t, n) = (600, 150);
        let data = synthetic(t, n, &[4.0, 3.0, 2.0, 1.0, 0.5, 0.25]);
        let run = |threads| {
            mesoflow_testkit::threads::with_threads(threads, || {
                let x = Block::new(&data, t, n, 0, t, Centring::Texels);
                let f = iterative(&x, 3, 5, Stop::PowerIterations(2), 1, &|| false).unwrap();
                (
                    f.residual.to_bits(),
                    values(&f.d).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                )
            })
        };
        assert_eq!(run(1), run(3));
    }
}
