//! `sources: beam`: the light diffuses from where it scatters along the refracted ray, not
//! from one point a reduced mean free path under the sample.
//!
//! Jensen et al. 2001 put each sample's source 1/σt′ deep along its normal, whatever the
//! light's angle. Light arriving obliquely scatters shallower (depth t·μt along a ray of length
//! t), so its multiple scattering stays nearer where it entered. An independent half-space
//! transport (`docs/experiments/oblique_far_field.py`, albedo 0.99) gives the multiply
//! scattered light leaving 12–20 mean free paths out 0.735× normal incidence's share at
//! μ0 = 0.4 and 0.557× at μ0 = 0.05; the fixed source gives 1×, and on a back-lit ball sends
//! too much light to the unlit half (marble's dimmer half +35% against the volumetric truth).
//!
//! Here each sample stands for the photon beam of Habel et al. 2013 along its own refracted
//! light: first scatterings σs′e^(−σt′t) at distance t along it, taken at [`NODES`] midpoints
//! of equal slices of that distribution. What diffuses from each is only the light that
//! collides again, 1 − E₂(σt′z)/2 of it at depth z, and it starts where that second collision
//! happens on average, deeper by what the step gains (`Collision`): light that leaves after
//! one scattering is single scattering, which the render adds exactly (`single_scattering`).
//! Each source has its image mirrored in the entry point's extrapolated plane (z_b above it).
//! The beam ends where its ray leaves the object (traced through the mesh once per source):
//! the slices are of the first scatterings before that point, and the light past it, which
//! crosses without scattering, is lost to diffusion. Without the cut, light entering near the
//! terminator of a curved object ran on through the air beyond a short chord and diffused
//! from there into the shadowed side: ketchup's torus at 60 mm a unit (1/σt′ = 4.2 mm in red)
//! had its dimmer half +38% against the volumetric truth, +2% with it; skin1's +12.5%, +3%.
//! Against the transport above this gives 0.726 and 0.582 (0.632 against 0.628 at μ0 = 0.2;
//! the test below); the first scatterings themselves as sources give 0.64 and 0.39, and on
//! the back-lit skin ball they sent green and blue 23–77% too much light near the terminator,
//! where grazing light scatters shallowest.
//!
//! Only where the light goes is taken from the beam; how much comes from the profile (or
//! `energy: half_space`): the factor on the profile is the beam's flux through the exit
//! point's normal as a share of all it lets out through a plane, over the same for a beam
//! straight down at the same distance. On a plane lit straight down it is exactly the profile.
//! With a profile of multiple scattering alone (`pbd_multiple`) the two agree on what they
//! describe. `geometry: body` takes the beam's fluence, scaled the same way, for its boundary
//! data. Light a sample receives from the far side of its tangent plane (bounced light) is
//! taken as arriving along the normal; a lit sample's bounced light goes along the light with
//! the rest.

use super::directional::refracted;
use super::expneg::exp_neg;
use crate::sss::dipole::Dipole;
use crate::sss::octree::Octree;
use crate::support::geometry::{dot, mul, sub, V3};
use crate::support::raytrace::light::Light;
use crate::support::raytrace::tracer::Tracer;
use crate::types::ScatteringMaterial;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Points along the beam: midpoints of 12 equal slices put the shallowest 0.04 and the deepest
/// 3.2 reduced mean free paths along it. Against 48 (measured once, in a numpy copy of the
/// model at albedo 0.96) the share 12–20 paths out moves by 3% at μ0 = 0.4 and the 5–8 paths
/// annulus by 9% at grazing incidence; each point costs two flux kernels per channel a pair.
pub(super) const NODES: usize = 12;

/// Per channel σtr, z_b and the distances along the beam (mm); the light.
#[derive(Clone)]
pub(super) struct Beam {
    sigma_tr: [f64; 3],
    zb: [f64; 3],
    /// 1/σt′, mm.
    zr: [f64; 3],
    along: [[f64; NODES]; 3],
    /// The same in reduced mean free paths (σt′t, alike in every channel).
    optical: [f64; NODES],
    /// Per channel the point dipole's light out through a plane (its real source zr deep, its
    /// image zv above), e^(−σtr zr) + e^(−σtr zv), up to 2π.
    dipole_total: [f64; 3],
    /// The beam straight down on a plane, as a share of what it lets out, per channel against
    /// the distance (`Flat`).
    flat: [Flat; 3],
    eta: f64,
    light: Light,
    /// mm per world unit (sources are in mm, the light in world units).
    unit: f64,
}

