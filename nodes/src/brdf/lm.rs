//! Levenberg–Marquardt with Marquardt's diagonal scaling and bounds by projection, for the small
//! per-pixel fits (5 Ward parameters, or 7 with the normal), on the stack; and the Cholesky
//! solve its steps need.

/// Minimises `cost` from `x`, with `normal_equations(x)` = (JᵀJ, Jᵀr) and `project` keeping a
/// step inside the bounds. `scale` is Σ obs² (a cost this far below it is an exact fit).
/// Returns the parameters and whether they converged: a step lowered the cost by less than
/// `tol` of it, or no step lowers it any more (a minimum to working precision).
pub fn minimise<const N: usize>(
    mut x: [f64; N],
    iterations: u32,
    tol: f64,
    scale: f64,
    cost: impl Fn(&[f64; N]) -> f64,
    normal_equations: impl Fn(&[f64; N]) -> ([[f64; N]; N], [f64; N]),
    project: impl Fn(&mut [f64; N]),
) -> ([f64; N], bool) {
    let mut c = cost(&x);
    let mut lambda = 1e-3;
    for _ in 0..iterations {
        if c <= 1e-30 * scale.max(1e-300) {
            return (x, true);
        }
        let (a, g) = normal_equations(&x);
        let dmax = (0..N).map(|u| a[u][u]).fold(0.0f64, f64::max);
        loop {
            let mut m = a;
            for (u, row) in m.iter_mut().enumerate() {
                row[u] += lambda * (a[u][u] + 1e-12 * dmax);
            }
            let Some(step) = solve(m, g) else {
                lambda *= 10.0;
                if lambda > 1e12 {
                    return (x, true);
                }
                continue;
            };
            let mut next = x;
            for (v, s) in next.iter_mut().zip(&step) {
                *v -= s;
            }
            project(&mut next);
            let cn = cost(&next);
            if cn.is_finite() && cn < c {
                let done = c - cn <= tol * cn;
                x = next;
                c = cn;
                lambda = (lambda / 3.0).max(1e-12);
                if done {
                    return (x, true);
                }
                break;
            }
            lambda *= 4.0;
            if lambda > 1e12 {
                return (x, true);
            }
        }
    }
    (x, false)
}

/// Cholesky solve of a symmetric positive definite system; `None` if it is not.
pub fn solve<const N: usize>(a: [[f64; N]; N], b: [f64; N]) -> Option<[f64; N]> {
    let mut l = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let s = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; N];
    for i in 0..N {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0; N];
    for i in (0..N).rev() {
        x[i] = (y[i] - (i + 1..N).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    #[test]
    fn solves_a_known_system_and_refuses_an_indefinite_one() {
        // A = [[4, 2], [2, 3]], b = A · [1, −2] = [0, −4] (worked by hand).
        let x = super::solve([[4.0, 2.0], [2.0, 3.0]], [0.0, -4.0]).unwrap();
        assert!(
            (x[0] - 1.0).abs() < 1e-12 && (x[1] + 2.0).abs() < 1e-12,
            "{x:?}"
        );
        assert!(super::solve([[1.0, 2.0], [2.0, 1.0]], [1.0, 1.0]).is_none());
    }
}
