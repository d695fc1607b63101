//! `geometry: body`: what a finite object's own boundary does to the light diffusing in it.
//!
//! `exit_normal` takes each entry point's dipole (Jensen et al. 2001) and its flux through the
//! exit point's normal; the dipole is the diffusion equation's solution for a half-space
//! bounded by the entry point's own tangent plane, so light that a small or curved body lets
//! out elsewhere stays in (a back-lit marble ball's unlit front 47% too bright against the
//! volumetric truth), and light crossing a slab meets no boundary on the far side (38% too
//! little through it against the one-dimensional solution). Here the body's own diffusion
//! problem is solved: with φ_dip the sum of every sample's dipole, the true fluence is
//! φ = φ_dip + ψ, where ψ has no sources inside (the dipoles' real sources are φ_dip's) and
//! makes φ vanish on the extrapolated boundary (the surface moved out by z_b = 2AD, where each
//! dipole vanishes on its own plane):
//!
//!   −D∇²ψ + σa ψ = 0 inside,   ψ = −φ_dip on the extrapolated boundary.
//!
//! On a flat object ψ = 0: each dipole already vanishes there. ψ is smooth (its boundary data
//! change on the scale of the shape and of 1/σtr, not of the dipoles' peaks), so a coarse grid
//! carries it: cell-centred finite differences, the boundary cut between cells where it lies
//! (Gibou et al. 2002's symmetric treatment), conjugate gradients per channel. The exitance
//! gains −D ∂ψ/∂n at each shaded point, on top of the `exit_normal` gather.

use super::beam::Beams;
use crate::sss::dipole::Dipole;
use crate::sss::octree::Octree;
use crate::support::geometry::{add, dot, mul, sub, V3};
use crate::support::raytrace::tracer::Tracer;
use crate::types::{BodyChannel, BodyGrid, Mesh, ScatteringMaterial};
use mesoflow_runtime::NodeError;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Most grid cells: the spacing grows past what the material asks for to respect it.
const MAX_CELLS: f64 = 1.5e6;
/// Cells across the object's smallest extent at least.
const ACROSS: f64 = 24.0;
/// Conjugate-gradient stop: residual over right-hand side.
const TOLERANCE: f64 = 1e-7;
const MAX_ITERATIONS: usize = 5000;
/// Cut cells nearer the boundary than this share of a cell count as this near: the diagonal
/// grows as 1/θ (Gibou et al.), and a thousandth of a cell changes nothing visible.
const THETA_MIN: f64 = 1e-3;
const NONE: u32 = u32::MAX;
/// The octree criterion (ΔA/d²) of φ_dip's sums: ψ's boundary data are a smooth far field,
/// so this is part of the grid's approximation, the same whatever the gather's `threshold`
/// (brute force included).
const LUMPING: f64 = 0.15;

/// The grid and, per channel, ψ.
pub(super) struct Body {
    /// Centre of cell (0, 0, 0), mm.
    origin: V3,
    h: f64,
    dims: [usize; 3],
    channels: Vec<Channel>,
    /// The dipoles' constants per channel.
    dipoles: [Dipole; 3],
    /// With `sources: beam`, the beams that stand for the dipoles, entered for the octree
    /// the body was made with.
    beam: Option<Beams>,
}

struct Channel {
    /// Unknown number per cell, or [`NONE`] outside the extrapolated boundary.
    index: Vec<u32>,
    psi: Vec<f64>,
    d: f64,
    zb: f64,
}

/// What building the grid found worth telling.
pub(super) struct Report {
    pub(super) spacing_mm: f64,
    pub(super) warnings: Vec<String>,
}