impl Beam {
    pub(super) fn new(m: &ScatteringMaterial, light: &Light, unit: f64) -> Beam {
        let d = [0, 1, 2].map(|c| Dipole::new(m.sigma_s_prime[c], m.sigma_a[c], m.eta));
        let optical: [f64; NODES] =
            std::array::from_fn(|k| -(1.0 - (k as f64 + 0.5) / NODES as f64).ln());
        let mut beam = Beam {
            optical,
            dipole_total: d.map(|d| (-d.sigma_tr * d.zr).exp() + (-d.sigma_tr * d.zv).exp()),
            sigma_tr: d.map(|d| d.sigma_tr),
            zb: d.map(|d| 0.5 * (d.zv - d.zr)),
            zr: d.map(|d| d.zr),
            // zr = 1/σt′: the first scattering's distance at the midpoints of NODES equal
            // slices of its distribution.
            along: d.map(|d| optical.map(|x| x * d.zr)),
            flat: [Flat::EMPTY, Flat::EMPTY, Flat::EMPTY],
            eta: m.eta,
            light: light.clone(),
            unit,
        };
        beam.flat = [0, 1, 2].map(|c| Flat::new(&beam, c));
        beam
    }

    /// Per point of the beam, its second collision, for light entering at `cos` to the normal.
    fn seconds(&self, cos: f64) -> [Second; NODES] {
        std::array::from_fn(|k| Collision::table().at(self.optical[k] * cos))
    }

    /// Channel `c`'s points for light entering at `cos` to the normal whose ray leaves the
    /// object `reach` mm on (infinite: it never does), and the share of its light that
    /// scatters before: the first scatterings' distribution cut at `reach`, its NODES equal
    /// slices' midpoints. What passes the object without scattering leaves it unchanged.
    fn points(&self, c: usize, cos: f64, reach: f64) -> (Points, f64) {
        if reach == f64::INFINITY {
            let points = Points {
                along: self.along[c],
                seconds: self.seconds(cos),
            };
            return (points, 1.0);
        }
        let reaching = -(-reach.max(0.0) / self.zr[c]).exp_m1();
        let optical: [f64; NODES] =
            std::array::from_fn(|k| -(-reaching * (k as f64 + 0.5) / NODES as f64).ln_1p());
        let points = Points {
            along: optical.map(|x| x * self.zr[c]),
            seconds: optical.map(|x| Collision::table().at(x * cos)),
        };
        (points, reaching)
    }

    /// The real and virtual sources of channel `c`'s beam points, for a sample at `xi` with
    /// unit normal `ni`, light travelling along `w` inside at `cos` to the normal, and each
    /// point's second collision. A real source is where the second collision happens on
    /// average: the first's place, moved deeper by the mean of the depth it gains (those that
    /// leave upwards are the ones that do not collide again); its image is mirrored in the
    /// extrapolated plane z_b above the entry. Laid out a coordinate at a time, so the
    /// kernels' loops over the points vectorise.
    #[inline(always)]
    fn sources(&self, c: usize, at: &Entry, points: &Points) -> Sources {
        let mut s = Sources::default();
        for k in 0..NODES {
            let t = points.along[k];
            let deeper = points.seconds[k].deeper * self.zr[c];
            let up = 2.0 * (t * at.cos + deeper + self.zb[c]);
            for a in 0..3 {
                let real = at.xi[a] + (at.w[a] * t + at.ni[a] * -deeper);
                s.real[a][k] = real;
                s.image[a][k] = real + at.ni[a] * up;
            }
        }
        s
    }

