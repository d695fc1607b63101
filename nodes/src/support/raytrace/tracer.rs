//! Tracing rays against a triangle mesh: a compressed wide BVH (the `obvhs` crate) to find
//! candidates, intersected in f64 with the mesh's own triangles, so which hit counts is decided
//! exactly. `render.reference`'s exact shadows and volumetric paths and `sss.render`'s body
//! geometry, bounces and single scattering all trace through it.
//!
//! The last BVH of a large mesh (at least [`KEEP_FROM`] triangles) is kept for the next tracer
//! of the same triangles (by their hash), so a second frame of one surface in a process (a
//! camera move in the studio, a sweep's frames, the planner's probes) does not build it again.
//! The build is deterministic, so the kept BVH is the one a new build would make: same bits.
//! A tracer made [`Tracer::in_context`] also keeps it in the run's disk cache for the next
//! process (`bvh_store`).

use super::bvh_store;
use crate::support::geometry::{add, cross, mul, normalize, sub, V3};
use crate::types::Mesh;
use mesoflow_runtime::NodeContext;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use std::sync::{Arc, Mutex};

/// Meshes with at least this many triangles keep their BVH for the next tracer (a build of
/// fewer costs milliseconds; one of the planner's displaced surfaces, millions of triangles,
/// seconds).
pub const KEEP_FROM: usize = 100_000;

/// A BVH with its triangles' corners in its own leaf order ([`Slots`]).
type Kept = (Arc<CwBvh>, Arc<Slots>);

/// The last kept BVH: its mesh's hash and the BVH (one entry, so at most one BVH a process
/// outlives its render).
static KEPT: Mutex<Option<([u8; 32], Kept)>> = Mutex::new(None);

/// Each BVH primitive slot's triangle corners (9 × f32, the mesh's own values), in the BVH's
/// order: a leaf's triangles are read from one place instead of through the primitive index,
/// the mesh's indices and three scattered positions (the intersection's cache misses were
/// a fifth of `render.reference`'s frame).
pub struct Slots(Vec<[f32; 9]>);

impl Slots {
    fn new(mesh: &Mesh, bvh: &CwBvh) -> Slots {
        Slots(
            bvh.primitive_indices
                .iter()
                .map(|&t| {
                    let [a, b, c] = mesh.corners(t as usize).map(|i| mesh.positions[i]);
                    [a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]]
                })
                .collect(),
        )
    }
}

/// Forgets the kept BVH, as a new process starts without one (tests).
#[cfg(test)]
pub(crate) fn forget_kept() {
    if let Ok(mut k) = KEPT.lock() {
        *k = None;
    }
}

/// The hash of what the BVH is built from: the positions and the indices.
fn mesh_hash(mesh: &Mesh) -> [u8; 32] {
    let mut h = blake3::Hasher::new();
    h.update(bytemuck::cast_slice(&mesh.positions));
    h.update(bytemuck::cast_slice(&mesh.indices));
    *h.finalize().as_bytes()
}

pub struct Hit {
    pub tri: usize,
    /// The BVH slot the triangle is stored in: a hint for a neighbouring ray
    /// ([`Tracer::closest_near`]).
    pub slot: usize,
    pub t: f64,
    pub b1: f64,
    pub b2: f64,
}

/// How far behind its origin a ray enters the BVH (world units). obvhs culls every box the ray
/// leaves within 10⁻⁴ (an absolute `EPSILON` in its node test), so without it a surface closer
/// than that to the origin is missed: 3% of the shadow rays from inside a dense medium. Which
/// hits count is decided in f64 from the true origin (`intersect`: t > 0).
const BACK_OFF: f64 = 1e-3;

/// Where a tracer's BVH came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BvhFrom {
    /// Built for this tracer.
    Built,
    /// Kept from this process's last tracer of the same triangles.
    Kept,
    /// Read from the run's disk cache, where an earlier process stored it.
    Stored,
}

/// The mesh and its BVH.
pub struct Tracer<'a> {
    pub mesh: &'a Mesh,
    bvh: Arc<CwBvh>,
    slots: Arc<Slots>,
    /// Where the BVH came from.
    pub from: BvhFrom,
    /// Shadow-ray offset along the geometric normal: a millionth of the scene's size.
    pub epsilon: f64,
}