impl Body {
    /// The grid over `mesh` (world units of `unit` mm), ψ solved for the dipoles (or, with
    /// `beam`, the beams, entered for `octree`) of the sources in `octree` (mm, E·ΔA).
    pub(super) fn new(
        tracer: &Tracer,
        mesh: &Mesh,
        octree: &Octree,
        beam: Option<Beams>,
        material: &ScatteringMaterial,
        unit: f64,
    ) -> Result<(Body, Report), NodeError> {
        let dipoles = dipoles(material);
        let mut warnings = Vec::new();
        let (lo, hi) = bounds_mm(mesh, unit);
        let smallest = (0..3).map(|k| hi[k] - lo[k]).fold(f64::INFINITY, f64::min);
        let reach = dipoles
            .iter()
            .map(|d| 1.0 / d.sigma_tr)
            .fold(f64::INFINITY, f64::min);
        let wanted = (0.5 * reach).min(smallest / ACROSS);
        let cells_at = |h: f64| Grid::over(lo, hi, h, pad(&dipoles, h)).count() as f64;
        let mut h = wanted;
        while cells_at(h) > MAX_CELLS {
            h *= 1.1;
        }
        if h > wanted * 1.0001 {
            warnings.push(format!(
                "geometry: body: the grid's cells are {h:.3} mm, coarser than the {wanted:.3} mm the material asks for ({MAX_CELLS} cells at most)"
            ));
        }
        let mut body = Body::with_spacing(tracer, mesh, octree, beam, material, unit, h)?;
        warnings.append(&mut body.1.warnings);
        body.1.warnings = warnings;
        Ok(body)
    }

    /// [`Body::new`] with cells of `h` mm.
    fn with_spacing(
        tracer: &Tracer,
        mesh: &Mesh,
        octree: &Octree,
        beam: Option<Beams>,
        material: &ScatteringMaterial,
        unit: f64,
        h: f64,
    ) -> Result<(Body, Report), NodeError> {
        let dipoles = dipoles(material);
        let (lo, hi) = bounds_mm(mesh, unit);
        let band = pad(&dipoles, h);
        let grid = Grid::over(lo, hi, h, band);
        let signed = grid.signed_distance(tracer, mesh, unit, band)?;
        let mut warnings = Vec::new();
        let mut channels = Vec::with_capacity(3);
        for (c, dipole) in dipoles.iter().enumerate() {
            let (channel, its, converged) = grid.solve(&signed, dipole, material.sigma_a[c], |x| {
                -fluence(octree, &dipoles, beam.as_ref(), c, x)
            });
            if !converged {
                warnings.push(format!(
                    "geometry: body: the {} channel's solve stopped after {its} iterations short of its tolerance",
                    ["red", "green", "blue"][c]
                ));
            }
            channels.push(channel);
        }
        Ok((
            Body {
                origin: grid.origin,
                h,
                dims: grid.dims,
                channels,
                dipoles,
                beam,
            },
            Report {
                spacing_mm: h,
                warnings,
            },
        ))
    }

    /// The grid and its solution as a cached `SssLighting` holds them.
    pub(super) fn to_grid(&self) -> BodyGrid {
        BodyGrid {
            origin: self.origin,
            h: self.h,
            dims: self.dims,
            channels: self
                .channels
                .iter()
                .map(|c| BodyChannel {
                    index: c.index.clone(),
                    psi: c.psi.clone(),
                    d: c.d,
                    zb: c.zb,
                })
                .collect(),
        }
    }

    /// The body [`Body::to_grid`] stored, for `material` and the beams (if any) of the octree
    /// it was made with.
    pub(super) fn from_grid(
        grid: &BodyGrid,
        material: &ScatteringMaterial,
        beam: Option<Beams>,
    ) -> Result<Body, NodeError> {
        if grid.channels.len() != 3 {
            return Err(NodeError::input(
                "lighting",
                "the body grid has not three channels",
            ));
        }
        Ok(Body {
            origin: grid.origin,
            h: grid.h,
            dims: grid.dims,
            channels: grid
                .channels
                .iter()
                .map(|c| Channel {
                    index: c.index.clone(),
                    psi: c.psi.clone(),
                    d: c.d,
                    zb: c.zb,
                })
                .collect(),
            dipoles: dipoles(material),
            beam,
        })
    }

    /// −D ∂ψ/∂n at the surface point `xo` (mm) with outward unit normal `no`, per channel
    /// (`octree` the one the body was made with): a quadratic along the normal through ψ's
    /// boundary value z_b outside and the grid's values one and two cells inside.
    pub(super) fn exitance(&self, octree: &Octree, xo: V3, no: V3) -> [f64; 3] {
        [0, 1, 2].map(|c| {
            let outside = add(xo, mul(no, self.channels[c].zb));
            let at_boundary = -fluence(octree, &self.dipoles, self.beam.as_ref(), c, outside);
            self.slope(&self.channels[c], xo, no, at_boundary)
        })
    }

