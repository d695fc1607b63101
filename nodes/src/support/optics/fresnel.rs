//! Fresnel reflectance of a smooth dielectric boundary seen from inside the medium, and its
//! angular moments, computed from the exact formula rather than a fitted polynomial so that
//! the better dipole and photon beam diffusion stay right for any η (including η < 1, where
//! the fits of the literature are least tested).

/// Unpolarised Fresnel reflectance for light inside a medium of relative index
/// η = n_inside / n_outside reaching the boundary at cosine `cos_i` (0 < cos_i ≤ 1).
/// Total internal reflection gives 1.
pub fn reflectance_inside(cos_i: f64, eta: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    // n1 = η (inside), n2 = 1 (outside).
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// The i-th Fresnel moment ∫₀¹ Fr(μ) μ^i dμ of the inside reflectance (d'Eon 2012's F̄r,i).
/// Simpson's rule on each side of the critical cosine, where Fr has a kink.
pub fn moment(i: i32, eta: f64) -> f64 {
    let f = |mu: f64| reflectance_inside(mu, eta) * mu.powi(i);
    let critical = if eta > 1.0 {
        (1.0 - 1.0 / (eta * eta)).sqrt()
    } else {
        0.0
    };
    simpson(f, 0.0, critical, 2000) + simpson(f, critical, 1.0, 2000)
}

fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    if b <= a {
        return 0.0;
    }
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for k in 1..n {
        s += f(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// Transmittance into a medium of relative index η from outside, at cosine `cos` (1 − Fr seen
/// from outside).
pub fn transmit_in(cos: f64, eta: f64) -> f64 {
    1.0 - reflectance_inside(cos, 1.0 / eta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_matched_index_and_total_internal_reflection() {
        // Closed forms: ((η − 1)/(η + 1))² at normal incidence; 0 for η = 1; 1 beyond the
        // critical angle (sin θc = 1/η).
        assert!((reflectance_inside(1.0, 1.5) - 0.04).abs() < 1e-12);
        assert!(reflectance_inside(0.3, 1.0).abs() < 1e-15);
        let cos_c = (1.0f64 - 1.0 / 1.69).sqrt();
        assert_eq!(reflectance_inside(cos_c - 1e-6, 1.3), 1.0);
        assert!(reflectance_inside(cos_c + 1e-3, 1.3) < 1.0);
        assert!(reflectance_inside(0.5, 0.8) < 1.0);
    }

    #[test]
    fn moments_agree_with_the_published_boundary_constants() {
        // 2·F̄r,1 is the hemispherical diffuse reflectance Fdr; Jensen's polynomial fit gives
        // 0.44476 at η = 1.3 (domain notes) and the fit is good to about 1e-2.
        assert!((2.0 * moment(1, 1.3) - 0.44476).abs() < 1e-2);
        // d'Eon's better-dipole boundary A = (1 + 3 F̄r,2)/(1 − 2 F̄r,1) is 2.339 at η = 1.3
        // (domain notes, from pbrt-v3's fitted moments: three decimals, plus the fit's error).
        let a = (1.0 + 3.0 * moment(2, 1.3)) / (1.0 - 2.0 * moment(1, 1.3));
        assert!((a - 2.339).abs() < 5e-3, "{a}");
        // Matched index: no reflection at all.
        assert!(moment(1, 1.0).abs() < 1e-15 && moment(2, 1.0).abs() < 1e-15);
        assert!(moment(1, 0.8).is_finite() && moment(1, 0.8) > 0.0);
    }
}
