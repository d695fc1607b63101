//! `geometry: directional`: the profile scaled by the directional dipole (Frisvad, Hachisuka &
//! Kjeldsen 2014) of each irradiance sample over the same model on a plane lit at normal
//! incidence at the same distance. The directional dipole replaces the point source 1/σt′ deep
//! by a ray source along the refracted light, mirrored in a plane tilted towards the exit point
//! (the modified tangent plane), and takes the flux through the exit point's own normal: light
//! arriving at a grazing angle travels on along the surface, and light leaves a curved or thin
//! part where its surface faces the source. As a ratio it keeps the profile's own energy at
//! normal incidence on a plane (exactly 1 there), and adds only how incidence and shape change
//! it.
//!
//! Constants per the paper: Grosjean's D = (2σa + σs′)/(3σt′²), σtr = √(σa/D), the extrapolation
//! distance de = 2.131·D/√α′, A from the Fresnel moments C₁ = 2F̄r,1 and C₂ = 3F̄r,2 (exact
//! moments, `fresnel.rs`), and the incident direction refracted at the sample's normal. Light
//! that arrives at a sample from the light's far side (bounced light, or a point behind the
//! sample's tangent plane) is taken as arriving along the normal.

use crate::support::geometry::{cross, dot, mul, normalize, sub, V3};
use crate::support::optics::fresnel;
use crate::support::raytrace::light::Light;
use crate::types::ScatteringMaterial;

/// The model's constants per channel, and the light.
pub(super) struct Directional {
    d: [f64; 3],
    sigma_tr: [f64; 3],
    de: [f64; 3],
    /// 1/(3σt′): the real source's distance where the exit faces away from the ray.
    reach: [f64; 3],
    c_phi: f64,
    c_e: f64,
    a: f64,
    eta: f64,
    light: Light,
    /// mm per world unit (sources are in mm, the light in world units).
    unit: f64,
}

impl Directional {
    pub(super) fn new(m: &ScatteringMaterial, light: &Light, unit: f64) -> Directional {
        let per =
            |f: &dyn Fn(f64, f64) -> f64| [0, 1, 2].map(|c| f(m.sigma_s_prime[c], m.sigma_a[c]));
        let d = per(&|sp, sa| (2.0 * sa + sp) / (3.0 * (sp + sa) * (sp + sa)));
        let sigma_tr = [0, 1, 2].map(|c| (m.sigma_a[c] / d[c]).sqrt());
        let albedo = per(&|sp, sa| sp / (sp + sa));
        let de = [0, 1, 2].map(|c| 2.131 * d[c] / albedo[c].sqrt());
        let reach = per(&|sp, sa| 1.0 / (3.0 * (sp + sa)));
        let c1 = 2.0 * fresnel::moment(1, m.eta);
        let c2 = 3.0 * fresnel::moment(2, m.eta);
        let c_phi = 0.25 * (1.0 - c1);
        let c_e = 0.5 * (1.0 - c2);
        Directional {
            d,
            sigma_tr,
            de,
            reach,
            c_phi,
            c_e,
            a: (1.0 - c_e) / (2.0 * c_phi),
            eta: m.eta,
            light: light.clone(),
            unit,
        }
    }

    /// The diffusion of one ray source in an infinite medium, flux and fluence through the exit
    /// normal `no`, from `x` (source to exit, mm), direction `w`, distance `r`.
    fn infinite(&self, c: usize, x: V3, w: V3, r: f64, no: V3) -> f64 {
        let (d, s) = (self.d[c], self.sigma_tr[c] * r);
        let (s1, xw, r2) = (1.0 + s, dot(x, w), r * r);
        let flux =
            3.0 * d * s1 * dot(w, no) - (s1 + 3.0 * d * (3.0 * s1 + s * s) / r2 * xw) * dot(x, no);
        (-s).exp() / (r2 * r) * (self.c_phi * (r2 / d + 3.0 * s1 * xw) - self.c_e * flux)
    }

