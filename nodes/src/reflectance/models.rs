//! Reflectance models for synthetic capture and the reference renderer, evaluated against a local
//! frame (normal, and for the anisotropic model a tangent). Values are BRDFs in sr⁻¹.
//!
//! Lambert and isotropic Ward are the models `brdf.fit_ward` fits; Cook–Torrance with GGX and
//! Fresnel, and anisotropic Ward, are there so a capture can hold a reflectance the fit does not
//! contain (its accuracy is then a model error, not a solver check).

use crate::support::geometry::dot;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Model {
    /// ρd/π.
    Lambert,
    /// Isotropic Ward: ρd/π + ρs·exp(−tan²δ/α²) / (4π α² √(cosθi cosθo)).
    Ward,
    /// Anisotropic Ward (1992): ρd/π + ρs·exp(−tan²δ (cos²φh/αu² + sin²φh/αv²)) /
    /// (4π αu αv √(cosθi cosθo)), αu along the image's x axis, αv along y.
    WardAnisotropic,
    /// Cook–Torrance: ρd/π + ρs·D·G·F / (4 cosθi cosθo) with the GGX (Trowbridge–Reitz)
    /// distribution of roughness α, height-correlated Smith masking–shadowing and Schlick's
    /// Fresnel for index `ior`; ρs = 1 is the physical lobe of a smooth-faceted dielectric.
    Ggx,
}

/// The specular lobe's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    pub model: Model,
    pub rho_s: f64,
    /// α, or αu for the anisotropic model.
    pub alpha: f64,
    /// αv of the anisotropic model (others ignore it).
    pub alpha_v: f64,
    /// Refractive index for the Fresnel term of GGX.
    pub ior: f64,
}

impl Lobe {
    /// An isotropic lobe with the default index (1.5).
    pub fn isotropic(model: Model, rho_s: f64, alpha: f64) -> Lobe {
        Lobe {
            model,
            rho_s,
            alpha,
            alpha_v: alpha,
            ior: 1.5,
        }
    }
}

/// The BRDF for unit vectors `wi` (to the light), `wo` (to the viewer), normal `n` and tangent
/// `t` (unit, ⊥ n; only the anisotropic model uses it), given the diffuse albedo `rho_d` of one
/// channel. Specular lobes are 0 where either cosine is ≤ 0 (a back-facing point reflects
/// nothing specular; Ward's normalisation diverges there).
pub fn eval_lobe(
    lobe: &Lobe,
    rho_d: f64,
    n: [f64; 3],
    t: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
) -> f64 {
    let diffuse = rho_d / PI;
    match specular(lobe, n, t, wi, wo) {
        Some(specular) => diffuse + lobe.rho_s * specular,
        None => diffuse,
    }
}

/// [`eval_lobe`] for three channels' diffuse albedos at once, the specular lobe (the same in
/// every channel) evaluated once: the same values, channel by channel.
pub fn eval_lobe_rgb(
    lobe: &Lobe,
    rho_d: [f64; 3],
    n: [f64; 3],
    t: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
) -> [f64; 3] {
    match specular(lobe, n, t, wi, wo) {
        Some(specular) => rho_d.map(|r| r / PI + lobe.rho_s * specular),
        None => rho_d.map(|r| r / PI),
    }
}