    /// The beam's flux through `no` at `xo` in channel `c`, as a share of `total`, all it lets
    /// out through a plane. On a CPU with AVX2 the same arithmetic runs four lanes wide
    /// (`simd`): the same bits, as neither version fuses a multiply and an add.
    fn flux(&self, c: usize, xo: V3, no: V3, at: &Entry, points: &Points, total: f64) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if simd::avx2() {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { simd::flux(self, c, xo, no, at, points, total) };
        }
        self.flux_body(c, xo, no, at, points, total)
    }

    #[inline(always)]
    fn flux_body(&self, c: usize, xo: V3, no: V3, at: &Entry, points: &Points, total: f64) -> f64 {
        let s = self.sigma_tr[c];
        let sources = self.sources(c, at, points);
        let (real, image) = (
            through(&sources.real, xo, no, s),
            through(&sources.image, xo, no, s),
        );
        let sum: f64 = (0..NODES)
            .map(|k| points.seconds[k].kept * (real[k] - image[k]))
            .sum();
        sum / total
    }

    /// Where the light enters at a sample at `xi` (mm) with unit normal `ni`.
    fn entry(&self, xi: V3, ni: V3) -> Entry {
        let w = refracted(&self.light, self.unit, self.eta, xi, ni);
        Entry {
            xi,
            ni,
            w,
            cos: -dot(w, ni),
        }
    }

    /// The beam of a source at `xi` with unit normal `ni` (mm): where its light enters, each
    /// point's second collision and what it lets out through a plane, the same for every
    /// shaded point. `None` for a lumped node whose normals cancel (zero normal): its images
    /// cancel its sources, as with `exit_normal`.
    /// With `tracer` (world units of `unit` mm), the beam stops where its ray leaves the
    /// object.
    pub(super) fn enter(&self, xi: V3, ni: V3, tracer: Option<&Tracer>) -> Option<Entered> {
        if dot(ni, ni) < 0.25 {
            return None;
        }
        let at = self.entry(xi, ni);
        let reach = tracer.map_or(f64::INFINITY, |t| self.reach(t, &at));
        let mut reaching = [1.0; 3];
        let points = [0, 1, 2].map(|c| {
            let (points, share) = self.points(c, at.cos, reach);
            reaching[c] = share;
            points
        });
        let total = [0, 1, 2].map(|c| self.total(c, at.cos, &points[c]));
        Some(Entered {
            at,
            points,
            total,
            reaching,
        })
    }

    /// How far (mm) the light entering at `at` goes before its ray leaves the object;
    /// infinite where it finds no way out (an open mesh) or starts outside.
    fn reach(&self, tracer: &Tracer, at: &Entry) -> f64 {
        let from = sub(at.xi.map(|v| v / self.unit), mul(at.ni, tracer.epsilon));
        let Some(hit) = tracer.closest(from, at.w) else {
            return f64::INFINITY;
        };
        let (_, ng) = tracer.triangle(hit.tri);
        if dot(ng, at.w) > 0.0 {
            (hit.t + tracer.epsilon) * self.unit
        } else {
            f64::INFINITY
        }
    }

    /// The factor for a source at `xi` with normal `ni` seen from `xo` with normal `no` (mm).
    #[cfg(test)]
    pub(super) fn factor(&self, xo: V3, no: V3, xi: V3, ni: V3) -> [f64; 3] {
        self.enter(xi, ni, None)
            .map_or([0.0; 3], |e| self.factor_entered(xo, no, &e))
    }

    /// The factor for the source `e` seen from `xo` with normal `no` (mm).
    fn factor_entered(&self, xo: V3, no: V3, e: &Entered) -> [f64; 3] {
        let v = sub(xo, e.at.xi);
        let r = dot(v, v).sqrt();
        // The distance's logarithm once for the three channels' tables.
        let ln_r = r.max(1e-300).ln();
        let mut out = [1.0; 3];
        for (c, out) in out.iter_mut().enumerate() {
            let actual = self.flux(c, xo, no, &e.at, &e.points[c], e.total[c]) * e.reaching[c];
            let flat = self.flat[c].at(r, ln_r, self, c);
            if flat > 0.0 && flat.is_finite() && actual.is_finite() {
                *out = (actual / flat).max(0.0);
            }
        }
        out
    }

    /// The beam's fluence at `x` (mm) in channel `c` per unit power entering at the source
    /// `e`, over α′/(4πD): as a dipole's bracket e^(−σtr dr)/dr − e^(−σtr dv)/dv, summed over
    /// the points with the light they keep, scaled to let out through a plane what the point
    /// dipole does (as the gather's factor keeps the profile's energy).
    fn fluence_entered(&self, c: usize, x: V3, e: &Entered) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if simd::avx2() {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { simd::fluence(self, c, x, e) };
        }
        self.fluence_body(c, x, e)
    }

    #[inline(always)]
    fn fluence_body(&self, c: usize, x: V3, e: &Entered) -> f64 {
        let s = self.sigma_tr[c];
        let sources = self.sources(c, &e.at, &e.points[c]);
        let (real, image) = (
            fluence_kernel(&sources.real, x, s),
            fluence_kernel(&sources.image, x, s),
        );
        let sum: f64 = (0..NODES)
            .map(|k| e.points[c].seconds[k].kept * (real[k] - image[k]))
            .sum();
        sum * self.dipole_total[c] / e.total[c] * e.reaching[c]
    }

    /// What the beam in channel `c` entering at `cos` to the normal lets out through a flat
    /// boundary, up to 2π: each point's real source at depth z gives e^(−σtr z) (the flux
    /// kernel z(1 + σtr d)e^(−σtr d)/d³ integrated over the plane) and its image, as far above
    /// the extrapolated plane, e^(−σtr (z + 2z_b)) (Jensen et al.'s total reflectance is α′/2
    /// times the two).
    fn total(&self, c: usize, cos: f64, points: &Points) -> f64 {
        let s = self.sigma_tr[c];
        (0..NODES)
            .map(|k| {
                let second = points.seconds[k];
                let z = points.along[k] * cos + second.deeper * self.zr[c];
                second.kept * ((-s * z).exp() + (-s * (z + 2.0 * self.zb[c])).exp())
            })
            .sum()
    }
}