    /// −D ∂ψ/∂n at `xo` given ψ's boundary value z_b outside along `no`.
    fn slope(&self, ch: &Channel, xo: V3, no: V3, at_boundary: f64) -> f64 {
        let one = self.interpolate(ch, sub(xo, mul(no, self.h)));
        let two = self.interpolate(ch, sub(xo, mul(no, 2.0 * self.h)));
        let slope = match (one, two) {
            (Some(a), Some(b)) => {
                derivative_at_zero([(ch.zb, at_boundary), (-self.h, a), (-2.0 * self.h, b)])
            }
            (Some(a), None) => (at_boundary - a) / (ch.zb + self.h),
            _ => 0.0,
        };
        -ch.d * slope
    }

    /// Trilinear ψ at `x` over the corners that are unknowns (renormalised), `None` if none is.
    fn interpolate(&self, ch: &Channel, x: V3) -> Option<f64> {
        let f = [0, 1, 2].map(|k| (x[k] - self.origin[k]) / self.h);
        let base = f.map(|v| v.floor());
        let t = [0, 1, 2].map(|k| f[k] - base[k]);
        let (mut sum, mut weight) = (0.0, 0.0);
        for corner in 0..8 {
            let mut idx = [0usize; 3];
            let mut w = 1.0;
            for k in 0..3 {
                let up = (corner >> k) & 1 == 1;
                let i = base[k] + up as usize as f64;
                if i < 0.0 || i >= self.dims[k] as f64 {
                    return None;
                }
                idx[k] = i as usize;
                w *= if up { t[k] } else { 1.0 - t[k] };
            }
            let u = ch.index[self.cell(idx)];
            if u != NONE {
                sum += w * ch.psi[u as usize];
                weight += w;
            }
        }
        (weight > 1e-3).then(|| sum / weight)
    }

    fn cell(&self, i: [usize; 3]) -> usize {
        (i[2] * self.dims[1] + i[1]) * self.dims[0] + i[0]
    }
}

/// Jensen et al. 2001's dipole per channel.
fn dipoles(material: &ScatteringMaterial) -> [Dipole; 3] {
    [0, 1, 2].map(|c| Dipole::new(material.sigma_s_prime[c], material.sigma_a[c], material.eta))
}

/// The largest extrapolation distance z_b = 2AD of the material's channels, mm: how far outside
/// the surface the body's boundary lies.
pub(crate) fn extrapolation_mm(material: &ScatteringMaterial) -> f64 {
    pad(&dipoles(material), 0.0)
}

/// The grid's margin around the mesh, and the band its signed distance is needed in: the
/// largest extrapolation distance z_b = 2AD plus two cells.
fn pad(dipoles: &[Dipole; 3], h: f64) -> f64 {
    let zb_max = dipoles
        .iter()
        .map(|d| 0.5 * (d.zv - d.zr))
        .fold(0.0, f64::max);
    zb_max + 2.0 * h
}

/// The mesh's bounding box in mm.
fn bounds_mm(mesh: &Mesh, unit: f64) -> (V3, V3) {
    let (lo, hi) = mesh.bounds();
    (lo.map(|v| v as f64 * unit), hi.map(|v| v as f64 * unit))
}

/// The derivative at 0 of the parabola through three (s, value) points.
fn derivative_at_zero(p: [(f64, f64); 3]) -> f64 {
    (0..3)
        .map(|k| {
            let others: Vec<f64> = (0..3).filter(|&j| j != k).map(|j| p[j].0).collect();
            let denom: f64 = others.iter().map(|s| p[k].0 - s).product();
            // d/ds of (s − a)(s − b) at 0 is −(a + b).
            p[k].1 * -(others[0] + others[1]) / denom
        })
        .sum()
}