impl<'a> Tracer<'a> {
    /// The tracer of `mesh`, its BVH built here or kept from this process's last large mesh.
    pub fn new(mesh: &'a Mesh) -> Self {
        Self::with_bvh(mesh, None)
    }

    /// The same, where with the run's `ctx` a large mesh's BVH is also looked for in, and kept
    /// in, the run's disk cache ([`bvh_store`](super::bvh_store)), for the next process that
    /// renders it.
    pub fn in_context(mesh: &'a Mesh, ctx: Option<&NodeContext>) -> Self {
        Self::with_bvh(mesh, ctx)
    }

    fn with_bvh(mesh: &'a Mesh, ctx: Option<&NodeContext>) -> Self {
        let with_slots = |bvh: CwBvh| -> Kept {
            let slots = Slots::new(mesh, &bvh);
            (Arc::new(bvh), Arc::new(slots))
        };
        let ((bvh, slots), from) = if mesh.triangles() >= KEEP_FROM {
            let key = mesh_hash(mesh);
            let kept = KEPT.lock().ok().and_then(|k| {
                k.as_ref()
                    .filter(|(h, _)| *h == key)
                    .map(|(_, b)| b.clone())
            });
            match kept {
                Some(kept) => (kept, BvhFrom::Kept),
                None => {
                    let (bvh, from) = Self::stored_or_built(mesh, &key, ctx);
                    let kept = with_slots(bvh);
                    if let Ok(mut k) = KEPT.lock() {
                        *k = Some((key, kept.clone()));
                    }
                    (kept, from)
                }
            }
        } else {
            (with_slots(bvh_store::build(mesh)), BvhFrom::Built)
        };
        let (lo, hi) = mesh.bounds();
        let size = (0..3).map(|k| (hi[k] - lo[k]) as f64).fold(0.0, f64::max);
        Tracer {
            mesh,
            bvh,
            slots,
            from,
            epsilon: 1e-6 * size.max(1e-30),
        }
    }

    /// The BVH of the mesh of hash `hash` from the run's disk cache, else built (and stored).
    fn stored_or_built(
        mesh: &Mesh,
        hash: &[u8; 32],
        ctx: Option<&NodeContext>,
    ) -> (CwBvh, BvhFrom) {
        let Some(ctx) = ctx else {
            return (bvh_store::build(mesh), BvhFrom::Built);
        };
        let key = bvh_store::key(hash);
        let stored = ctx
            .load_derived(bvh_store::KIND, &key)
            .and_then(|bytes| bvh_store::decode(&bytes, mesh.triangles()));
        if let Some(bvh) = stored {
            return (bvh, BvhFrom::Stored);
        }
        let start = std::time::Instant::now();
        let built = bvh_store::build(mesh);
        if let Some(bytes) = bvh_store::encode(&built) {
            let seconds = start.elapsed().as_secs_f64();
            ctx.store_derived(bvh_store::KIND, &key, &bytes, seconds);
        }
        (built, BvhFrom::Built)
    }

    /// Triangle `t`'s corners' positions' plane: a point and the unit geometric normal (the
    /// winding's).
    pub fn triangle(&self, t: usize) -> (V3, V3) {
        let [a, b, c] = self
            .mesh
            .corners(t)
            .map(|i| self.mesh.positions[i].map(|x| x as f64));
        (
            a,
            normalize(cross(sub(b, a), sub(c, a))).unwrap_or([0.0, 0.0, 1.0]),
        )
    }

