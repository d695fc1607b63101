//! Exact ray casting through a periodic height field, the geometric core of BTF capture (masking
//! by the view ray, self-shadowing by the light ray) and of MDF tabulation.
//!
//! The surface is the bilinear interpolation of the samples, which sit on the integer grid points
//! (sample (i, j) at (u, v) = (i, j); callers that think in texel centres add 0.5). Coordinates are
//! grid coordinates: u along columns, v along rows (down the image), z up, all in texels. A ray is
//! walked cell by cell (Amanatides–Woo traversal); inside a cell the height along the ray is a
//! quadratic in t, so the first crossing is found in closed form, not by stepping.

use crate::types::HeightField;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) direction from the origin.
    pub t: f64,
    pub u: f64,
    pub v: f64,
    pub z: f64,
}

/// Why a ray found no surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Miss {
    /// It rose above the highest sample: it leaves the mesostructure (a lit shadow ray).
    Escaped,
    /// It travelled `max_distance` without hitting or escaping (near-horizontal rays).
    TooFar,
}

pub struct Caster<'a> {
    hf: &'a HeightField,
    min: f64,
    max: f64,
    /// Per cell (row-major, cell (i, j) between samples i..i+1 and j..j+1, wrapped): its four
    /// corner heights h00, h10, h01, h11 and their maximum, which bounds the bilinear patch, so
    /// a ray segment above it is passed without solving for a crossing.
    cells: Vec<[f32; 5]>,
    /// Limit on the horizontal distance walked, in texels.
    pub max_distance: f64,
}

impl<'a> Caster<'a> {
    pub fn new(hf: &'a HeightField) -> Self {
        let (lo, hi) = hf.min_max();
        let tiles = 64.0 * hf.width.max(hf.height) as f64;
        let cells = (0..hf.height as isize)
            .flat_map(|j| (0..hf.width as isize).map(move |i| (i, j)))
            .map(|(i, j)| {
                let h = [
                    hf.at_wrapped(i, j),
                    hf.at_wrapped(i + 1, j),
                    hf.at_wrapped(i, j + 1),
                    hf.at_wrapped(i + 1, j + 1),
                ];
                [h[0], h[1], h[2], h[3], h[0].max(h[1]).max(h[2]).max(h[3])]
            })
            .collect();
        Caster {
            hf,
            min: lo as f64,
            max: hi as f64,
            cells,
            max_distance: tiles,
        }
    }

    fn sample(&self, i: i64, j: i64) -> f64 {
        self.hf.at_wrapped(i as isize, j as isize) as f64
    }

    /// Bilinear height at (u, v), periodic.
    pub fn height(&self, u: f64, v: f64) -> f64 {
        let (i, j) = (u.floor(), v.floor());
        let (fx, fy) = (u - i, v - j);
        let (i, j) = (i as i64, j as i64);
        let (h00, h10, h01, h11) = (
            self.sample(i, j),
            self.sample(i + 1, j),
            self.sample(i, j + 1),
            self.sample(i + 1, j + 1),
        );
        h00 * (1.0 - fx) * (1.0 - fy)
            + h10 * fx * (1.0 - fy)
            + h01 * (1.0 - fx) * fy
            + h11 * fx * fy
    }