/// A sample's entry: position and unit normal (mm), the light's direction inside and its
/// cosine to the inward normal.
#[derive(Clone)]
struct Entry {
    xi: V3,
    ni: V3,
    w: V3,
    cos: f64,
}

impl Entry {
    /// Straight down into a plane at the origin.
    const STRAIGHT_DOWN: Entry = Entry {
        xi: [0.0; 3],
        ni: [0.0, 0.0, 1.0],
        w: [0.0, 0.0, -1.0],
        cos: 1.0,
    };
}

/// One channel's beam points: the first scatterings' distances along the light (mm) and
/// their second collisions.
#[derive(Clone, Copy)]
struct Points {
    along: [f64; NODES],
    seconds: [Second; NODES],
}

/// The flux kernel (`geometry::flux_kernel`) through `no` at `xo` from each of the sources
/// `p` (a coordinate at a time), σtr `s`: a loop over the points that vectorises.
#[inline(always)]
fn through(p: &[[f64; NODES]; 3], xo: V3, no: V3, s: f64) -> [f64; NODES] {
    let mut out = [0.0; NODES];
    for k in 0..NODES {
        let v = [xo[0] - p[0][k], xo[1] - p[1][k], xo[2] - p[2][k]];
        let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-12);
        let across = v[0] * no[0] + v[1] * no[1] + v[2] * no[2];
        out[k] = across * (1.0 + s * d) * exp_neg(-s * d) / (d * d * d);
    }
    out
}

/// A dipole's bracket term e^(−σtr d)/d at `x` from each of the sources `p`.
#[inline(always)]
fn fluence_kernel(p: &[[f64; NODES]; 3], x: V3, s: f64) -> [f64; NODES] {
    let mut out = [0.0; NODES];
    for k in 0..NODES {
        let v = [x[0] - p[0][k], x[1] - p[1][k], x[2] - p[2][k]];
        let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
        out[k] = exp_neg(-s * d) / d;
    }
    out
}

/// The kernels compiled for AVX2, chosen at run time: LLVM widens their loops over the beam
/// points from two lanes to four. Only instructions that round each operation as the portable
/// version does (no fused multiply-add), so the values are the same bits on either path.
#[cfg(target_arch = "x86_64")]
mod simd {
    use super::{Beam, Entered, Entry, Points};
    use crate::support::geometry::V3;

    pub(super) fn avx2() -> bool {
        std::arch::is_x86_feature_detected!("avx2")
    }

    /// # Safety
    /// The CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn flux(
        beam: &Beam,
        c: usize,
        xo: V3,
        no: V3,
        at: &Entry,
        points: &Points,
        total: f64,
    ) -> f64 {
        beam.flux_body(c, xo, no, at, points, total)
    }

    /// # Safety
    /// The CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn fluence(beam: &Beam, c: usize, x: V3, e: &Entered) -> f64 {
        beam.fluence_body(c, x, e)
    }
}

/// One channel's real sources and their images ([`Beam::sources`]), a coordinate at a time.
#[derive(Default)]
struct Sources {
    real: [[f64; NODES]; 3],
    image: [[f64; NODES]; 3],
}

/// One source's beam as [`Beam::enter`] makes it.
#[derive(Clone)]
pub(super) struct Entered {
    at: Entry,
    points: [Points; 3],
    /// What it lets out through a plane per channel ([`Beam::total`]).
    total: [f64; 3],
    /// The share of its light that scatters before its ray leaves the object.
    reaching: [f64; 3],
}

/// A beam with every term an octree's gather can have entered once ([`Octree::points`]):
/// per term a gather then pays only for the pairs, not for the light's refraction, the
/// second collisions and the totals again, which were half its time.
#[derive(Clone)]
pub(super) struct Beams {
    beam: Beam,
    entered: Vec<Option<Entered>>,
}