/// φ_dip at `x` (mm) in channel `c`: every source's dipole, α′Φ/(4πD)·(e^(−σtr dr)/dr −
/// e^(−σtr dv)/dv), the real source z_r inside along its normal, the virtual one z_v outside.
/// A lumped node whose normals cancel has its dipoles cancel too. With `beam`, each source's
/// beam in place of its dipole.
fn fluence(octree: &Octree, dipoles: &[Dipole; 3], beam: Option<&Beams>, c: usize, x: V3) -> f64 {
    let d = &dipoles[c];
    let diffusion = d.zr / 3.0;
    let scale = d.alpha_prime / (4.0 * PI * diffusion);
    let kernel = |key: usize, p: V3, n: V3, _: f64| {
        let term = |z: f64| {
            let v = sub(x, add(p, mul(n, z)));
            let r = dot(v, v).sqrt().max(1e-9);
            super::expneg::exp_neg(-d.sigma_tr * r) / r
        };
        let mut out = [0.0; 3];
        out[c] = scale
            * match beam {
                Some(beam) => beam.fluence(c, x, key),
                None => term(-d.zr) - term(d.zv),
            };
        out
    };
    octree.gather_keyed(x, 0.0, LUMPING, &kernel).0[c]
}

/// The cell-centred grid.
struct Grid {
    origin: V3,
    h: f64,
    dims: [usize; 3],
}

impl Grid {
    /// Cells of `h` mm over the box `lo`..`hi` (mm) grown by `pad` on every side.
    fn over(lo: V3, hi: V3, h: f64, pad: f64) -> Grid {
        Grid {
            origin: [0, 1, 2].map(|k| lo[k] - pad),
            h,
            dims: [0, 1, 2].map(|k| ((hi[k] - lo[k] + 2.0 * pad) / h).ceil() as usize + 1),
        }
    }

    fn centre(&self, i: [usize; 3]) -> V3 {
        [0, 1, 2].map(|k| self.origin[k] + self.h * i[k] as f64)
    }

    fn cell(&self, i: [usize; 3]) -> usize {
        (i[2] * self.dims[1] + i[1]) * self.dims[0] + i[0]
    }

    fn count(&self) -> usize {
        self.dims.iter().product()
    }

