//! Single scattering through the object's own shape (`single_scattering_shape: traced`): the
//! camera ray is followed into the mesh to where it first leaves, and at points along it the light
//! arrives through every part of the mesh between them and the light, attenuated by the real
//! distance inside. Hanrahan & Krueger's formula (`half_space`) assumes a flat semi-infinite
//! medium instead: it lets a grazing rim, where the object is a thin sliver, scatter as if it
//! were deep, and gives nothing where the surface faces away from the light although light
//! reaches the point through a thin part (the shadowed front of a tube lit from behind).
//!
//! At η = 1 this is the exact first-order term for a directional or point light. At η ≠ 1 the
//! Fresnel transmittances in (at the point where the light enters) and out are kept, but the
//! directions are not bent inside: an approximation, documented with the parameter.
//!
//! The integral along the ray, ∫₀ᵀ σs e^(−σt t) p e^(−σt s(t)) dt, uses fixed stratified points
//! distributed as e^(−σt,min t) on [0, T]: deterministic, and no channel's weight exceeds
//! σs/σt,min.

use crate::support::geometry::{add, dot, mul, V3};
use crate::support::optics::fresnel::transmit_in;
use crate::support::optics::phase::henyey_greenstein;
use crate::support::raytrace::light::Light;
use crate::support::raytrace::tracer::Tracer;
use crate::types::ScatteringMaterial;

/// Points along the camera ray inside the object.
const STEPS: usize = 32;
/// Most boundary crossings a light path is followed through.
const CROSSINGS: usize = 64;

/// The mesh's tracer and the material in mm.
pub(super) struct Traced<'a> {
    pub(super) tracer: &'a Tracer<'a>,
    /// mm per world unit.
    pub(super) unit: f64,
}

impl Traced<'_> {
    /// First crossing of the boundary along the ray from `o` (unit `d`): distance (world) and
    /// whether the ray is inside after it.
    fn cross(&self, o: V3, d: V3) -> Option<(f64, bool, f64)> {
        let hit = self.tracer.closest(o, d)?;
        let (_, ng) = self.tracer.triangle(hit.tri);
        Some((hit.t, dot(ng, d) < 0.0, dot(ng, d).abs()))
    }

    /// A point just past the boundary at `t` along the ray, on the side the ray goes to.
    fn past(&self, o: V3, d: V3, t: f64) -> V3 {
        add(o, mul(d, t + self.tracer.epsilon))
    }

    /// Length inside the mesh (world) from `y` (inside) towards the light `reach` away along
    /// `l`, and the cosine at the last crossing (where the light entered).
    fn inside_towards(&self, y: V3, l: V3, reach: f64) -> (f64, f64) {
        let (mut o, mut left, mut inside, mut length, mut cos) = (y, reach, true, 0.0, 1.0);
        for _ in 0..CROSSINGS {
            match self.cross(o, l) {
                Some((t, now_inside, c)) if t < left => {
                    if inside {
                        length += t;
                        cos = c;
                    }
                    inside = now_inside;
                    o = self.past(o, l, t);
                    left -= t;
                }
                // Out of the scene (or the point light reached) on this side.
                _ => {
                    if inside && left.is_finite() {
                        length += left;
                    }
                    return (length, cos);
                }
            }
        }
        (length, cos)
    }

    /// Radiance scattered once towards the camera at the surface point `x` seen along the
    /// unit view direction `d` (from the camera), with geometric normal `ng` of the entered
    /// triangle and cosine `cos_o` between the shading normal and the viewer.
    pub(super) fn radiance(
        &self,
        m: &ScatteringMaterial,
        light: &Light,
        x: V3,
        ng: V3,
        d: V3,
        cos_o: f64,
    ) -> [f64; 3] {
        if cos_o <= 0.0 {
            return [0.0; 3];
        }
        // Just inside, then to where the ray leaves.
        let side = if dot(ng, d) < 0.0 { -1.0 } else { 1.0 };
        let start = add(x, mul(ng, side * self.tracer.epsilon));
        let Some((length, _, _)) = self.cross(start, d) else {
            return [0.0; 3];
        };
        let depth = length * self.unit;
        let sigma_s = m.sigma_s_prime.map(|s| s / (1.0 - m.g));
        let sigma_t: [f64; 3] = [0, 1, 2].map(|c| sigma_s[c] + m.sigma_a[c]);
        let least = sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
        if !(least > 0.0 && depth > 0.0) {
            return [0.0; 3];
        }
        let ft_o = transmit_in(cos_o, m.eta);
        // The share of the exponential e^(−σt,min t) inside [0, depth].
        let mass = -(-least * depth).exp_m1();
        let mut sum = [0.0; 3];
        for k in 0..STEPS {
            let u = (k as f64 + 0.5) / STEPS as f64;
            let t = -(-u * mass).ln_1p() / least;
            let y = add(start, mul(d, t / self.unit));
            let (l, e) = light.at(y);
            let reach = light.reach(y, l);
            let (s, cos_in) = self.inside_towards(y, l, reach);
            let ft_i = transmit_in(cos_in, m.eta);
            let phase = henyey_greenstein(dot(l, d), m.g);
            // f(t)/q(t) with q(t) = σt,min e^(−σt,min t)/mass.
            for c in 0..3 {
                let w = mass / least * (-(sigma_t[c] - least) * t).exp();
                sum[c] += w * sigma_s[c] * phase * e * ft_i * (-sigma_t[c] * s * self.unit).exp();
            }
        }
        sum.map(|v| v * ft_o / STEPS as f64)
    }
}