    /// First point where the ray from `o` along unit `d` goes from above the surface to on or below
    /// it, ignoring the first `t_min` of its length (so a shadow ray can leave the point it starts
    /// on). The origin may be anywhere above the surface, including far above the shell.
    pub fn cast(&self, o: [f64; 3], d: [f64; 3], t_min: f64) -> Result<Hit, Miss> {
        let horizontal = (d[0] * d[0] + d[1] * d[1]).sqrt();
        // Skip straight to the top of the shell when starting above it.
        let mut t = t_min.max(0.0);
        if o[2] + d[2] * t > self.max {
            if d[2] >= 0.0 {
                return Err(Miss::Escaped);
            }
            t = (self.max - o[2]) / d[2];
        }
        let t_end = if horizontal > 0.0 {
            t + self.max_distance / horizontal
        } else {
            f64::INFINITY
        };
        let at = |t: f64| [o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t];
        let p = at(t);
        let (mut i, mut j) = (p[0].floor() as i64, p[1].floor() as i64);
        let step_i: i64 = if d[0] > 0.0 { 1 } else { -1 };
        let step_j: i64 = if d[1] > 0.0 { 1 } else { -1 };
        // Ray parameter of the next cell boundary in u and in v.
        let next = |c: i64, step: i64, o: f64, d: f64| {
            if d == 0.0 {
                f64::INFINITY
            } else {
                let boundary = if step > 0 { (c + 1) as f64 } else { c as f64 };
                (boundary - o) / d
            }
        };
        // Cell (i, j) wrapped into the tile, stepped with it.
        let (w, h) = (self.hf.width as i64, self.hf.height as i64);
        let (mut ci, mut cj) = (i.rem_euclid(w), j.rem_euclid(h));
        let mut t_u = next(i, step_i, o[0], d[0]);
        let mut t_v = next(j, step_j, o[1], d[1]);
        let dt_u = if d[0] == 0.0 {
            f64::INFINITY
        } else {
            1.0 / d[0].abs()
        };
        let dt_v = if d[1] == 0.0 {
            f64::INFINITY
        } else {
            1.0 / d[1].abs()
        };
        loop {
            let t_exit = t_u.min(t_v);
            let tb = t_exit.min(t_end);
            let cell = &self.cells[(cj * w + ci) as usize];
            // The patch lies at or under its highest corner: a segment above that (by more
            // than rounding) cannot cross it.
            let lowest = (o[2] + d[2] * t).min(o[2] + d[2] * tb);
            let top = cell[4] as f64;
            if lowest <= top + 1e-9 * (1.0 + top.abs()) {
                if let Some(hit) = self.in_cell(cell, i, j, o, d, t, tb) {
                    return Ok(hit);
                }
            }
            let z_exit = o[2] + d[2] * t_exit;
            if d[2] >= 0.0 && z_exit > self.max {
                return Err(Miss::Escaped);
            }
            if t_exit >= t_end || (d[2] < 0.0 && z_exit < self.min - 1.0) {
                // Below the lowest sample without a crossing can only come from rounding.
                return Err(Miss::TooFar);
            }
            t = t_exit;
            if t_u < t_v {
                i += step_i;
                ci = (ci + step_i).rem_euclid(w);
                t_u += dt_u;
            } else {
                j += step_j;
                cj = (cj + step_j).rem_euclid(h);
                t_v += dt_v;
            }
        }
    }

    /// The first crossing inside cell (i, j) (its entry `cell`) for t in [ta, tb].
    #[allow(clippy::too_many_arguments)]
    fn in_cell(
        &self,
        cell: &[f32; 5],
        i: i64,
        j: i64,
        o: [f64; 3],
        d: [f64; 3],
        ta: f64,
        tb: f64,
    ) -> Option<Hit> {
        if tb < ta {
            return None;
        }
        let [h00, h10, h01, h11] = [cell[0], cell[1], cell[2], cell[3]].map(f64::from);
        let (c0, c1, c2, c3) = (h00, h10 - h00, h01 - h00, h11 - h10 - h01 + h00);
        // Local coordinates at the segment start, then linear in s = t − ta.
        let (ax, ay, az) = (
            o[0] + d[0] * ta - i as f64,
            o[1] + d[1] * ta - j as f64,
            o[2] + d[2] * ta,
        );
        let (bx, by) = (d[0], d[1]);
        // g(s) = z(s) − h(s) = k0 + k1 s + k2 s²; the ray is above the surface where g > 0.
        let k0 = az - (c0 + c1 * ax + c2 * ay + c3 * ax * ay);
        let k1 = d[2] - (c1 * bx + c2 * by + c3 * (ax * by + bx * ay));
        let k2 = -c3 * bx * by;
        let len = tb - ta;
        let g = |s: f64| k0 + s * (k1 + s * k2);
        if k0 <= 0.0 {
            // Starting on or under the surface counts as a hit only when moving into it.
            return (k1 < 0.0 || (k1 == 0.0 && k2 < 0.0)).then(|| self.hit(o, d, ta));
        }
        let mut roots = [f64::NAN; 2];
        if k2.abs() < 1e-12 * (k1.abs() + k0.abs()).max(1e-300) {
            if k1 < 0.0 {
                roots[0] = -k0 / k1;
            }
        } else {
            let disc = k1 * k1 - 4.0 * k2 * k0;
            if disc >= 0.0 {
                // Numerically stable pair (no cancellation between −k1 and the root).
                let q = -0.5 * (k1 + k1.signum() * disc.sqrt());
                roots = [q / k2, if q != 0.0 { k0 / q } else { f64::NAN }];
            }
        }
        let s = roots
            .into_iter()
            .filter(|s| s.is_finite() && *s >= 0.0 && *s <= len)
            .fold(f64::INFINITY, f64::min);
        if s.is_finite() {
            return Some(self.hit(o, d, ta + s));
        }
        // A tangent graze within rounding of zero is not a crossing; a sign change that the
        // root test missed through rounding is caught here.
        (g(len) < 0.0).then(|| self.hit(o, d, tb))
    }