/// The specular lobe before its weight ρs; `None` for Lambert and where either cosine is ≤ 0.
fn specular(lobe: &Lobe, n: [f64; 3], t: [f64; 3], wi: [f64; 3], wo: [f64; 3]) -> Option<f64> {
    let (ci, co) = (dot(n, wi), dot(n, wo));
    if lobe.model == Model::Lambert || ci <= 0.0 || co <= 0.0 {
        return None;
    }
    let h = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
    let len = dot(h, h).sqrt();
    let h = h.map(|v| v / len);
    let cd = dot(n, h);
    let a = lobe.alpha;
    let specular = match lobe.model {
        Model::Lambert => 0.0,
        Model::Ward => {
            let tan2 = (1.0 - cd * cd).max(0.0) / (cd * cd);
            (-tan2 / (a * a)).exp() / (4.0 * PI * a * a * (ci * co).sqrt())
        }
        Model::WardAnisotropic => {
            let b = cross(n, t);
            let (hu, hv) = (dot(h, t) / lobe.alpha, dot(h, b) / lobe.alpha_v);
            (-(hu * hu + hv * hv) / (cd * cd)).exp()
                / (4.0 * PI * lobe.alpha * lobe.alpha_v * (ci * co).sqrt())
        }
        Model::Ggx => {
            let a2 = a * a;
            let d = a2 / (PI * (cd * cd * (a2 - 1.0) + 1.0).powi(2));
            let lambda = |c: f64| 0.5 * (-1.0 + (1.0 + a2 * (1.0 - c * c) / (c * c)).sqrt());
            let g = 1.0 / (1.0 + lambda(ci) + lambda(co));
            let f0 = ((lobe.ior - 1.0) / (lobe.ior + 1.0)).powi(2);
            let f = f0 + (1.0 - f0) * (1.0 - dot(wi, h).clamp(0.0, 1.0)).powi(5);
            d * g * f / (4.0 * ci * co)
        }
    };
    Some(specular)
}

/// The isotropic models with the default index (1.5): `eval_lobe` with any tangent.
pub fn eval(
    model: Model,
    rho_d: f64,
    rho_s: f64,
    alpha: f64,
    n: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
) -> f64 {
    let lobe = Lobe::isotropic(model, rho_s, alpha);
    eval_lobe(&lobe, rho_d, n, tangent(n), wi, wo)
}

/// [`eval`] for three channels' diffuse albedos at once (the specular lobe evaluated once).
pub fn eval_rgb(
    model: Model,
    rho_d: [f64; 3],
    rho_s: f64,
    alpha: f64,
    n: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
) -> [f64; 3] {
    let lobe = Lobe::isotropic(model, rho_s, alpha);
    eval_lobe_rgb(&lobe, rho_d, n, tangent(n), wi, wo)
}

