//! A second reflectance model for the weathered sample: Cook–Torrance (Cook & Torrance 1982) with
//! the Beckmann distribution, Schlick's Fresnel and the V-cavity masking–shadowing term. It shares
//! the Ward parameters' meaning (ρd, a specular albedo ρs, slope roughness α) but not their lobe:
//! the cos⁴δ of the Beckmann density, the full cos θi·cos θo, Fresnel growth towards grazing and
//! shadowing between microfacets. A Ward fit to a capture rendered with it is a cross-model check,
//! not a solver check: the fit cannot reproduce the data exactly.

use crate::types::DirectionPair;
use std::f64::consts::PI;

/// Reflectance at normal incidence of the Schlick Fresnel term (a metal-like surface); the lobe is
/// divided by it so that ρs keeps the meaning of the specular albedo at normal incidence.
const F0: f64 = 0.5;

/// Radiance under unit irradiance: cos θi · f(ωi, ωo) for the unit normal `n`.
pub fn value(pair: &DirectionPair, n: [f64; 3], rho_d: f64, rho_s: f64, alpha: f64) -> f64 {
    let (wi, wo) = (pair.light.vector(), pair.view.vector());
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (cos_i, cos_o) = (dot(n, wi), dot(n, wo));
    if cos_i <= 0.0 || cos_o <= 0.0 {
        return 0.0;
    }
    let h = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
    let len = dot(h, h).sqrt();
    let h = [h[0] / len, h[1] / len, h[2] / len];
    let (nh, vh) = (dot(n, h), dot(wo, h));
    let specular = if nh > 0.0 && vh > 0.0 {
        let a2 = alpha * alpha;
        let nh2 = nh * nh;
        let d = (-(1.0 - nh2) / (nh2 * a2)).exp() / (PI * a2 * nh2 * nh2);
        let g = (2.0 * nh * cos_o / vh).min(2.0 * nh * cos_i / vh).min(1.0);
        let f = (F0 + (1.0 - F0) * (1.0 - vh).powi(5)) / F0;
        d * g * f / (4.0 * cos_i * cos_o)
    } else {
        0.0
    };
    cos_i * (rho_d / PI + rho_s * specular)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Direction;

    #[test]
    fn the_beckmann_density_projects_to_one() {
        // ∫ D(h) (n·h) dω_h = 1 over the hemisphere (the normalisation of a microfacet density),
        // by a midpoint sum in θ (2000 steps; the error is far below the 1e-3 bound).
        for alpha in [0.1, 0.3, 0.6] {
            let a2: f64 = alpha * alpha;
            let steps = 2000;
            let mut sum = 0.0;
            for k in 0..steps {
                let t = (k as f64 + 0.5) / steps as f64 * PI / 2.0;
                let c = t.cos();
                let d = (-(1.0 - c * c) / (c * c * a2)).exp() / (PI * a2 * c.powi(4));
                sum += d * c * t.sin() * 2.0 * PI * (PI / 2.0 / steps as f64);
            }
            assert!((sum - 1.0).abs() < 1e-3, "α {alpha}: {sum}");
        }
    }

    #[test]
    fn it_is_reciprocal_and_not_ward() {
        let a = Direction::degrees(30.0, 10.0);
        let b = Direction::degrees(55.0, 200.0);
        let n = [0.0, 0.0, 1.0];
        let ab = DirectionPair { view: a, light: b };
        let ba = DirectionPair { view: b, light: a };
        // value = cos θi · f: dividing by the cosine leaves the symmetric BRDF.
        let f = |p: &DirectionPair, v: f64| v / p.light.vector()[2];
        let (x, y) = (value(&ab, n, 0.3, 0.5, 0.2), value(&ba, n, 0.3, 0.5, 0.2));
        assert!((f(&ab, x) - f(&ba, y)).abs() < 1e-12 * f(&ab, x));
        let ward = crate::reflectance::ward::PairGeometry::flat(&ab).value(0.3, 0.5, 0.2);
        assert!((ward - x).abs() > 1e-3 * ward, "{ward} vs {x}");
    }
}