    /// Signed distance (mm, negative inside) to the mesh within `band`; ±∞ beyond it. Inside
    /// is decided by the parity of crossings along x, each row nudged off the grid's planes so
    /// that it meets no edge or vertex exactly.
    fn signed_distance(
        &self,
        tracer: &Tracer,
        mesh: &Mesh,
        unit: f64,
        band: f64,
    ) -> Result<Vec<f64>, NodeError> {
        let torn = open_edges(mesh);
        if torn > 0 {
            return Err(NodeError::input(
                "mesh",
                format!("geometry: body needs a closed mesh: {torn} edges border only one triangle (an open or torn surface has no inside to solve in)"),
            ));
        }
        let [nx, ny, nz] = self.dims;
        let nudge = 1.37e-4 * self.h;
        let rows: Vec<Option<Vec<bool>>> = (0..ny * nz)
            .into_par_iter()
            .map(|row| {
                let (j, k) = (row % ny, row / ny);
                let start = self.centre([0, j, k]);
                let o = [start[0] - self.h, start[1] + nudge, start[2] + 0.7 * nudge];
                let mut crossings = Vec::new();
                let mut from = o.map(|v| v / unit);
                let dir = [1.0, 0.0, 0.0];
                while let Some(hit) = tracer.closest(from, dir) {
                    let x = from[0] + hit.t;
                    crossings.push(x * unit);
                    from = [x + 10.0 * tracer.epsilon, from[1], from[2]];
                }
                if crossings.len() % 2 == 1 {
                    return None;
                }
                let mut inside = vec![false; nx];
                let mut next = 0;
                let mut state = false;
                for (i, v) in inside.iter_mut().enumerate() {
                    let x = self.origin[0] + self.h * i as f64;
                    while next < crossings.len() && crossings[next] < x {
                        state = !state;
                        next += 1;
                    }
                    *v = state;
                }
                Some(inside)
            })
            .collect();
        if rows.iter().any(Option::is_none) {
            return Err(NodeError::input(
                "mesh",
                "geometry: body needs a closed mesh: a line through it crossed its surface an odd number of times",
            ));
        }
        let mut sd: Vec<f64> = rows
            .into_iter()
            .flatten()
            .flatten()
            .map(|inside| {
                if inside {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        // Triangles (mm) bucketed by the z-slabs of cells they come within `band` of; each
        // slab then takes the nearest distance over its bucket.
        let tris: Vec<[V3; 3]> = (0..mesh.triangles())
            .map(|t| {
                mesh.corners(t)
                    .map(|i| mesh.positions[i].map(|v| v as f64 * unit))
            })
            .collect();
        let range = |lo: f64, hi: f64, k: usize| {
            let a = ((lo - band - self.origin[k]) / self.h).ceil().max(0.0) as usize;
            let b = ((hi + band - self.origin[k]) / self.h).floor();
            let b = if b < 0.0 {
                None
            } else {
                Some((b as usize).min(self.dims[k] - 1))
            };
            b.filter(|&b| a <= b).map(|b| (a, b))
        };
        let bounds = |t: &[V3; 3], k: usize| {
            let lo = t.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            let hi = t.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
            (lo, hi)
        };
        let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); nz];
        for (t, tri) in tris.iter().enumerate() {
            let (lo, hi) = bounds(tri, 2);
            if let Some((a, b)) = range(lo, hi, 2) {
                for bucket in &mut buckets[a..=b] {
                    bucket.push(t);
                }
            }
        }
        sd.par_chunks_mut(nx * ny)
            .zip(buckets.par_iter())
            .enumerate()
            .for_each(|(k, (slab, bucket))| {
                let mut nearest = vec![f64::INFINITY; nx * ny];
                for &t in bucket {
                    let tri = &tris[t];
                    let (Some((x0, x1)), Some((y0, y1))) = (
                        range(bounds(tri, 0).0, bounds(tri, 0).1, 0),
                        range(bounds(tri, 1).0, bounds(tri, 1).1, 1),
                    ) else {
                        continue;
                    };
                    for j in y0..=y1 {
                        for i in x0..=x1 {
                            let p = self.centre([i, j, k]);
                            let d = point_triangle(p, tri);
                            let e = &mut nearest[j * nx + i];
                            if d < *e {
                                *e = d;
                            }
                        }
                    }
                }
                for (s, d) in slab.iter_mut().zip(nearest) {
                    if d <= band {
                        *s = if *s < 0.0 { -d } else { d };
                    }
                }
            });
        Ok(sd)
    }

    /// ψ for one channel: unknowns where the signed distance is under z_b; the boundary's
    /// value from `boundary(x)` where an unknown's neighbour lies beyond. Returns the channel,
    /// the iterations and whether the tolerance was met.
    fn solve(
        &self,
        sd: &[f64],
        dipole: &Dipole,
        sigma_a: f64,
        boundary: impl Fn(V3) -> f64 + Sync,
    ) -> (Channel, usize, bool) {
        let d = dipole.zr / 3.0;
        let zb = 0.5 * (dipole.zv - dipole.zr);
        let mut index = vec![NONE; self.count()];
        let mut cells = Vec::new();
        for (i, &s) in sd.iter().enumerate() {
            if s < zb {
                index[i] = cells.len() as u32;
                cells.push(i);
            }
        }
        let [nx, ny, _] = self.dims;
        let coupling = d / (self.h * self.h);
        // Per unknown: its six neighbours (unknown numbers or NONE), diagonal and right side.
        let rows: Vec<([u32; 6], f64, f64)> = cells
            .par_iter()
            .map(|&cell| {
                let i = [cell % nx, (cell / nx) % ny, cell / (nx * ny)];
                let mut neighbours = [NONE; 6];
                let mut diagonal = sigma_a;
                let mut rhs = 0.0;
                for (slot, (axis, step)) in [(0, -1i64), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)]
                    .into_iter()
                    .enumerate()
                {
                    let mut j = i;
                    let moved = i[axis] as i64 + step;
                    // The padding keeps every unknown off the grid's faces.
                    if moved < 0 || moved >= self.dims[axis] as i64 {
                        continue;
                    }
                    j[axis] = moved as usize;
                    let other = self.cell(j);
                    if index[other] != NONE {
                        neighbours[slot] = index[other];
                        diagonal += coupling;
                    } else {
                        let (si, sn) = (sd[cell], sd[other]);
                        let theta = if si.is_finite() && sn.is_finite() && sn > si {
                            ((zb - si) / (sn - si)).clamp(THETA_MIN, 1.0)
                        } else {
                            1.0
                        };
                        let mut at = self.centre(i);
                        at[axis] += step as f64 * theta * self.h;
                        diagonal += coupling / theta;
                        rhs += coupling / theta * boundary(at);
                    }
                }
                (neighbours, diagonal, rhs)
            })
            .collect();
        let apply = |x: &[f64], out: &mut [f64]| {
            out.par_iter_mut().enumerate().for_each(|(u, o)| {
                let (nb, diag, _) = &rows[u];
                let mut v = diag * x[u];
                for &n in nb {
                    if n != NONE {
                        v -= coupling * x[n as usize];
                    }
                }
                *o = v;
            });
        };
        let n = cells.len();
        let b: Vec<f64> = rows.iter().map(|r| r.2).collect();
        let inverse: Vec<f64> = rows.iter().map(|r| 1.0 / r.1).collect();
        let mut x = vec![0.0; n];
        let mut r = b.clone();
        let mut z: Vec<f64> = r.iter().zip(&inverse).map(|(r, m)| r * m).collect();
        let mut p = z.clone();
        let mut ap = vec![0.0; n];
        let mut rz = dot_fixed(&r, &z);
        let target = TOLERANCE * dot_fixed(&b, &b).sqrt();
        let mut iterations = 0;
        let mut converged = dot_fixed(&r, &r).sqrt() <= target;
        while !converged && iterations < MAX_ITERATIONS {
            apply(&p, &mut ap);
            let alpha = rz / dot_fixed(&p, &ap);
            x.par_iter_mut().zip(&p).for_each(|(x, p)| *x += alpha * p);
            r.par_iter_mut().zip(&ap).for_each(|(r, a)| *r -= alpha * a);
            z.par_iter_mut()
                .zip(&r)
                .zip(&inverse)
                .for_each(|((z, r), m)| *z = r * m);
            let next = dot_fixed(&r, &z);
            let beta = next / rz;
            rz = next;
            p.par_iter_mut()
                .zip(&z)
                .for_each(|(p, z)| *p = z + beta * *p);
            iterations += 1;
            converged = dot_fixed(&r, &r).sqrt() <= target;
        }
        (
            Channel {
                index,
                psi: x,
                d,
                zb,
            },
            iterations,
            converged,
        )
    }
}

