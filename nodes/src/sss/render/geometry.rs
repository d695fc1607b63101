//! How the shape between an irradiance sample and a shaded point changes the profile. A
//! diffusion profile Rd(r) is the exitance of a flat half-space: the dipole's flux through the
//! surface, whose normal is the entry point's own. On a curved or thin object the exit point's
//! surface faces elsewhere: light entering the top of a tube leaves through its bottom, whose
//! normal points away from the source, not along the entry normal. `exit_normal` keeps the dipole
//! of the entry point (the real source 1/σt′ inside along its normal, the virtual one zv above)
//! but takes its flux through the exit point's normal, −D∇φ·n_o, and scales the profile by that
//! over the flat value at the same distance: exactly 1 on a plane, more where the exit faces the
//! source through the material, less where it faces away. Jensen et al. 2001's dipole constants
//! (σtr, zr, zv) per channel.
//!
//! Measured and dropped (docs/guide/translucency.md): placing the dipole against the exit
//! point's tangent plane (the source as deep below it as it lies, a slab's multipole for the
//! local thickness) sends 3× too much light through the torus's tube.

use crate::sss::dipole::Dipole;
use crate::support::geometry::{dot, sub, V3};
use crate::types::ScatteringMaterial;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// How the gather relates an irradiance sample to a shaded point.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Geometry {
    /// `body` on a closed mesh, `exit_normal` (with a warning) on an open one: the most
    /// accurate the mesh allows (the default).
    #[default]
    Auto,
    /// The profile at the straight distance, as on a flat half-space (Jensen & Buhler 2002).
    Planar,
    /// The profile scaled by the entry point's dipole's flux through the exit point's normal:
    /// light through thin and curved parts (CPU gather only).
    ExitNormal,
    /// The profile scaled by the directional dipole (Frisvad et al. 2014) over its value on a
    /// plane lit straight down: the light's incident direction and the exit point's normal
    /// (`directional.rs`; CPU gather only).
    Directional,
    /// `exit_normal` plus what the object's own boundary takes away: the diffusion equation
    /// solved on a grid inside the mesh for the difference from the dipoles (`body.rs`; CPU
    /// gather only; the mesh must be closed).
    Body,
}

/// Per channel: σtr, zr and zv (mm).
pub(super) struct ExitNormal {
    sigma_tr: [f64; 3],
    zr: [f64; 3],
    zv: [f64; 3],
}

impl ExitNormal {
    pub(super) fn new(m: &ScatteringMaterial) -> ExitNormal {
        let d = [0, 1, 2].map(|c| Dipole::new(m.sigma_s_prime[c], m.sigma_a[c], m.eta));
        ExitNormal {
            sigma_tr: d.map(|d| d.sigma_tr),
            zr: d.map(|d| d.zr),
            zv: d.map(|d| d.zv),
        }
    }

    /// The factor for a source at `xi` with normal `ni` seen from `xo` with normal `no` (mm,
    /// unit normals). A lumped node whose normals cancel has a zero normal: its sources sit at
    /// their centre, and the flux through `no` is that of a point source there.
    pub(super) fn factor(&self, xo: V3, no: V3, xi: V3, ni: V3) -> [f64; 3] {
        let r2 = dot(sub(xi, xo), sub(xi, xo));
        [0, 1, 2].map(|c| {
            let (s, zr, zv) = (self.sigma_tr[c], self.zr[c], self.zv[c]);
            let kernel = |d: f64| flux_kernel(s, d);
            // Each source's kernel times its height above the exit plane.
            let flat = zr * kernel((r2 + zr * zr).sqrt()) + zv * kernel((r2 + zv * zv).sqrt());
            if flat.is_nan() || flat <= 0.0 {
                return 1.0;
            }
            let through = |z: f64| {
                let v = [0, 1, 2].map(|k| xo[k] - (xi[k] + z * ni[k]));
                let d = dot(v, v).sqrt().max(1e-12);
                dot(v, no) * kernel(d)
            };
            // Real source zr inside (z = −zr), virtual one zv outside, subtracted.
            ((through(-zr) - through(zv)) / flat).max(0.0)
        })
    }
}

/// The diffusion flux of a unit point source per unit of the source's offset along the normal
/// it crosses, d away: (1 + σtr d)e^(−σtr d)/d³ (the flux kernel of Jensen et al. 2001's Rd).
pub(super) fn flux_kernel(sigma_tr: f64, d: f64) -> f64 {
    (1.0 + sigma_tr * d) * super::expneg::exp_neg(-sigma_tr * d) / (d * d * d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_is_the_profile_itself_and_a_slab_lets_more_through() {
        let marble = ScatteringMaterial {
            sigma_s_prime: [2.19, 2.62, 3.00],
            sigma_a: [0.0021, 0.0041, 0.0071],
            eta: 1.0,
            g: 0.0,
        };
        let en = ExitNormal::new(&marble);
        let up = [0.0, 0.0, 1.0];
        for r in [0.1, 1.0, 5.0, 20.0] {
            for f in en.factor([0.0; 3], up, [r, 0.0, 0.0], up) {
                assert!((f - 1.0).abs() < 1e-12, "{r}: {f}");
            }
        }
        // Straight through a 15 mm slab (entering at the top, leaving at the bottom facing
        // down): the real source is 15 − zr below the exit and the virtual one 15 + zv, so the
        // flux is (15 − zr)K(15 − zr) − (15 + zv)K(15 + zv) with K(d) = (1 + σtr d)e^(−σtr d)/d³,
        // against the plane's zr·K(√(15² + zr²)) + zv·K(√(15² + zv²)): written out here from
        // the dipole's constants (Jensen et al. 2001, A = 1 at η = 1).
        let f = en.factor([0.0, 0.0, -15.0], [0.0, 0.0, -1.0], [0.0; 3], up);
        let (sa, sp): (f64, f64) = (0.0021, 2.19);
        let st = sa + sp;
        let s = (3.0 * sa * st).sqrt();
        let zr = 1.0 / st;
        let zv = zr * (1.0 + 4.0 / 3.0 * crate::sss::dipole::boundary_a(1.0));
        let k = |d: f64| (1.0 + s * d) * (-s * d).exp() / (d * d * d);
        let want = ((15.0 - zr) * k(15.0 - zr) - (15.0 + zv) * k(15.0 + zv))
            / (zr * k((225.0 + zr * zr).sqrt()) + zv * k((225.0 + zv * zv).sqrt()));
        assert!((f[0] / want - 1.0).abs() < 1e-9, "{} vs {want}", f[0]);
        assert!(f[0] > 1.0, "through the slab: {}", f[0]);
        // Facing away from the source (the exit normal towards it): nothing.
        let away = en.factor([0.0, 0.0, -15.0], [0.0, 0.0, 1.0], [0.0; 3], up);
        assert_eq!(away, [0.0; 3]);
    }
}
