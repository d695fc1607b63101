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
//!
//! But P1 is the shape of light that has diffused far from where it entered. Where the light
//! enters around the shaded point itself, transport theory's exact answer for a half-space lit
//! uniformly at incidence μ0 (η = 1, isotropic: Chandrasekhar 1960) is I(μ) ∝ H(μ)H(μ0)/(μ + μ0),
//! close to diffuse, and without the first scattering (H(μ)H(μ0) − 1)/(μ + μ0). `half_space`
//! splits each pixel's exitance: the share its own light would return on a plane under the same
//! irradiance (at most all of it) leaves with that local shape, the rest, light from elsewhere,
//! with the deep field's H(μ). Exact in both limits, at η = 1 only; g ≠ 0 through the reduced
//! albedo.

use crate::support::optics::chandrasekhar::h_function;
use crate::support::optics::fresnel;
use crate::support::optics::fresnel::transmit_in;
use crate::types::ScatteringMaterial;
use mesoflow_runtime::NodeError;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The angular distribution of the multiply scattered light that leaves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Emission {
    /// Diffuse behind the boundary: Ft(μo)·M/(π(1 − Fdr)).
    Diffuse,
    /// Diffusion's own P1 radiance at the boundary, 1 + 3μ′/(2A) inside, refracted out.
    #[default]
    P1,
    /// Chandrasekhar's exact shapes: local light as a half-space lit at the point's own
    /// incidence, light from elsewhere as the deep field (η = 1 only).
    HalfSpace,
}

/// The pixel's own light, for `half_space`: the cosine of its incidence and, per channel, the
/// exitance a plane under the same irradiance would return.
pub(super) struct Local {
    pub(super) mu0: f64,
    pub(super) exitance: [f64; 3],
}

/// Points of the μ tables (0 to 1).
const TABLE: usize = 129;

/// Per channel, H on a grid of μ and the two shapes' normalisations.
#[derive(Clone, Debug)]
pub(super) struct HalfSpaceShapes {
    h: [Vec<f64>; 3],
    /// 2π∫H(μ)μ dμ.
    far_norm: [f64; 3],
    /// Over μ0 on the grid: 2π∫K(μ; μ0)μ dμ.
    local_norm: [Vec<f64>; 3],
    multiple_only: bool,
}

fn lerp(table: &[f64], x: f64) -> f64 {
    let f = x.clamp(0.0, 1.0) * (table.len() - 1) as f64;
    let i = (f.floor() as usize).min(table.len() - 2);
    let t = f - i as f64;
    table[i] * (1.0 - t) + table[i + 1] * t
}

impl HalfSpaceShapes {
    fn new(m: &ScatteringMaterial, multiple_only: bool) -> HalfSpaceShapes {
        let grid = |i: usize| i as f64 / (TABLE - 1) as f64;
        let h = [0, 1, 2].map(|c| {
            let (sp, sa) = (m.sigma_s_prime[c], m.sigma_a[c]);
            let h = h_function(if sp + sa > 0.0 { sp / (sp + sa) } else { 0.0 });
            (0..TABLE).map(|i| h(grid(i))).collect::<Vec<f64>>()
        });
        let mut shapes = HalfSpaceShapes {
            h,
            far_norm: [1.0; 3],
            local_norm: [vec![1.0; TABLE], vec![1.0; TABLE], vec![1.0; TABLE]],
            multiple_only,
        };
        // Midpoint rule on μ: K(μ; μ0) is finite for μ + μ0 > 0.
        let steps = 512;
        let mids: Vec<f64> = (0..steps)
            .map(|k| (k as f64 + 0.5) / steps as f64)
            .collect();
        for c in 0..3 {
            shapes.far_norm[c] =
                2.0 * PI * mids.iter().map(|&mu| shapes.far(c, mu) * mu).sum::<f64>()
                    / steps as f64;
            shapes.local_norm[c] = (0..TABLE)
                .map(|i| {
                    2.0 * PI
                        * mids
                            .iter()
                            .map(|&mu| shapes.local(c, mu, grid(i)) * mu)
                            .sum::<f64>()
                        / steps as f64
                })
                .collect();
        }
        shapes
    }

    fn far(&self, c: usize, mu: f64) -> f64 {
        lerp(&self.h[c], mu)
    }

    fn local(&self, c: usize, mu: f64, mu0: f64) -> f64 {
        let hh = lerp(&self.h[c], mu) * lerp(&self.h[c], mu0);
        let k = if self.multiple_only { hh - 1.0 } else { hh };
        k.max(0.0) / (mu + mu0).max(1e-9)
    }