    /// The directional dipole from a source at `xi` (normal `ni`, refracted light `w12`) to
    /// `xo` (normal `no`), per channel, up to the constant factor the ratio cancels.
    fn dipole(&self, xo: V3, no: V3, xi: V3, ni: V3, w12: V3) -> [f64; 3] {
        let x = sub(xo, xi);
        let r2 = dot(x, x);
        let r = r2.sqrt();
        // The modified tangent plane's normal: in the plane of ni and x, perpendicular to x.
        let tilted = normalize(cross(ni, x))
            .and_then(|t| normalize(cross(mul(x, 1.0 / r.max(1e-300)), t)))
            .unwrap_or(ni);
        let wv = sub(w12, mul(tilted, 2.0 * dot(w12, tilted)));
        let mu0 = -dot(no, w12);
        [0, 1, 2].map(|c| {
            let (d, de) = (self.d[c], self.de[c]);
            let xw = dot(x, w12);
            let cos_beta = -((r2 - xw * xw).max(0.0) / (r2 + de * de)).sqrt();
            let dr2 = if mu0 > 0.0 {
                r2 + d * mu0 * (d * mu0 - 2.0 * de * cos_beta)
            } else {
                r2 + self.reach[c] * self.reach[c]
            };
            let xv = sub(x, mul(tilted, 2.0 * self.a * de));
            let dv = dot(xv, xv).sqrt();
            (self.infinite(c, x, w12, dr2.sqrt(), no) - self.infinite(c, xv, wv, dv, no)).max(0.0)
        })
    }

    /// The factor for a source at `xi` with normal `ni` seen from `xo` with normal `no` (mm,
    /// unit normals). A lumped node whose normals cancel (zero normal) keeps the profile (1).
    pub(super) fn factor(&self, xo: V3, no: V3, xi: V3, ni: V3) -> [f64; 3] {
        if dot(ni, ni) < 0.25 {
            return [1.0; 3];
        }
        let r = dot(sub(xo, xi), sub(xo, xi)).sqrt();
        let actual = self.dipole(
            xo,
            no,
            xi,
            ni,
            refracted(&self.light, self.unit, self.eta, xi, ni),
        );
        // The same distance on a plane lit straight down: source at the origin, exit along x.
        let up = [0.0, 0.0, 1.0];
        let flat = self.dipole([r, 0.0, 0.0], up, [0.0; 3], up, [0.0, 0.0, -1.0]);
        [0, 1, 2].map(|c| {
            if flat[c] > 0.0 && flat[c].is_finite() && actual[c].is_finite() {
                actual[c] / flat[c]
            } else {
                1.0
            }
        })
    }
}

/// The light's direction into the medium at a sample at `xi` (mm, `unit` mm per world unit)
/// with unit normal `ni`; along −`ni` where the light is behind the sample's tangent plane.
pub(super) fn refracted(light: &Light, unit: f64, eta: f64, xi: V3, ni: V3) -> V3 {
    let (l, _) = light.at(xi.map(|v| v / unit));
    let cos = dot(ni, l);
    if cos <= 0.0 {
        return mul(ni, -1.0);
    }
    // Snell with η = n_inside/n_outside: the tangential part shrinks by 1/η.
    let tangential = sub(mul(ni, cos), l);
    let sin2 = (1.0 - cos * cos) / (eta * eta);
    let along = (1.0 - sin2).max(0.0).sqrt();
    normalize(sub(mul(tangential, 1.0 / eta), mul(ni, along))).unwrap_or(mul(ni, -1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::raytrace::light::LightParams;

    fn skin() -> ScatteringMaterial {
        ScatteringMaterial {
            sigma_s_prime: [0.74, 0.88, 1.01],
            sigma_a: [0.032, 0.17, 0.48],
            eta: 1.0,
            g: 0.0,
        }
    }

    fn lit_from(direction: V3) -> Light {
        Light::new(&LightParams {
            direction,
            position: None,
            intensity: 1.0,
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn a_plane_lit_straight_down_is_the_profile_and_grazing_light_travels_forward() {
        let up = [0.0, 0.0, 1.0];
        let straight = Directional::new(&skin(), &lit_from(up), 1.0);
        for r in [0.3, 1.0, 4.0] {
            for f in straight.factor([r, 0.0, 0.0], up, [0.0; 3], up) {
                assert!((f - 1.0).abs() < 1e-12, "{r}: {f}");
            }
        }
        // Light from −x at 70° from the normal travels towards +x: more light leaves ahead
        // of the entry point than behind it, at the same distance.
        let t = 70f64.to_radians();
        let grazing = Directional::new(&skin(), &lit_from([-t.sin(), 0.0, t.cos()]), 1.0);
        let ahead = grazing.factor([2.0, 0.0, 0.0], up, [0.0; 3], up);
        let behind = grazing.factor([-2.0, 0.0, 0.0], up, [0.0; 3], up);
        for c in 0..3 {
            assert!(ahead[c] > behind[c], "{c}: {} vs {}", ahead[c], behind[c]);
        }
    }
}
