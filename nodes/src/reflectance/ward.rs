//! The isotropic Ward BRDF on a flat sample, as the fit sees it: per direction pair the
//! geometry is fixed, so a captured value is
//! `I = cosθi · (ρd/π + ρs · S(α))`, `S(α) = exp(−tan²δ/α²) / (4π α² √(cosθi cosθo))`,
//! linear in ρd and ρs, and the derivative in α is `∂S/∂α = S · (2 tan²δ/α³ − 2/α)`.

use crate::types::DirectionPair;
use std::f64::consts::PI;

/// The widest Ward lobe a fit may reach.
pub const ALPHA_MAX: f64 = 2.0;

/// The largest specular albedo: Ward's ρs is the lobe's share of the light it reflects, so
/// above 1 it would create energy. Without the bound a pixel whose data no Ward lobe explains
/// (a GGX capture's Fresnel rise at grazing angles) could run to ρs ≈ 1e48 at the narrowest α.
pub const RHO_S_MAX: f64 = 1.0;

/// The bounds of a Ward parameter vector (ρd RGB, ρs, α, …): reflectances not negative, ρs at
/// most RHO_S_MAX, α in [alpha_min, ALPHA_MAX]; entries past α are left alone.
pub fn clamp_ward(x: &mut [f64], alpha_min: f64) {
    for v in x.iter_mut().take(4) {
        *v = v.max(0.0);
    }
    x[3] = x[3].min(RHO_S_MAX);
    x[4] = x[4].clamp(alpha_min, ALPHA_MAX);
}

/// What a direction pair contributes to every pixel's model.
#[derive(Clone, Copy, Debug)]
pub struct PairGeometry {
    pub cos_i: f64,
    pub cos_o: f64,
    pub tan2_delta: f64,
}

impl PairGeometry {
    /// For the flat normal (0, 0, 1).
    pub fn flat(pair: &DirectionPair) -> PairGeometry {
        PairGeometry::with_normal(pair, [0.0, 0.0, 1.0])
    }

    /// For a unit normal `n` in the frame of the direction vectors (a tilted pixel). Where
    /// n · h ≤ 0 the lobe is empty (tan²δ = ∞).
    pub fn with_normal(pair: &DirectionPair, n: [f64; 3]) -> PairGeometry {
        let (wi, wo) = (pair.light.vector(), pair.view.vector());
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let h = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
        let len2 = dot(h, h);
        let nh = dot(n, h);
        let cd2 = nh * nh / len2;
        PairGeometry {
            cos_i: dot(n, wi),
            cos_o: dot(n, wo),
            tan2_delta: if nh > 0.0 {
                (1.0 - cd2).max(0.0) / cd2
            } else {
                f64::INFINITY
            },
        }
    }

    /// The specular lobe S(α) and its α-derivative; 0 where either cosine is not positive.
    pub fn lobe(&self, alpha: f64) -> (f64, f64) {
        if self.cos_i <= 0.0 || self.cos_o <= 0.0 {
            return (0.0, 0.0);
        }
        let a2 = alpha * alpha;
        let s = (-self.tan2_delta / a2).exp() / (4.0 * PI * a2 * (self.cos_i * self.cos_o).sqrt());
        (s, s * (2.0 * self.tan2_delta / (a2 * alpha) - 2.0 / alpha))
    }

    /// The captured value of one channel.
    pub fn value(&self, rho_d: f64, rho_s: f64, alpha: f64) -> f64 {
        self.cos_i.max(0.0) * (rho_d / PI + rho_s * self.lobe(alpha).0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reflectance::models::{eval, Model};
    use crate::types::Direction;

    #[test]
    fn agrees_with_the_capture_brdf_and_its_own_derivative() {
        // Against btf::brdf::eval (the vector form the capture renderer uses) times cos θi, and
        // the α-derivative against a central difference (h = 1e-6: error O(h²) ≈ 1e-12 relative,
        // rounding ≈ 1e-10; bound 1e-6).
        let pairs = [
            (Direction::degrees(0.0, 0.0), Direction::degrees(20.0, 90.0)),
            (
                Direction::degrees(30.0, 45.0),
                Direction::degrees(30.0, 225.0),
            ),
            (
                Direction::degrees(60.0, 10.0),
                Direction::degrees(15.0, 200.0),
            ),
        ];
        for (view, light) in pairs {
            let g = PairGeometry::flat(&DirectionPair { view, light });
            for alpha in [0.05, 0.2, 0.6] {
                let want = eval(
                    Model::Ward,
                    0.3,
                    0.2,
                    alpha,
                    [0.0, 0.0, 1.0],
                    light.vector(),
                    view.vector(),
                ) * light.theta.cos();
                let got = g.value(0.3, 0.2, alpha);
                assert!((got - want).abs() < 1e-12 * want, "{got} vs {want}");
                let h = 1e-6;
                let fd = (g.lobe(alpha + h).0 - g.lobe(alpha - h).0) / (2.0 * h);
                let d = g.lobe(alpha).1;
                assert!((d - fd).abs() <= 1e-6 * fd.abs().max(1e-3), "{d} vs {fd}");
            }
        }
    }

    #[test]
    fn a_tilted_normal_agrees_with_the_capture_brdf() {
        // btf::brdf::eval takes the normal itself (vector form, independent of this code):
        // value = eval(n, wi, wo) · (n · wi) wherever both cosines are positive, 0 elsewhere.
        let n = {
            let v = [0.3f64, -0.2, 0.93];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [v[0] / l, v[1] / l, v[2] / l]
        };
        for (view, light) in [
            (Direction::degrees(0.0, 0.0), Direction::degrees(40.0, 30.0)),
            (
                Direction::degrees(20.0, 90.0),
                Direction::degrees(65.0, 200.0),
            ),
            (
                Direction::degrees(10.0, 0.0),
                Direction::degrees(80.0, 160.0),
            ),
        ] {
            let g = PairGeometry::with_normal(&DirectionPair { view, light }, n);
            let ci = n
                .iter()
                .zip(light.vector())
                .map(|(a, b)| a * b)
                .sum::<f64>();
            let want = if ci > 0.0 {
                eval(
                    Model::Ward,
                    0.3,
                    0.2,
                    0.15,
                    n,
                    light.vector(),
                    view.vector(),
                ) * ci
            } else {
                0.0
            };
            let got = g.value(0.3, 0.2, 0.15);
            assert!(
                (got - want).abs() <= 1e-12 * want.abs().max(1e-12),
                "{got} vs {want}"
            );
        }
    }
}
