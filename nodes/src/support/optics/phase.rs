//! The Henyey–Greenstein phase function: its value and the sampling of its scattering angle,
//! shared by the Monte Carlo profile, the diffusion models and the volumetric path tracer.

use std::f64::consts::PI;

/// Henyey–Greenstein phase function of the cosine between propagation directions, sr⁻¹.
pub fn henyey_greenstein(cos: f64, g: f64) -> f64 {
    let denom = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())
}

/// Cosine of the scattering angle drawn from Henyey–Greenstein by inverting its CDF.
pub(crate) fn sample_hg(g: f64, u: f64) -> f64 {
    if g.abs() < 1e-6 {
        return 2.0 * u - 1.0;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}
