//! Reflectance models for synthetic capture, evaluated against a local normal (isotropic, so no
//! tangent is needed). Values are BRDFs in sr⁻¹.

use crate::geometry::dot;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// ρd/π.
    Lambert,
    /// Isotropic Ward: ρd/π + ρs·exp(−tan²δ/α²) / (4π α² √(cosθi cosθo)).
    Ward,
}

/// The BRDF for unit vectors `wi` (to the light), `wo` (to the viewer) and normal `n`, given the
/// diffuse albedo `rho_d` of one channel. Ward's specular lobe is 0 where either cosine is ≤ 0
/// (its normalisation diverges there; a back-facing point reflects nothing specular).
pub fn eval(
    model: Model,
    rho_d: f64,
    rho_s: f64,
    alpha: f64,
    n: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
) -> f64 {
    let diffuse = rho_d / PI;
    match model {
        Model::Lambert => diffuse,
        Model::Ward => {
            let (ci, co) = (dot(n, wi), dot(n, wo));
            if ci <= 0.0 || co <= 0.0 {
                return diffuse;
            }
            let h = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
            let len = dot(h, h).sqrt();
            let cd = dot(n, h) / len;
            let tan2 = (1.0 - cd * cd).max(0.0) / (cd * cd);
            diffuse
                + rho_s * (-tan2 / (alpha * alpha)).exp()
                    / (4.0 * PI * alpha * alpha * (ci * co).sqrt())
        }
    }
}
