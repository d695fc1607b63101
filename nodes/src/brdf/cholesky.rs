//! Cholesky solves of the small symmetric positive definite systems Levenberg–Marquardt steps
//! produce (5 and 7 unknowns), on the stack.

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