impl Beams {
    /// Each beam cut where its ray leaves the mesh `tracer` holds.
    pub(super) fn new(beam: Beam, octree: &Octree, tracer: &Tracer) -> Beams {
        let entered = octree
            .points()
            .par_iter()
            .map(|&(p, n)| beam.enter(p, n, Some(tracer)))
            .collect();
        Beams { beam, entered }
    }

    /// The same beam for a rebuilt octree.
    pub(super) fn rebuilt(self, octree: &Octree, tracer: &Tracer) -> Beams {
        Beams::new(self.beam, octree, tracer)
    }

    /// [`Beam::enter`]'s factor for the term `key` of a gather over the octree these were
    /// made for.
    pub(super) fn factor(&self, xo: V3, no: V3, key: usize) -> [f64; 3] {
        self.entered[key]
            .as_ref()
            .map_or([0.0; 3], |e| self.beam.factor_entered(xo, no, e))
    }

    /// The beam's fluence (`Beam::fluence_entered`) for the term `key`.
    pub(super) fn fluence(&self, c: usize, x: V3, key: usize) -> f64 {
        self.entered[key]
            .as_ref()
            .map_or(0.0, |e| self.beam.fluence_entered(c, x, e))
    }
}

/// The beam straight down on a plane, the flux at distance r on it as a share of all it lets
/// out: the factor's denominator, the same for every pair at the same distance. Tabulated in
/// ln r, PER_DECADE points a decade from a thousandth of 1/σt′ to fifty diffusion lengths
/// (log-linear between them: its shape is smooth there); computed where it falls outside.
#[derive(Clone)]
struct Flat {
    ln_first: f64,
    per_ln: f64,
    ln_values: Vec<f64>,
}

impl Flat {
    const PER_DECADE: f64 = 512.0;
    const EMPTY: Flat = Flat {
        ln_first: 0.0,
        per_ln: 0.0,
        ln_values: Vec::new(),
    };

    fn new(beam: &Beam, c: usize) -> Flat {
        let first = 1e-3 * beam.zr[c];
        let last = 50.0 / beam.sigma_tr[c].max(1e-12);
        let per_ln = Flat::PER_DECADE / std::f64::consts::LN_10;
        let count = ((last / first).ln() * per_ln).ceil() as usize + 1;
        let ln_values = (0..count)
            .map(|i| Flat::direct(beam, c, first * (i as f64 / per_ln).exp()).ln())
            .collect();
        Flat {
            ln_first: first.ln(),
            per_ln,
            ln_values,
        }
    }

    fn direct(beam: &Beam, c: usize, r: f64) -> f64 {
        let up = [0.0, 0.0, 1.0];
        let (points, _) = beam.points(c, 1.0, f64::INFINITY);
        let total = beam.total(c, 1.0, &points);
        beam.flux(c, [r, 0.0, 0.0], up, &Entry::STRAIGHT_DOWN, &points, total)
    }

    /// At distance `r`, whose logarithm (of `r.max(1e-300)`) is `ln_r`.
    fn at(&self, r: f64, ln_r: f64, beam: &Beam, c: usize) -> f64 {
        let f = (ln_r - self.ln_first) * self.per_ln;
        let n = self.ln_values.len();
        if !(f >= 0.0 && f < (n - 1) as f64 && n >= 2) {
            return Flat::direct(beam, c, r);
        }
        let i = f as usize;
        let t = f - i as f64;
        let v = self.ln_values[i] * (1.0 - t) + self.ln_values[i + 1] * t;
        if v.is_finite() {
            v.exp()
        } else {
            Flat::direct(beam, c, r)
        }
    }
}

/// Where light scattered isotropically x reduced mean free paths under a flat boundary
/// collides next. Over the direction's cosine u (uniform on −1..1) and an exponential step:
/// it leaves without another collision with probability E₂(x)/2, E₂(x) = ∫₀¹ e^(−x/u) du
/// (Chandrasekhar 1960); the depth it gains, summed over the steps that stay inside,
/// ∫ uℓ e^(−ℓ), is ½∫₀¹ (u + x) e^(−x/u) du (¼ at the boundary, 0 deep down); over the share
/// that stays, how much deeper its second collision lies on average.
struct Collision {
    step: f64,
    entries: Vec<Second>,
}

/// At one depth: the share that collides again and how much deeper it does so on average
/// (reduced mean free paths).
#[derive(Clone, Copy, Debug)]
struct Second {
    kept: f64,
    deeper: f64,
}