    fn hit(&self, o: [f64; 3], d: [f64; 3], t: f64) -> Hit {
        Hit {
            t,
            u: o[0] + d[0] * t,
            v: o[1] + d[1] * t,
            z: o[2] + d[2] * t,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(n: usize, f: impl Fn(usize, usize) -> f32) -> HeightField {
        HeightField::from_fn(n, n, f)
    }

    fn dir(theta_deg: f64, phi_deg: f64, down: bool) -> [f64; 3] {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        let z = if down { -t.cos() } else { t.cos() };
        [t.sin() * p.cos(), t.sin() * p.sin(), z]
    }

    #[test]
    fn flat_tile_gives_the_plane_distance() {
        // Closed form: from height z0 down to the plane h, the distance is (z0 − h) / cos θ.
        let hf = field(8, |_, _| 2.5);
        let c = Caster::new(&hf);
        for theta in [0.0, 15.0, 45.0, 75.0, 85.0] {
            for phi in [0.0, 37.0, 200.0] {
                let hit = c
                    .cast([3.3, 4.1, 10.0], dir(theta, phi, true), 0.0)
                    .unwrap();
                let expected = (10.0 - 2.5) / theta.to_radians().cos();
                assert!(
                    (hit.t - expected).abs() < 1e-9 * expected,
                    "θ {theta} φ {phi}: {} vs {expected}",
                    hit.t
                );
            }
        }
    }

    #[test]
    fn a_ramp_is_hit_where_the_plane_equation_says() {
        // Samples 0 at i = 0 and 4 at i = 1 (a 4-texel-high ramp in one cell, periodic in v):
        // inside that cell the surface is the plane z = 4u; a vertical ray at u = 0.25 hits z = 1.
        let hf = field(2, |i, _| if i == 1 { 4.0 } else { 0.0 });
        let c = Caster::new(&hf);
        let hit = c.cast([0.25, 0.7, 9.0], [0.0, 0.0, -1.0], 0.0).unwrap();
        assert!(
            (hit.z - 1.0).abs() < 1e-12 && (hit.t - 8.0).abs() < 1e-12,
            "{hit:?}"
        );
        // An oblique ray along +u entering at the shell top (z = 4) over the low side:
        // z = 4 − s·cos45, u = 0.05 + s·sin45 meets z = 4u at s = (4 − 0.2) / (5 · cos45).
        let d = dir(45.0, 0.0, true);
        let hit = c.cast([0.05, 0.5, 4.0], d, 0.0).unwrap();
        let s = (4.0 - 0.2) / (d[2].abs() + 4.0 * d[0]);
        assert!((hit.t - s).abs() < 1e-9, "{} vs {s}", hit.t);
        // From z = 9 the same ray reaches the shell top only at u = 5.05, passes over the falling
        // copy of the ramp in [5, 6] and meets the rising one in [6, 7]: 9.05 − u = 4(u − 6), so
        // u = 6.61 and s = (6.61 − 0.05) / sin45.
        let hit = c.cast([0.05, 0.5, 9.0], d, 0.0).unwrap();
        let s = (6.61 - 0.05) / d[0];
        assert!((hit.t - s).abs() < 1e-9, "{} vs {s}", hit.t);
    }

    #[test]
    fn rays_wrap_around_the_tile() {
        // One pillar at sample (1, 0) on a 4-wide tile: along v = 0 the surface is 5(u − 0) on
        // [0, 1] (rising towards the pillar). A horizontal ray at z = 4 heading +u from u = 2.5
        // meets it only through the seam u = 4 ≡ 0, at u = 4.8: t = 2.3.
        let hf = field(4, |i, j| if (i, j) == (1, 0) { 5.0 } else { 0.0 });
        let c = Caster::new(&hf);
        let hit = c.cast([2.5, 0.0, 4.0], [1.0, 0.0, 0.0], 0.0).unwrap();
        assert!(
            (hit.t - 2.3).abs() < 1e-12 && (hit.u - 4.8).abs() < 1e-12,
            "{hit:?}"
        );
    }

    #[test]
    fn shadow_rays_escape_or_are_blocked() {
        let hf = field(16, |i, j| {
            if (7..=8).contains(&i) && (7..=8).contains(&j) {
                6.0
            } else {
                0.0
            }
        });
        let c = Caster::new(&hf);
        // From the floor far from the block, straight up: lit.
        assert_eq!(
            c.cast([2.5, 2.5, 0.0], [0.0, 0.0, 1.0], 1e-6),
            Err(Miss::Escaped)
        );
        // From the floor beside the block, towards it at a low elevation: blocked.
        let d = dir(80.0, 0.0, false);
        assert!(c.cast([4.5, 7.5, 0.0], d, 1e-6).is_ok());
        // Away from it at the same elevation: the next block is a tile away (16 texels) and the
        // ray rises 16 / tan 80° ≈ 2.8 < 6 texels by then, so it is blocked by the next copy.
        let away = dir(80.0, 180.0, false);
        let hit = c.cast([4.5, 7.5, 0.0], away, 1e-6).unwrap();
        assert!(hit.u < -2.0, "hit the periodic copy: {hit:?}");
        // Steeply up and away: it clears everything.
        assert_eq!(
            c.cast([4.5, 7.5, 0.0], dir(20.0, 180.0, false), 1e-6),
            Err(Miss::Escaped)
        );
    }

    #[test]
    fn agrees_with_an_independent_brute_force_march() {
        // Reference: march the ray in steps of 1e-3 texel, evaluating the bilinear surface
        // directly, then bisect the first sign change. Its error is far below the 1e-6 tolerance
        // unless a thin crossing shorter than a step is missed, which the smooth field excludes.
        let p = crate::heightfield::procedural::Params {
            pattern: crate::heightfield::procedural::Pattern::Noise,
            size: 16,
            depth: 4.0,
            count: 2,
            octaves: 2,
            ..Default::default()
        };
        let hf = field(16, |i, j| {
            (p.depth
                * crate::heightfield::procedural::unit_height(&p, i as f64 / 16.0, j as f64 / 16.0))
                as f32
        });
        let c = Caster::new(&hf);
        let mut checked = 0;
        for k in 0..60 {
            let theta = 5.0 + (k as f64 * 7.3) % 70.0;
            let phi = (k as f64 * 47.0) % 360.0;
            let d = dir(theta, phi, true);
            let o = [(k as f64 * 1.37) % 16.0, (k as f64 * 2.11) % 16.0, 6.0];
            let g = |t: f64| o[2] + d[2] * t - c.height(o[0] + d[0] * t, o[1] + d[1] * t);
            let (mut a, step) = (0.0, 1e-3);
            while g(a + step) > 0.0 {
                a += step;
                assert!(a < 500.0, "reference never hit");
            }
            let (mut lo, mut hi) = (a, a + step);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if g(mid) > 0.0 {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            let hit = c.cast(o, d, 0.0).unwrap();
            assert!(
                (hit.t - hi).abs() < 1e-6,
                "ray {k}: caster {} vs reference {hi}",
                hit.t
            );
            checked += 1;
        }
        assert_eq!(checked, 60);
    }

    #[test]
    fn horizontal_rays_stop_at_the_distance_limit() {
        // A channel: walls of height 5 on row 0, floor 0 elsewhere. A horizontal ray at z = 1
        // along the channel (v = 2) never meets the surface and never rises out of the shell.
        let hf = field(4, |_, j| if j == 0 { 5.0 } else { 0.0 });
        let mut c = Caster::new(&hf);
        c.max_distance = 100.0;
        assert_eq!(
            c.cast([0.5, 2.0, 1.0], [1.0, 0.0, 0.0], 0.0),
            Err(Miss::TooFar)
        );
        // Above the shell, the same ray escapes at once.
        assert_eq!(
            c.cast([0.5, 2.0, 6.0], [1.0, 0.0, 0.0], 0.0),
            Err(Miss::Escaped)
        );
    }
}
