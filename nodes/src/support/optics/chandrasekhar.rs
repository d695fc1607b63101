//! Chandrasekhar's H function of isotropic scattering, and with it the exact reflectance of a
//! semi-infinite medium behind an index-matched boundary (Chandrasekhar 1960, §§27, 39): the
//! transport theory's answer that diffusion profiles approximate. Used by `sss.render`'s
//! `albedo: half_space` and by the volumetric reference's test.

/// Midpoints of [0, 1] the integral equation is solved on.
const GRID: usize = 400;

/// H(μ) for single-scattering albedo ω ∈ [0, 1], from the form
/// 1/H(μ) = √(1 − ω) + (ω/2) ∫₀¹ μ′H(μ′)/(μ + μ′) dμ′, which converges in tens of iterations
/// even near ω = 1 (the textbook form 1/H = 1 − (ω/2) μ ∫ H/(μ + μ′) needs thousands there).
pub fn h_function(omega: f64) -> impl Fn(f64) -> f64 {
    let omega = omega.clamp(0.0, 1.0);
    let root = (1.0 - omega).sqrt();
    let grid: Vec<f64> = (0..GRID).map(|i| (i as f64 + 0.5) / GRID as f64).collect();
    let at = move |grid: &[f64], h: &[f64], m: f64| {
        let s: f64 = grid
            .iter()
            .zip(h)
            .map(|(g, v)| g * v / (m + g))
            .sum::<f64>()
            / GRID as f64;
        1.0 / (root + 0.5 * omega * s)
    };
    let mut h = vec![1.0; GRID];
    for _ in 0..500 {
        let next: Vec<f64> = grid.iter().map(|&m| at(&grid, &h, m)).collect();
        let change = next
            .iter()
            .zip(&h)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        h = next;
        if change < 1e-13 {
            break;
        }
    }
    move |m| at(&grid, &h, m)
}

/// A semi-infinite isotropic medium of albedo ω behind an index-matched boundary, lit at
/// cosine μ₀: the share of the light it reflects, in all (1 − H(μ₀)√(1 − ω)) and after one
/// scattering only ((ω/2)(1 − μ₀ ln(1 + 1/μ₀))), tabulated over μ₀.
pub struct HalfSpace {
    total: Vec<f64>,
    single: Vec<f64>,
}

/// Cosines the reflectances are tabulated at, uniformly in μ₀ including 0 and 1.
const TABLE: usize = 129;

impl HalfSpace {
    pub fn new(omega: f64) -> HalfSpace {
        let h = h_function(omega);
        let root = (1.0 - omega.clamp(0.0, 1.0)).sqrt();
        let mu = |i: usize| i as f64 / (TABLE - 1) as f64;
        HalfSpace {
            total: (0..TABLE).map(|i| 1.0 - h(mu(i)) * root).collect(),
            single: (0..TABLE)
                .map(|i| {
                    let m = mu(i);
                    // μ ln(1 + 1/μ) → 0 as μ → 0.
                    let tail = if m > 0.0 {
                        m * (1.0 + 1.0 / m).ln()
                    } else {
                        0.0
                    };
                    0.5 * omega * (1.0 - tail)
                })
                .collect(),
        }
    }

    fn lookup(table: &[f64], mu0: f64) -> f64 {
        let f = mu0.clamp(0.0, 1.0) * (TABLE - 1) as f64;
        let i = (f.floor() as usize).min(TABLE - 2);
        let t = f - i as f64;
        table[i] * (1.0 - t) + table[i + 1] * t
    }

    /// Everything reflected at incidence cosine `mu0`.
    pub fn total(&self, mu0: f64) -> f64 {
        Self::lookup(&self.total, mu0)
    }

    /// What is reflected after two or more scatterings at incidence cosine `mu0`.
    pub fn multiple(&self, mu0: f64) -> f64 {
        Self::lookup(&self.total, mu0) - Self::lookup(&self.single, mu0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn h_integrates_to_its_closed_form_moment() {
        // ∫₀¹ H(μ) dμ = (2/ω)(1 − √(1 − ω)) (Chandrasekhar 1960, §39, the zeroth moment).
        for omega in [0.999, 0.9, 0.6] {
            let (n, h) = (400, h_function(omega));
            let mean = (0..n).map(|i| h((i as f64 + 0.5) / n as f64)).sum::<f64>() / n as f64;
            let want = 2.0 / omega * (1.0 - (1.0 - omega).sqrt());
            assert!(
                (mean - want).abs() < 1e-3 * want,
                "ω {omega}: {mean} vs {want}"
            );
        }
    }

    #[test]
    fn a_conservative_medium_reflects_everything_and_single_scattering_has_its_closed_form() {
        // ω = 1: all light comes back, whatever the incidence. At normal incidence one
        // scattering returns (ω/2)(1 − ln 2) (sss.render's half-space test has the same).
        let white = HalfSpace::new(1.0);
        for mu in [0.05, 0.5, 1.0] {
            assert!((white.total(mu) - 1.0).abs() < 1e-9, "{mu}");
        }
        let grey = HalfSpace::new(0.6);
        let single = grey.total(1.0) - grey.multiple(1.0);
        assert!((single - 0.3 * (1.0 - 2f64.ln())).abs() < 1e-12);
        // Grazing light comes back more than normal light (van de Hulst's tables' trend).
        assert!(grey.total(0.1) > grey.total(1.0));
    }
}
