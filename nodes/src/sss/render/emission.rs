//! How the diffuse exitance M leaves the surface in angle: the radiance per unit exitance
//! towards a viewer at cosine μo to the normal.
//!
//! Jensen & Buhler 2002 (and the profiles' papers) leave it diffuse behind the boundary:
//! L = Ft(μo)·M/(π(1 − Fdr)). Diffusion theory itself says more: its radiance at the boundary
//! is the P1 expansion L(μ′) = φ/(4π) + 3Eμ′/(4π), and the boundary condition φ = 2A·E sets the
//! ratio, so inside the light that reaches the boundary at cosine μ′ goes as 1 + 3μ′/(2A). Out
//! through the boundary at the refracted cosine μ′(μo), normalised so that the exitance stays M:
//! at η = 1 (A = 1) that is 1.25× the diffuse radiance face-on and 0.5× at grazing, where
//! Chandrasekhar's exact half-space (radiance ∝ H(μ)) gives 1.26× and 0.43×.

use super::setup::transmit_in;
use crate::sss::fresnel;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The angular distribution of the multiply scattered light that leaves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Emission {
    /// Diffuse behind the boundary: Ft(μo)·M/(π(1 − Fdr)).
    #[default]
    Diffuse,
    /// Diffusion's own P1 radiance at the boundary, 1 + 3μ′/(2A) inside, refracted out.
    P1,
}

/// Radiance per unit exitance as a function of the viewing cosine, for one boundary.
#[derive(Clone, Copy, Debug)]
pub(super) struct Exit {
    eta: f64,
    /// 3/(2A): 0 for `Diffuse`.
    slope: f64,
    /// ∫ Ft(μo)·(1 + slope·μ′(μo))·μo dωo over the hemisphere.
    norm: f64,
}

impl Exit {
    pub(super) fn new(emission: Emission, eta: f64) -> Exit {
        let slope = match emission {
            Emission::Diffuse => 0.0,
            // d'Eon 2012's boundary from the exact Fresnel moments of the inside reflectance.
            Emission::P1 => {
                let a =
                    (1.0 + 3.0 * fresnel::moment(2, eta)) / (1.0 - 2.0 * fresnel::moment(1, eta));
                1.5 / a
            }
        };
        let mut exit = Exit {
            eta,
            slope,
            norm: 1.0,
        };
        // Simpson's rule on μo; the integrand is smooth (Ft has no kink seen from outside).
        let steps = 2000;
        let h = 1.0 / steps as f64;
        let f = |mu: f64| exit.shape(mu) * mu;
        let mut s = f(0.0) + f(1.0);
        for k in 1..steps {
            s += f(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        exit.norm = 2.0 * PI * s * h / 3.0;
        exit
    }

    /// Unnormalised radiance towards cosine `mu` (0 ≤ mu ≤ 1).
    fn shape(&self, mu: f64) -> f64 {
        let inside = (1.0 - (1.0 - mu * mu) / (self.eta * self.eta))
            .max(0.0)
            .sqrt();
        transmit_in(mu, self.eta) * (1.0 + self.slope * inside)
    }

    /// Radiance towards cosine `mu` per unit exitance.
    pub(super) fn radiance(&self, mu: f64) -> f64 {
        self.shape(mu.clamp(0.0, 1.0)) / self.norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diffuse_is_jensen_and_buhlers_normalisation() {
        // Ft(μo)/(π(1 − Fdr,outside)), Fdr from its own moment: the same numbers the render used
        // before `emission`.
        for eta in [1.0, 1.3, 1.5] {
            let exit = Exit::new(Emission::Diffuse, eta);
            let fdr = 2.0 * fresnel::moment(1, 1.0 / eta);
            for mu in [0.1, 0.5, 1.0] {
                let want = transmit_in(mu, eta) / (PI * (1.0 - fdr));
                assert!((exit.radiance(mu) - want).abs() < 1e-6 * want);
            }
        }
    }

    #[test]
    fn p1_keeps_the_exitance_and_follows_chandrasekhar_at_eta_1() {
        // A conservative half-space's exact radiance is ∝ H(μ) (Chandrasekhar 1960, the ω = 1
        // H function), so per unit exitance it is H(μ)/(2π·∫H(μ)μ dμ). P1's 1 + 1.5μ is the
        // diffusion approximation to it: within 3% for μ ≥ 0.3, 15% at grazing.
        let exit = Exit::new(Emission::P1, 1.0);
        let h = crate::sss::chandrasekhar::h_function(1.0);
        let steps = 400;
        let first: f64 = (0..steps)
            .map(|k| {
                let mu = (k as f64 + 0.5) / steps as f64;
                h(mu) * mu / steps as f64
            })
            .sum();
        for (mu, tol) in [(0.02, 0.16), (0.3, 0.03), (0.6, 0.03), (1.0, 0.03)] {
            let want = h(mu) / (2.0 * PI * first);
            let got = exit.radiance(mu);
            assert!(
                (got - want).abs() < tol * want,
                "μ {mu}: {got} against {want}"
            );
        }
        for eta in [1.0, 1.3] {
            let exit = Exit::new(Emission::P1, eta);
            let steps = 1000;
            let flux: f64 = (0..steps)
                .map(|k| {
                    let mu = (k as f64 + 0.5) / steps as f64;
                    2.0 * PI * exit.radiance(mu) * mu / steps as f64
                })
                .sum();
            assert!((flux - 1.0).abs() < 1e-4, "η {eta}: exitance {flux}");
        }
    }
}