/// The image's x axis projected onto the plane ⊥ n, unit (y's when n is along x).
pub fn tangent(n: [f64; 3]) -> [f64; 3] {
    let axis = if n[0].abs() < 0.999 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let k = dot(axis, n);
    let t = [axis[0] - k * n[0], axis[1] - k * n[1], axis[2] - k * n[2]];
    let len = dot(t, t).sqrt();
    t.map(|v| v / len)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Directional-hemispherical reflectance of the specular lobe alone for light from θi, by a
    /// midpoint rule over the viewing hemisphere (independent of any closed form).
    fn albedo(lobe: &Lobe, theta_i: f64) -> f64 {
        let n = [0.0, 0.0, 1.0];
        let wi = [theta_i.sin(), 0.0, theta_i.cos()];
        let (nt, np) = (400, 800);
        let mut sum = 0.0;
        for i in 0..nt {
            let t = (i as f64 + 0.5) / nt as f64 * PI / 2.0;
            for j in 0..np {
                let p = (j as f64 + 0.5) / np as f64 * 2.0 * PI;
                let wo = [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
                sum += eval_lobe(lobe, 0.0, n, [1.0, 0.0, 0.0], wi, wo) * t.cos() * t.sin();
            }
        }
        sum * (PI / 2.0 / nt as f64) * (2.0 * PI / np as f64)
    }

    #[test]
    fn ggx_with_unit_fresnel_loses_only_what_single_scattering_loses() {
        // With F = 1 (ior → ∞ makes F0 → 1) the lobe's albedo is 1 minus what masking loses
        // without multiple scattering: about 1% at α = 0.1 and about 30% at α = 0.5 at normal
        // incidence (Kulla & Conty 2017, Fig. 3, roughness √α; a numpy midpoint rule run beside
        // this gave 0.988 and 0.688). It never exceeds 1 (energy conservation).
        let lobe = |alpha| Lobe {
            model: Model::Ggx,
            rho_s: 1.0,
            alpha,
            alpha_v: alpha,
            ior: 1e9,
        };
        let smooth = albedo(&lobe(0.1), 0.0);
        assert!((0.98..=1.0).contains(&smooth), "{smooth}");
        let rough = albedo(&lobe(0.5), 0.0);
        assert!((0.65..0.72).contains(&rough), "{rough}");
        for deg in [30.0f64, 60.0, 80.0] {
            let a = albedo(&lobe(0.5), deg.to_radians());
            assert!(a <= 1.0, "{deg}°: {a}");
        }
    }

    #[test]
    fn fresnel_makes_ggx_brighter_at_grazing_than_ward_can_be() {
        // At ior 1.5, F0 = 0.04 and Schlick's F(85°) = 0.04 + 0.96·(1 − cos 85°)^5 ≈ 0.65: the
        // mirror-direction value rises ~16× from normal to grazing incidence relative to D·G's
        // own change, which no isotropic Ward lobe with fixed ρs reproduces.
        let f = |deg: f64| {
            let c = deg.to_radians().cos();
            0.04 + 0.96 * (1.0 - c).powi(5)
        };
        let lobe = Lobe {
            model: Model::Ggx,
            rho_s: 1.0,
            alpha: 0.3,
            alpha_v: 0.3,
            ior: 1.5,
        };
        let at = |deg: f64| {
            let t = deg.to_radians();
            let (wi, wo) = ([t.sin(), 0.0, t.cos()], [-t.sin(), 0.0, t.cos()]);
            eval_lobe(&lobe, 0.0, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], wi, wo)
        };
        // In the mirror direction D = 1/(πα²), so value·4cos²θ/(D·G) is F.
        let a2: f64 = 0.09;
        for deg in [0.0f64, 60.0, 85.0] {
            let c = f64::cos(deg.to_radians());
            let lambda = 0.5 * (-1.0 + (1.0 + a2 * (1.0 - c * c) / (c * c)).sqrt());
            let g = 1.0 / (1.0 + 2.0 * lambda);
            let fresnel = at(deg) * 4.0 * c * c / (g / (PI * a2));
            assert!(
                (fresnel - f(deg)).abs() < 1e-9,
                "{deg}: {fresnel} vs {}",
                f(deg)
            );
        }
    }

    #[test]
    fn anisotropic_ward_is_isotropic_ward_when_its_roughnesses_agree_and_stretches_otherwise() {
        let n = [0.0, 0.0, 1.0];
        let wi = [0.5f64.sin(), 0.0, 0.5f64.cos()];
        let iso = Lobe {
            model: Model::Ward,
            rho_s: 0.1,
            alpha: 0.2,
            alpha_v: 0.2,
            ior: 1.5,
        };
        let aniso = Lobe {
            model: Model::WardAnisotropic,
            ..iso
        };
        for p in [0.0f64, 1.0, 2.5] {
            let wo = [0.4 * p.cos(), 0.4 * p.sin(), (1.0f64 - 0.16).sqrt()];
            let (a, b) = (
                eval_lobe(&iso, 0.3, n, [1.0, 0.0, 0.0], wi, wo),
                eval_lobe(&aniso, 0.3, n, [1.0, 0.0, 0.0], wi, wo),
            );
            assert!((a - b).abs() < 1e-12 * a, "{a} vs {b}");
        }
        // αu = 0.4 along x, αv = 0.1 along y: a half vector tilted along x is far brighter than the
        // same tilt along y (exp(−tan²δ/αu²) vs exp(−tan²δ/αv²)).
        let stretched = Lobe {
            alpha: 0.4,
            alpha_v: 0.1,
            ..aniso
        };
        let tilt = 0.15f64;
        let along = |dir: [f64; 2]| {
            // Mirror pair about a normal tilted by `tilt` towards dir: h is that tilted normal.
            let h = [tilt.sin() * dir[0], tilt.sin() * dir[1], tilt.cos()];
            let wi = [0.0, 0.0, 1.0];
            let k = 2.0 * dot(wi, h);
            let wo = [k * h[0] - wi[0], k * h[1] - wi[1], k * h[2] - wi[2]];
            eval_lobe(&stretched, 0.0, n, [1.0, 0.0, 0.0], wi, wo)
        };
        let (x, y) = (along([1.0, 0.0]), along([0.0, 1.0]));
        let expected = (tilt.tan().powi(2) * (1.0 / 0.01 - 1.0 / 0.16)).exp();
        assert!(
            (x / y / expected - 1.0).abs() < 1e-9,
            "{} vs {expected}",
            x / y
        );
    }
}
