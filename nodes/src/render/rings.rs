//! Sampled directions as rings of equal polar angle (UBO2003's 81, any θ × φ grid), and the
//! bilinear lookup over them: between the two rings that bracket the query's θ, and on each
//! between the two directions that bracket its φ (cyclically), weights linear in θ and in φ. A
//! query on a sampled direction gets that direction alone. Beyond the outermost ring (or inside
//! the innermost) the nearest ring stands in. It replaces the nearest-three inverse-angle blend,
//! which mixes directions from three sides of the query and smears what neighbouring views
//! disagree on; direction sets that are not rings (fewer than two directions per ring on
//! average) keep that blend.
//!
//! The GPU reads the same table from the `dirs` buffer ([`Rings::encode`]).

use std::sync::OnceLock;

/// Up to four (index, weight) pairs, weights summing to 1: a direction's blend over sampled
/// directions (bilinear over rings: four; nearest three: three; on one ring: two). Held inline,
/// so a lookup allocates nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    len: usize,
    items: [(usize, f64); 4],
}

impl Blend {
    pub const EMPTY: Blend = Blend {
        len: 0,
        items: [(0, 0.0); 4],
    };

    /// One direction alone.
    pub fn one(i: usize) -> Blend {
        let mut b = Blend::EMPTY;
        b.push(i, 1.0);
        b
    }

    /// Appends a pair; a fifth is a bug in the caller (no blend has more than four).
    pub fn push(&mut self, i: usize, w: f64) {
        self.items[self.len] = (i, w);
        self.len += 1;
    }

    /// Keeps the pairs `keep` accepts, in order.
    pub fn retain(&mut self, keep: impl Fn(&(usize, f64)) -> bool) {
        let mut n = 0;
        for k in 0..self.len {
            if keep(&self.items[k]) {
                self.items[n] = self.items[k];
                n += 1;
            }
        }
        self.len = n;
    }
}

impl std::ops::Deref for Blend {
    type Target = [(usize, f64)];
    fn deref(&self) -> &[(usize, f64)] {
        &self.items[..self.len]
    }
}

impl IntoIterator for Blend {
    type Item = (usize, f64);
    type IntoIter = std::iter::Take<std::array::IntoIter<(usize, f64), 4>>;
    fn into_iter(self) -> Self::IntoIter {
        self.items.into_iter().take(self.len)
    }
}

impl<'b> IntoIterator for &'b Blend {
    type Item = &'b (usize, f64);
    type IntoIter = std::slice::Iter<'b, (usize, f64)>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// Whether directions at cosine `c` (clamped to [-1, 1]) are within 1e-4 rad of each other,
/// `acos(c) < 1e-4`, without the arc cosine: `c` at least the smallest cosine whose arc cosine
/// is under 1e-4, found once by bisection over the doubles (`acos` is monotone), so the answer
/// is the arc cosine's own, bit for bit.
pub fn within_1e4_rad(c: f64) -> bool {
    static SMALLEST: OnceLock<f64> = OnceLock::new();
    let x0 = *SMALLEST.get_or_init(|| {
        // acos(0.99) > 1e-4 and acos(1) = 0: the first double in between whose arc cosine is
        // under 1e-4 (positive doubles order as their bits).
        let (mut lo, mut hi) = (0.99f64.to_bits(), 1.0f64.to_bits());
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if f64::from_bits(mid).acos() < 1e-4 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        f64::from_bits(hi)
    });
    c >= x0
}

#[derive(Clone, Debug, PartialEq)]
pub struct Ring {
    pub theta: f64,
    /// (φ in [0, 2π), direction index), sorted by φ.
    pub members: Vec<(f64, usize)>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Rings {
    /// Sorted by θ.
    pub rings: Vec<Ring>,
}

/// Directions within this polar angle of each other share a ring (radians).
const SAME_RING: f64 = 0.01;

fn polar(d: &[f64; 3]) -> (f64, f64) {
    let theta = d[2].clamp(-1.0, 1.0).acos();
    let phi = d[1].atan2(d[0]).rem_euclid(std::f64::consts::TAU);
    (theta, phi)
}

impl Rings {
    /// The rings of `dirs` (unit vectors), or `None` when they are not ring-structured.
    pub fn of(dirs: &[[f64; 3]]) -> Option<Rings> {
        let mut rings: Vec<Ring> = Vec::new();
        for (i, d) in dirs.iter().enumerate() {
            let (theta, phi) = polar(d);
            match rings
                .iter_mut()
                .find(|r| (r.theta - theta).abs() < SAME_RING)
            {
                Some(r) => r.members.push((phi, i)),
                None => rings.push(Ring {
                    theta,
                    members: vec![(phi, i)],
                }),
            }
        }
        if rings.len() < 2 || 2 * rings.len() > dirs.len() {
            return None;
        }
        rings.sort_by(|a, b| a.theta.total_cmp(&b.theta));
        for r in &mut rings {
            r.members
                .sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        }
        Some(Rings { rings })
    }