    /// Möller–Trumbore in f64 (the CPU ray caster's, `layers::intersect`) against BVH slot
    /// `id`'s triangle: distance and barycentrics (of corners 1 and 2).
    #[inline(always)]
    fn intersect(&self, id: usize, o: V3, d: V3) -> Option<(f64, f64, f64)> {
        let v = self.slots.0[id].map(|x| x as f64);
        let (p0, p1, p2) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]);
        super::layers::intersect(o, d, p0, p1, p2).map(|(t, b1, b2, _)| (t, b1, b2))
    }

    /// The BVH's ray: started [`BACK_OFF`] behind `o`, so that the traversal's t is the
    /// distance from `o` plus `BACK_OFF`.
    fn ray(o: V3, d: V3, tmax: f64) -> Ray {
        let f = |v: V3| glam::Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32);
        let back = add(o, mul(d, -BACK_OFF));
        Ray::new(
            f(back),
            f(d),
            0.0,
            (tmax + BACK_OFF).min(f32::MAX as f64) as f32,
        )
    }

    /// The nearest hit along the ray from `o` in unit direction `d`. Ties go to the lower
    /// triangle index, so the answer does not depend on the traversal order.
    pub fn closest(&self, o: V3, d: V3) -> Option<Hit> {
        self.closest_near(o, d, None)
    }

    /// [`closest`](Self::closest), trying first the BVH slot `hint` (where a neighbouring
    /// ray hit, [`Hit::slot`]): its distance prunes the traversal from the start, and the
    /// answer is the same (the true nearest is never beyond it, and ties are settled by index
    /// as without a hint).
    pub fn closest_near(&self, o: V3, d: V3, hint: Option<usize>) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut ray = Self::ray(o, d, f64::INFINITY);
        if let Some(id) = hint.filter(|&id| id < self.slots.0.len()) {
            let end = self.consider(id, o, d, &mut best);
            if end < ray.tmax {
                ray.tmax = end;
            }
        }
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |_, id| self.consider(id, o, d, &mut best));
        best
    }

    /// BVH slot `id`'s triangle against the ray from `o` along `d`: kept in `best` where
    /// nearer (ties to the lower triangle index); the traversal's new end, or infinity.
    #[inline(always)]
    fn consider(&self, id: usize, o: V3, d: V3, best: &mut Option<Hit>) -> f32 {
        let Some((dist, b1, b2)) = self.intersect(id, o, d) else {
            return f32::INFINITY;
        };
        let t = self.bvh.primitive_indices[id] as usize;
        let better = best
            .as_ref()
            .is_none_or(|h| dist < h.t || (dist == h.t && t < h.tri));
        if better {
            *best = Some(Hit {
                tri: t,
                slot: id,
                t: dist,
                b1,
                b2,
            });
        }
        // Widened a little so that an f32 rounding never prunes an equal-distance tie.
        ((dist + BACK_OFF) * (1.0 + 1e-6)) as f32
    }

    /// Whether anything lies along the ray from `o` in direction `d` closer than `reach`.
    pub fn occluded(&self, o: V3, d: V3, reach: f64) -> bool {
        !self.bvh.ray_traverse_miss(Self::ray(o, d, reach), |_, id| {
            match self.intersect(id, o, d) {
                // Any value below the ray's end is a hit: the f64 test has decided.
                Some((dist, ..)) if dist < reach => 0.0,
                _ => f32::INFINITY,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tracer_in_a_run_with_a_disk_cache_stores_its_bvh_and_the_next_reads_it() {
        // 131 072 triangles: above `tracer::KEEP_FROM`, and no other test's mesh.
        let mesh = crate::mesh::primitive::build(&crate::mesh::primitive::Params {
            shape: crate::mesh::primitive::Shape::Sphere,
            size: 1.0,
            minor: 0.0,
            segments: [256, 257],
        })
        .expect("a sphere");
        assert!(mesh.triangles() >= KEEP_FROM);
        let dir = tempfile::tempdir().unwrap();
        let cache = mesoflow_runtime::cache::DiskCache::new(dir.path());
        let ctx = mesoflow_runtime::NodeContext::detached(None).with_derived(cache.clone());
        let first = Tracer::in_context(&mesh, Some(&ctx));
        assert_ne!(first.from, BvhFrom::Stored);
        assert_eq!(cache.stats().by_kind[bvh_store::KIND].entries, 1);
        // This process keeps it too: forget that, as a new process would not have it.
        forget_kept();
        let second = Tracer::in_context(&mesh, Some(&ctx));
        assert_eq!(second.from, BvhFrom::Stored);
        for (o, d) in [
            ([0.0, 0.0, 3.0], [0.0, 0.0, -1.0]),
            ([0.3, 2.0, 0.1], [0.0, -1.0, 0.0]),
        ] {
            let (a, b) = (first.closest(o, d).unwrap(), second.closest(o, d).unwrap());
            assert_eq!((a.tri, a.t.to_bits()), (b.tri, b.t.to_bits()));
        }
    }
}