/// Edges with an odd number of triangles on them, corners welded by position
/// ([`Mesh::position_twins`]: a UV seam repeats its vertices).
pub(crate) fn open_edges(mesh: &Mesh) -> usize {
    use std::collections::HashMap;
    let id = mesh.position_twins();
    let mut edges: HashMap<(usize, usize), u32> = HashMap::new();
    for t in 0..mesh.triangles() {
        let c = mesh.corners(t).map(|i| id[i]);
        for (a, b) in [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])] {
            if a != b {
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
    }
    edges.values().filter(|&&n| n % 2 == 1).count()
}

/// Σ aᵢbᵢ in fixed chunks summed in order: the same bits whatever the thread count.
fn dot_fixed(a: &[f64], b: &[f64]) -> f64 {
    const CHUNK: usize = 4096;
    let partial: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(a, b)| a.iter().zip(b).map(|(a, b)| a * b).sum())
        .collect();
    partial.iter().sum()
}

/// Distance from `p` to the triangle (Ericson, Real-Time Collision Detection §5.1.5: the
/// closest point by the region of the triangle's plane `p` projects into).
fn point_triangle(p: V3, t: &[V3; 3]) -> f64 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    let closest = if d1 <= 0.0 && d2 <= 0.0 {
        a
    } else {
        let bp = sub(p, b);
        let (d3, d4) = (dot(ab, bp), dot(ac, bp));
        let cp = sub(p, c);
        let (d5, d6) = (dot(ab, cp), dot(ac, cp));
        let vc = d1 * d4 - d3 * d2;
        let vb = d5 * d2 - d1 * d6;
        let va = d3 * d6 - d5 * d4;
        if d3 >= 0.0 && d4 <= d3 {
            b
        } else if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
            add(a, mul(ab, d1 / (d1 - d3)))
        } else if d6 >= 0.0 && d5 <= d6 {
            c
        } else if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
            add(a, mul(ac, d2 / (d2 - d6)))
        } else if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
            add(b, mul(sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))))
        } else {
            let denom = 1.0 / (va + vb + vc);
            add(a, add(mul(ab, vb * denom), mul(ac, vc * denom)))
        }
    };
    let v = sub(p, closest);
    dot(v, v).sqrt()
}

#[cfg(test)]
mod tests;