impl Collision {
    /// Up to 30 mean free paths (beyond, e^(−30): nothing leaves).
    const REACH: f64 = 30.0;
    const ENTRIES: usize = 3001;
    /// Midpoints per integral: the integrands are smooth and bounded.
    const SLICES: usize = 4000;

    /// The one table, made on first use.
    fn table() -> &'static Collision {
        static TABLE: OnceLock<Collision> = OnceLock::new();
        TABLE.get_or_init(Collision::new)
    }

    fn new() -> Collision {
        let step = Collision::REACH / (Collision::ENTRIES - 1) as f64;
        let du = 1.0 / Collision::SLICES as f64;
        let entries = (0..Collision::ENTRIES)
            .map(|i| {
                let x = i as f64 * step;
                let (mut e2, mut gained) = (0.0, 0.0);
                for j in 0..Collision::SLICES {
                    let u = (j as f64 + 0.5) * du;
                    let f = (-x / u).exp() * du;
                    e2 += f;
                    gained += (u + x) * f;
                }
                let kept = 1.0 - 0.5 * e2;
                Second {
                    kept,
                    deeper: 0.5 * gained / kept,
                }
            })
            .collect();
        Collision { step, entries }
    }

    fn at(&self, x: f64) -> Second {
        let f = (x.max(0.0) / self.step).min((Collision::ENTRIES - 1) as f64);
        let i = (f as usize).min(Collision::ENTRIES - 2);
        let t = f - i as f64;
        let (a, b) = (self.entries[i], self.entries[i + 1]);
        Second {
            kept: a.kept * (1.0 - t) + b.kept * t,
            deeper: a.deeper * (1.0 - t) + b.deeper * t,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::raytrace::light::LightParams;

    fn marble() -> ScatteringMaterial {
        ScatteringMaterial {
            sigma_s_prime: [2.19, 2.62, 3.00],
            sigma_a: [0.0021, 0.0041, 0.0071],
            eta: 1.0,
            g: 0.0,
        }
    }

    fn lit_from(to_light: V3) -> Light {
        Light::new(&LightParams {
            direction: to_light,
            ..LightParams::default()
        })
        .expect("a valid light")
    }

    #[test]
    fn the_second_collision_table_against_published_exponential_integrals() {
        // E₁ and E₂ from Abramowitz & Stegun, table 5.1: the share kept is 1 − E₂/2, and the
        // depth gained, ½∫₀¹ (u + x) e^(−x/u) du, is in closed form ¼(1 + x)e^(−x) − x²E₁(x)/4
        // (integrating x·E₁ by parts). The table's linear steps of 0.01 and its 4000
        // midpoints are good to a few parts in 10⁵ of these values.
        for (x, e1, e2) in [
            (0.1, 1.822_923_958, 0.722_545_022),
            (0.5, 0.559_773_595, 0.326_643_862),
            (1.0, 0.219_383_934, 0.148_495_507),
            (2.0, 0.048_900_511, 0.037_534_262),
            (5.0, 0.001_148_295_6, 0.000_996_469_8),
        ] {
            let got = Collision::table().at(x);
            let kept = 1.0 - 0.5 * e2;
            let gained = 0.25 * (1.0 + x) * (-x).exp() - 0.25 * x * x * e1;
            assert!(
                (got.kept / kept - 1.0).abs() < 2e-4,
                "{x}: kept {}",
                got.kept
            );
            assert!(
                (got.deeper * got.kept / gained - 1.0).abs() < 2e-4,
                "{x}: deeper {}",
                got.deeper
            );
        }
        // At the boundary half leaves, and the half that stays went a quarter path down on
        // average over everything, so half a path over itself.
        let edge = Collision::table().at(0.0);
        assert!((edge.kept - 0.5).abs() < 1e-12 && (edge.deeper - 0.5).abs() < 1e-3);
    }

    #[test]
    fn what_a_beam_lets_out_through_a_plane_is_its_flux_summed_over_the_plane() {
        // The closed form `total` against the flux summed over a wide disc by brute force
        // (polar midpoints, 0.01 mm near the entry where the shallow points peak), lit at
        // 60° and straight down.
        let m = marble();
        for to_light in [[0.0, 0.0, 1.0], [0.75f64.sqrt(), 0.0, 0.5]] {
            let beam = Beam::new(&m, &lit_from(to_light), 1.0);
            let up = [0.0, 0.0, 1.0];
            let at = beam.entry([0.0; 3], up);
            let points = [0, 1, 2].map(|c| beam.points(c, at.cos, f64::INFINITY).0);
            let totals = [0, 1, 2].map(|c| beam.total(c, at.cos, &points[c]));
            let mut sum = [0.0; 3];
            let (mut r, angles): (f64, usize) = (0.0, 256);
            while r < 400.0 {
                let dr = (0.01 + 0.02 * r).min(2.0);
                let mid = r + 0.5 * dr;
                for a in 0..angles {
                    let phi = 2.0 * std::f64::consts::PI * (a as f64 + 0.5) / angles as f64;
                    let x = [mid * phi.cos(), mid * phi.sin(), 0.0];
                    let da = mid * dr * 2.0 * std::f64::consts::PI / angles as f64;
                    for (c, sum) in sum.iter_mut().enumerate() {
                        *sum += beam.flux(c, x, up, &at, &points[c], totals[c]) * da;
                    }
                }
                r += dr;
            }
            for (c, sum) in sum.iter().enumerate() {
                // `flux` is a share of `total`: summed over the plane it must give all of it.
                let want = 2.0 * std::f64::consts::PI;
                // The sum's own error: midpoints over a peak 0.04 reduced mean free paths deep.
                assert!(
                    (sum / want - 1.0).abs() < 0.01,
                    "{to_light:?} {c}: {} vs {want}",
                    sum
                );
            }
        }
    }

    /// The beam's share of its multiply scattered light leaving 12 to 20 mean free paths from
    /// where light enters a flat medium at `mu0` (σt′ = 1, albedo 0.99), over normal
    /// incidence's share.
    fn far_share(mu0: f64) -> f64 {
        let m = ScatteringMaterial {
            sigma_s_prime: [0.99; 3],
            sigma_a: [0.01; 3],
            eta: 1.0,
            g: 0.0,
        };
        let share = |mu0: f64| {
            let to_light = [(1.0 - mu0 * mu0).sqrt(), 0.0, mu0];
            let beam = Beam::new(&m, &lit_from(to_light), 1.0);
            let up = [0.0, 0.0, 1.0];
            let at = beam.entry([0.0; 3], up);
            let (points, _) = beam.points(0, at.cos, f64::INFINITY);
            let total = beam.total(0, at.cos, &points);
            let (steps, angles) = (160, 256);
            let mut sum = 0.0;
            for i in 0..steps {
                let r = 12.0 + 8.0 * (i as f64 + 0.5) / steps as f64;
                for a in 0..angles {
                    let phi = 2.0 * std::f64::consts::PI * (a as f64 + 0.5) / angles as f64;
                    let x = [r * phi.cos(), r * phi.sin(), 0.0];
                    sum += beam.flux(0, x, up, &at, &points, total) * r;
                }
            }
            let area = 8.0 / steps as f64 * 2.0 * std::f64::consts::PI / angles as f64;
            sum * area / (2.0 * std::f64::consts::PI)
        };
        share(mu0) / share(1.0)
    }

    #[test]
    fn oblique_light_sends_its_multiple_scattering_less_far_as_transport_does() {
        // Independent transport: docs/experiments/oblique_far_field.py 0.99 200000 (Monte
        // Carlo, isotropic scattering, index-matched; its last table, 12–20 mean free paths).
        // Jensen's fixed source gives 1 at every angle; the beam from the first collisions
        // themselves, without moving them to the second's depth, 0.64, 0.50 and 0.39.
        for (mu0, transport) in [(0.4, 0.735), (0.2, 0.628), (0.05, 0.557)] {
            let beam = far_share(mu0);
            eprintln!("μ0 {mu0}: beam {beam:.3}, transport {transport:.3}");
            // Measured within 4.5% (0.726, 0.632, 0.582); the transport's own noise in the
            // annulus is a few percent, the rest is diffusion's.
            assert!(
                (beam / transport - 1.0).abs() < 0.08,
                "μ0 {mu0}: {beam} vs {transport}"
            );
        }
    }

    #[test]
    fn the_avx2_kernels_give_the_portable_kernels_bits() {
        // The kernels run four lanes wide where the CPU has AVX2 and two otherwise: the same
        // operations, each rounded alike, so the same bits (no tolerance). Oblique light,
        // points near and far, above and below the entry, an exit normal that tilts.
        #[cfg(target_arch = "x86_64")]
        if simd::avx2() {
            let beam = Beam::new(&marble(), &lit_from([0.6, 0.2, 0.7]), 1.0);
            let e = beam
                .enter([0.1, -0.2, 0.3], [0.0, 0.6, 0.8], None)
                .expect("lit");
            let mut compared = 0;
            for i in 0..200 {
                let t = i as f64 * 0.37;
                let x = [
                    t.sin() * t,
                    (1.3 * t).cos() * 0.5 * t,
                    (0.7 * t).sin() * 3.0,
                ];
                let no = [(0.3 * t).cos(), (0.3 * t).sin(), 0.2];
                for c in 0..3 {
                    let points = &e.points[c];
                    // SAFETY: the CPU has AVX2 (checked above).
                    let wide = unsafe { simd::flux(&beam, c, x, no, &e.at, points, e.total[c]) };
                    let narrow = beam.flux_body(c, x, no, &e.at, points, e.total[c]);
                    assert_eq!(wide.to_bits(), narrow.to_bits(), "flux {i} {c}");
                    // SAFETY: as above.
                    let wide = unsafe { simd::fluence(&beam, c, x, &e) };
                    let narrow = beam.fluence_body(c, x, &e);
                    assert_eq!(wide.to_bits(), narrow.to_bits(), "fluence {i} {c}");
                    compared += 1;
                }
            }
            assert_eq!(compared, 600);
        } else {
            mesoflow_testkit::skip::skip("this CPU has no AVX2, so only the portable kernels run");
        }
    }

    #[test]
    fn a_plane_lit_straight_down_keeps_the_profile() {
        let beam = Beam::new(&marble(), &lit_from([0.0, 0.0, 1.0]), 1.0);
        let up = [0.0, 0.0, 1.0];
        // Between the denominator's table points too (log-linear in ln r, 512 a decade):
        // exactly 1 up to that interpolation, 2.5·10⁻⁶ σtr r at most.
        for r in [0.013, 0.05, 0.5, 0.777, 3.0, 20.0, 123.4] {
            for f in beam.factor([r, 0.0, 0.0], up, [0.0; 3], up) {
                assert!((f - 1.0).abs() < 1e-4, "{r}: {f}");
            }
        }
    }

    #[test]
    fn a_beam_stops_where_its_ray_leaves_a_ball() {
        // A ball of 10 mm lit from straight above, η = 1: the light entering at polar angle θ
        // runs straight down a chord 2R·cos θ long (closed form; the facets stay within 0.06%
        // of the sphere). A medium of 1/σt′ = 4 mm lets e^(−σt′·chord) of it through unscattered,
        // so 1 − e^(−σt′·chord) reaches the beam, and every point lies on the chord.
        let mesh = crate::mesh::primitive::build(&crate::mesh::primitive::Params {
            shape: crate::mesh::primitive::Shape::Sphere,
            size: 1.0,
            minor: 0.0,
            segments: [96, 48],
        })
        .expect("a sphere");
        let tracer = Tracer::new(&mesh);
        let (radius, zr) = (10.0, 4.0);
        let m = ScatteringMaterial {
            sigma_s_prime: [0.9 / zr; 3],
            sigma_a: [0.1 / zr; 3],
            eta: 1.0,
            g: 0.0,
        };
        let beam = Beam::new(&m, &lit_from([0.0, 0.0, 1.0]), radius);
        for theta in [0.05f64, 0.6, 1.2] {
            let phi: f64 = 0.013;
            let n = [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ];
            // The entry on the mesh (the facets lie inside the sphere): where a ray from
            // outside along −n meets it.
            let hit = tracer.closest(mul(n, 2.0), mul(n, -1.0)).expect("the ball");
            let xi = mul(n, (2.0 - hit.t) * radius);
            let e = beam.enter(xi, n, Some(&tracer)).expect("lit");
            let chord = 2.0 * radius * theta.cos();
            let want = 1.0 - (-chord / zr).exp();
            // The facets sit up to 0.06% of R inside the sphere, at both ends of the chord,
            // which meets them at cos θ.
            let slack = 2.0 * 6e-4 * radius / theta.cos();
            for c in 0..3 {
                assert!(
                    (e.reaching[c] - want).abs() < slack / zr,
                    "θ {theta}: {} vs {want}",
                    e.reaching[c]
                );
                let last = e.points[c].along[NODES - 1];
                assert!(
                    last < chord + slack,
                    "θ {theta}: point {last} mm past {chord}"
                );
            }
            // Never cut without a tracer.
            let open = beam.enter(xi, n, None).expect("lit");
            assert_eq!(open.reaching, [1.0; 3]);
        }
    }
}