    /// Radiance towards `mu` per channel for exitance `m`, of which `local` is the pixel's own.
    fn radiance(&self, mu: f64, m: [f64; 3], local: Option<&Local>) -> [f64; 3] {
        [0, 1, 2].map(|c| {
            let own = local.map_or(0.0, |l| l.exitance[c].clamp(0.0, m[c].max(0.0)));
            let far = self.far(c, mu) / self.far_norm[c];
            let near = match local {
                Some(l) if own > 0.0 => {
                    let norm = lerp(&self.local_norm[c], l.mu0);
                    if norm > 0.0 {
                        self.local(c, mu, l.mu0) / norm
                    } else {
                        far
                    }
                }
                _ => far,
            };
            own * near + (m[c] - own) * far
        })
    }
}

/// Radiance per unit exitance as a function of the viewing cosine, for one boundary.
#[derive(Clone, Debug)]
pub(super) struct Exit {
    eta: f64,
    /// 3/(2A): 0 for `Diffuse`.
    slope: f64,
    /// ∫ Ft(μo)·(1 + slope·μ′(μo))·μo dωo over the hemisphere.
    norm: f64,
    /// With `half_space`, its shapes.
    half_space: Option<HalfSpaceShapes>,
}

impl Exit {
    /// The shapes for `material`; `multiple_only` when single scattering is rendered apart.
    pub(super) fn for_material(
        emission: Emission,
        material: &ScatteringMaterial,
        multiple_only: bool,
    ) -> Result<Exit, NodeError> {
        let mut exit = Exit::new(emission, material.eta);
        if emission == Emission::HalfSpace {
            if material.eta != 1.0 {
                return Err(NodeError::param(
                    "emission",
                    format!(
                        "half_space is the exact angular shape behind an index-matched boundary; the material has η = {} (set eta: 1 on sss.material, or emission: diffuse or p1)",
                        material.eta
                    ),
                ));
            }
            exit.half_space = Some(HalfSpaceShapes::new(material, multiple_only));
        }
        Ok(exit)
    }

    pub(super) fn new(emission: Emission, eta: f64) -> Exit {
        let slope = match emission {
            Emission::Diffuse | Emission::HalfSpace => 0.0,
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
            half_space: None,
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

    /// Radiance per channel towards cosine `mu` for exitance `m`; `local` is the pixel's own
    /// light, which only `half_space` tells apart.
    pub(super) fn leaving(&self, mu: f64, m: [f64; 3], local: Option<&Local>) -> [f64; 3] {
        let mu = mu.clamp(0.0, 1.0);
        match &self.half_space {
            Some(shapes) => shapes.radiance(mu, m, local),
            None => {
                let k = self.radiance(mu);
                m.map(|v| v * k)
            }
        }
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
        let h = crate::support::optics::chandrasekhar::h_function(1.0);
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

    #[test]
    fn half_space_keeps_the_exitance_and_gives_chandrasekhars_radiance() {
        // A half-space of albedo 0.9 lit uniformly at μ0 = 0.5 returns R(μ0) = 1 − H(μ0)√(1 − ω)
        // (HalfSpace::total, Chandrasekhar's closed form for the reflectance) with the radiance
        // E·ω/(4π)·μ0·H(μ)H(μ0)/(μ + μ0): given that exitance as the pixel's own, the shape must
        // reproduce that radiance, which checks its tables and normalisation against an
        // identity of the H function rather than against themselves.
        let omega = 0.9;
        let m = ScatteringMaterial {
            sigma_s_prime: [omega; 3],
            sigma_a: [1.0 - omega; 3],
            eta: 1.0,
            g: 0.0,
        };
        let exit = Exit::for_material(Emission::HalfSpace, &m, false).unwrap();
        let (e, mu0) = (2.0, 0.5);
        let r = crate::support::optics::chandrasekhar::HalfSpace::new(omega).total(mu0);
        let own = Local {
            mu0,
            exitance: [e * mu0 * r; 3],
        };
        let h = h_function(omega);
        for mu in [0.1, 0.5, 0.9] {
            let got = exit.leaving(mu, own.exitance, Some(&own))[0];
            let want = e * omega / (4.0 * PI) * mu0 * h(mu) * h(mu0) / (mu + mu0);
            // The tables' linear interpolation on 129 points: 0.5%.
            assert!(
                (got - want).abs() < 5e-3 * want,
                "μ {mu}: {got} against {want}"
            );
        }
        // Any split of the exitance between the pixel's own light and light from elsewhere
        // leaves as the same exitance.
        for share in [0.0, 0.4, 1.0] {
            let own = Local {
                mu0: 0.3,
                exitance: [share; 3],
            };
            let steps = 1000;
            let flux: f64 = (0..steps)
                .map(|k| {
                    let mu = (k as f64 + 0.5) / steps as f64;
                    2.0 * PI * exit.leaving(mu, [1.0; 3], Some(&own))[1] * mu / steps as f64
                })
                .sum();
            assert!((flux - 1.0).abs() < 2e-3, "share {share}: exitance {flux}");
        }
        let refused = Exit::for_material(
            Emission::HalfSpace,
            &ScatteringMaterial { eta: 1.3, ..m },
            false,
        );
        assert!(refused.is_err());
    }
}