    /// Ring `r` at azimuth `phi`: the two members bracketing it, linear in φ.
    pub fn on_ring(&self, r: usize, phi: f64) -> Blend {
        let m = &self.rings[r].members;
        if m.len() == 1 {
            return Blend::one(m[0].1);
        }
        let tau = std::f64::consts::TAU;
        let phi = phi.rem_euclid(tau);
        // The last member at or before φ (cyclically: before the first is the last).
        let j = m.partition_point(|x| x.0 <= phi);
        let (a, b) = if j == 0 || j == m.len() {
            (m[m.len() - 1], m[0])
        } else {
            (m[j - 1], m[j])
        };
        let span = (b.0 - a.0).rem_euclid(tau);
        let t = if span > 0.0 {
            ((phi - a.0).rem_euclid(tau) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let mut out = Blend::EMPTY;
        out.push(a.1, 1.0 - t);
        out.push(b.1, t);
        out
    }

    /// The bilinear blend of `q` (unit vector); a sampled direction within 1e-4 rad alone.
    pub fn blend(&self, dirs: &[[f64; 3]], q: [f64; 3]) -> Blend {
        let (theta, phi) = polar(&q);
        let n = self.rings.len();
        let below = self.rings.partition_point(|r| r.theta <= theta);
        let mut out: Blend = if below == 0 {
            self.on_ring(0, phi)
        } else if below == n {
            self.on_ring(n - 1, phi)
        } else {
            let (a, b) = (below - 1, below);
            let s = (theta - self.rings[a].theta) / (self.rings[b].theta - self.rings[a].theta);
            let mut v = Blend::EMPTY;
            for (i, w) in self.on_ring(a, phi) {
                v.push(i, w * (1.0 - s));
            }
            for (i, w) in self.on_ring(b, phi) {
                v.push(i, w * s);
            }
            v
        };
        let exact = out.iter().find(|(i, _)| {
            let d = dirs[*i];
            within_1e4_rad((d[0] * q[0] + d[1] * q[1] + d[2] * q[2]).clamp(-1.0, 1.0))
        });
        if let Some(&(i, _)) = exact {
            return Blend::one(i);
        }
        out.retain(|(_, w)| *w > 0.0);
        out
    }

    /// The table as the GPU reads it: ring count, then per ring θ, member count and the
    /// members' (φ, index) pairs, as f32 (indices are exact).
    pub fn encode(&self) -> Vec<f32> {
        let mut v = vec![self.rings.len() as f32];
        for r in &self.rings {
            v.push(r.theta as f32);
            v.push(r.members.len() as f32);
            for &(phi, i) in &r.members {
                v.push(phi as f32);
                v.push(i as f32);
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Direction;

    fn ubo() -> Vec<[f64; 3]> {
        crate::btf::directions::ubo81()
            .iter()
            .map(|d| d.vector())
            .collect()
    }

    #[test]
    fn ubo81_is_six_rings_and_a_sample_is_its_own_blend() {
        let dirs = ubo();
        let r = Rings::of(&dirs).unwrap();
        let counts: Vec<usize> = r.rings.iter().map(|x| x.members.len()).collect();
        assert_eq!(counts, [1, 6, 12, 18, 20, 24]);
        for (i, d) in dirs.iter().enumerate() {
            assert_eq!(&*r.blend(&dirs, *d), &[(i, 1.0)]);
        }
        // Scattered directions are not rings.
        let scattered: Vec<[f64; 3]> = (0..10)
            .map(|k| Direction::degrees(5.0 * k as f64 + 3.0, 37.0 * k as f64).vector())
            .collect();
        assert!(Rings::of(&scattered).is_none());
    }

    #[test]
    fn the_blend_is_bilinear_in_theta_and_phi() {
        // Between the 30° ring (every 30°) and the 45° ring (every 20°), at θ = 33.75° (a
        // quarter of the way) and φ = 50°: on the 30° ring between φ 30° and 60° at t = 2/3, on
        // the 45° ring between 40° and 60° at t = 1/2. Any function linear in (θ, φ) on each
        // ring's segment is reproduced: here θ itself and φ itself.
        let dirs = ubo();
        let r = Rings::of(&dirs).unwrap();
        let q = Direction::degrees(33.75, 50.0).vector();
        let b = r.blend(&dirs, q);
        assert_eq!(b.len(), 4);
        assert!((b.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-12);
        let f = |g: &dyn Fn(&Direction) -> f64| -> f64 {
            let all = crate::btf::directions::ubo81();
            b.iter().map(|&(i, w)| w * g(&all[i])).sum()
        };
        assert!((f(&|d| d.theta.to_degrees()) - 33.75).abs() < 1e-9);
        let on_30 = 30.0 + 30.0 * (2.0 / 3.0);
        let on_45 = 50.0;
        let want_phi = 0.75 * on_30 + 0.25 * on_45;
        assert!((f(&|d| d.phi.to_degrees()) - want_phi).abs() < 1e-9);
        // Across φ = 0 the bracket wraps: between 345° and 0° on the 75° ring.
        let b = r.on_ring(5, 355f64.to_radians());
        let all = crate::btf::directions::ubo81();
        let phis: Vec<f64> = b.iter().map(|(i, _)| all[*i].phi.to_degrees()).collect();
        assert_eq!(phis, [345.0, 0.0]);
        assert!((b[0].1 - 1.0 / 3.0).abs() < 1e-9);
    }
}
