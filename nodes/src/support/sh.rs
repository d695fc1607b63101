//! Real spherical harmonics: the orthonormal basis `render.mesh` carries environment light in.
//! Order L holds bands 0..L, L² functions; function i = l(l + 1) + m, with
//! Y_l^0 = K_l^0 P_l^0(cos θ), Y_l^m = √2 K_l^m cos(mφ) P_l^m(cos θ) for m > 0 and
//! √2 K_l^|m| sin(|m|φ) P_l^|m|(cos θ) for m < 0, K_l^m = √((2l + 1)/4π · (l − m)!/(l + m)!),
//! θ from +z and φ from +x towards +y (Green, "Spherical Harmonic Lighting: The Gritty Details",
//! 2003). The products of two expansions integrate as the dot product of their coefficients.

use crate::support::geometry::V3;

/// The most bands any caller asks for; factorials up to 2·(MAX_ORDER − 1) stay exact in f64.
pub const MAX_ORDER: usize = 12;

/// Functions in an expansion of `order` bands.
pub const fn count(order: usize) -> usize {
    order * order
}

/// All L² basis functions at unit direction `w`, into `out` (at least L² long).
pub fn basis(order: usize, w: V3, out: &mut [f64]) {
    let order = order.min(MAX_ORDER);
    let z = w[2].clamp(-1.0, 1.0);
    let s = (1.0 - z * z).max(0.0).sqrt();
    let phi = w[1].atan2(w[0]);
    // P_l^m(z) by the standard recurrences, m fixed, l rising.
    let mut p = [[0.0f64; MAX_ORDER]; MAX_ORDER];
    let mut pmm = 1.0;
    for m in 0..order {
        if m > 0 {
            pmm *= -((2 * m - 1) as f64) * s;
        }
        p[m][m] = pmm;
        if m + 1 < order {
            p[m + 1][m] = z * (2 * m + 1) as f64 * pmm;
        }
        for l in m + 2..order {
            p[l][m] = (z * (2 * l - 1) as f64 * p[l - 1][m] - (l + m - 1) as f64 * p[l - 2][m])
                / (l - m) as f64;
        }
    }
    for (l, pl) in p.iter().enumerate().take(order) {
        for m in 0..=l {
            // (l − m)!/(l + m)! as a product, so nothing overflows.
            let ratio: f64 = (l - m + 1..=l + m).map(|k| 1.0 / k as f64).product();
            let k = ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * ratio).sqrt();
            let base = l * (l + 1);
            if m == 0 {
                out[base] = k * pl[0];
            } else {
                let a = std::f64::consts::SQRT_2 * k * pl[m];
                let mf = m as f64 * phi;
                out[base + m] = a * mf.cos();
                out[base - m] = a * mf.sin();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ Y_i Y_j dω by a midpoint rule in (cos θ, φ) fine enough for band 5 (error ~1e-4).
    #[test]
    fn the_basis_is_orthonormal() {
        let order = 5;
        let n = count(order);
        let (rows, cols) = (200, 400);
        let mut gram = vec![0.0; n * n];
        let mut y = vec![0.0; n];
        let dw = 4.0 * std::f64::consts::PI / (rows * cols) as f64;
        for r in 0..rows {
            let z = 1.0 - 2.0 * (r as f64 + 0.5) / rows as f64;
            let s = (1.0 - z * z).sqrt();
            for c in 0..cols {
                let phi = 2.0 * std::f64::consts::PI * (c as f64 + 0.5) / cols as f64;
                basis(order, [s * phi.cos(), s * phi.sin(), z], &mut y);
                for i in 0..n {
                    for j in 0..n {
                        gram[i * n + j] += y[i] * y[j] * dw;
                    }
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!(
                    (gram[i * n + j] - want).abs() < 2e-3,
                    "<Y{i}, Y{j}> = {}",
                    gram[i * n + j]
                );
            }
        }
    }

    #[test]
    fn the_first_bands_have_their_closed_forms() {
        let mut y = [0.0; 4];
        let w = [0.36, 0.48, 0.8];
        basis(2, w, &mut y);
        let c0 = 0.5 / std::f64::consts::PI.sqrt();
        let c1 = (3.0 / (4.0 * std::f64::consts::PI)).sqrt();
        assert!((y[0] - c0).abs() < 1e-12);
        // Y_1^{-1} ∝ y, Y_1^0 ∝ z, Y_1^1 ∝ x (up to the Condon–Shortley sign, −1 here).
        assert!((y[1].abs() - c1 * w[1]).abs() < 1e-12);
        assert!((y[2] - c1 * w[2]).abs() < 1e-12);
        assert!((y[3].abs() - c1 * w[0]).abs() < 1e-12);
    }
}
