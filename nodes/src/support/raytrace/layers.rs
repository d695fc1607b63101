//! Visibility layers by depth peeling, computed by ray casting (the CPU path; the GPU path
//! rasterises the same layers). Along a pixel's ray through a closed mesh, front and back faces
//! alternate; layer k is the k-th front face after the previous layer's back face and the first
//! back face after it. Each is stored as a visibility sample: distance along the ray, triangle,
//! and the barycentric weights of the triangle's corners 1 and 2.

use super::camera::Camera;
use crate::support::geometry::{cross, dot, sub, V3};
use crate::support::progress::Counter;
use crate::types::Mesh;
use rayon::prelude::*;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frag {
    pub t: f64,
    pub tri: u32,
    pub b1: f64,
    pub b2: f64,
}

/// `front[(k · H + y) · W + x]` and the same for `back`; `None` where the layer is empty.
pub struct Layers {
    pub count: usize,
    pub width: usize,
    pub height: usize,
    pub front: Vec<Option<Frag>>,
    pub back: Vec<Option<Frag>>,
}

/// The peel threshold: a fragment belongs to a later layer only beyond this distance past the
/// previous one, so coincident hits on shared edges (the same surface twice) are not a layer.
pub fn beyond(t: f64, previous: f64) -> bool {
    t > previous + 1e-5 * previous.abs().max(1.0)
}

/// Möller–Trumbore; (t, b1, b2, front-facing) for t > 0.
#[inline]
pub fn intersect(o: V3, d: V3, p0: V3, p1: V3, p2: V3) -> Option<(f64, f64, f64, bool)> {
    let (e1, e2) = (sub(p1, p0), sub(p2, p0));
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    // |det| ≤ 10⁻¹² |e1| |e2|, squared: no square roots on the tracer's hot path.
    let scale2 = dot(e1, e1) * dot(e2, e2);
    if det * det <= 1e-24 * scale2 || scale2 == 0.0 {
        return None; // parallel to the ray or degenerate
    }
    let inv = 1.0 / det;
    let s = sub(o, p0);
    let b1 = dot(s, pv) * inv;
    if !(0.0..=1.0).contains(&b1) {
        return None;
    }
    let q = cross(s, e1);
    let b2 = dot(d, q) * inv;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return None;
    }
    let t = dot(e2, q) * inv;
    (t > 0.0).then_some((t, b1, b2, det > 0.0))
}

const TILE: u32 = 16;

/// A pixel's index and its layers (front, back).
type PixelLayers = (usize, Vec<(Option<Frag>, Option<Frag>)>);

/// A mesh's triangles binned by the screen tiles of a camera their projection covers, so that
/// one pixel's layers cost the triangles of its tile ([`Binned::pixel`]): [`trace`] peels every
/// pixel, a lazy shadow map only the texels a frame asks for.
pub struct Binned<'a> {
    mesh: &'a Mesh,
    cam: &'a Camera,
    tiles_x: u32,
    bins: Vec<Vec<u32>>,
    /// Each triangle's screen box widened by a pixel.
    boxes: Vec<[f64; 4]>,
}

impl<'a> Binned<'a> {
    pub fn new(mesh: &'a Mesh, cam: &'a Camera) -> Binned<'a> {
        let (w, h) = (cam.width, cam.height);
        let (tiles_x, tiles_y) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let pos = |i: usize| mesh.positions[i].map(|v| v as f64);
        // Bin triangles by the screen tiles their projection covers; a corner behind a pinhole
        // puts the triangle in every tile (rare, and correct, just slower).
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); (tiles_x * tiles_y) as usize];
        // Each triangle's screen box widened by a pixel, so that a pixel whose centre lies
        // outside it skips the triangle: a far object lands whole in one tile, and without this
        // every pixel of that tile would test every triangle.
        let mut boxes: Vec<[f64; 4]> = Vec::with_capacity(mesh.triangles());
        for t in 0..mesh.triangles() {
            let c = mesh.corners(t);
            let proj: Option<Vec<(f64, f64, f64)>> =
                c.iter().map(|&i| cam.project(pos(i))).collect();
            let (x0, x1, y0, y1) = match proj {
                Some(p) => {
                    let xs = p.iter().map(|q| q.0);
                    let ys = p.iter().map(|q| q.1);
                    (
                        xs.clone().fold(f64::INFINITY, f64::min),
                        xs.fold(f64::NEG_INFINITY, f64::max),
                        ys.clone().fold(f64::INFINITY, f64::min),
                        ys.fold(f64::NEG_INFINITY, f64::max),
                    )
                }
                None => (
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                ),
            };
            boxes.push([x0 - 1.0, x1 + 1.0, y0 - 1.0, y1 + 1.0]);
            if x1 < -1.0 || y1 < -1.0 || x0 > w as f64 + 1.0 || y0 > h as f64 + 1.0 {
                continue;
            }
            let tx = |x: f64| ((x.max(0.0) as u32) / TILE).min(tiles_x - 1);
            let ty = |y: f64| ((y.max(0.0) as u32) / TILE).min(tiles_y - 1);
            for j in ty(y0 - 1.0)..=ty(y1 + 1.0) {
                for i in tx(x0 - 1.0)..=tx(x1 + 1.0) {
                    bins[(j * tiles_x + i) as usize].push(t as u32);
                }
            }
        }
        Binned {
            mesh,
            cam,
            tiles_x,
            bins,
            boxes,
        }
    }

    /// The camera the triangles are binned for.
    pub fn camera(&self) -> &'a Camera {
        self.cam
    }

    /// The layers of every pixel of screen tile (bx, by), appended to `out`: the same as
    /// [`Binned::pixel`] for each, found triangle by triangle (each tested against the
    /// pixels its widened box holds, by the same test) and sorted per pixel by (t, triangle),
    /// which orders any pixel's hits exactly as the pixel's own loop does.
    pub fn tile(&self, bx: u32, by: u32, count: usize, out: &mut Vec<PixelLayers>) {
        let (w, h) = (self.cam.width, self.cam.height);
        let (x_end, y_end) = (((bx + 1) * TILE).min(w), ((by + 1) * TILE).min(h));
        let (x0, y0) = (bx * TILE, by * TILE);
        let tw = (x_end - x0) as usize;
        let rays: Vec<_> = (y0..y_end)
            .flat_map(|y| (x0..x_end).map(move |x| (x, y)))
            .map(|(x, y)| self.cam.ray(x, y))
            .collect();
        let pos = |i: usize| self.mesh.positions[i].map(|v| v as f64);
        // (pixel in the tile, hit, front-facing)
        let mut hits: Vec<(u32, Frag, bool)> = Vec::new();
        for &tri in &self.bins[(by * self.tiles_x + bx) as usize] {
            let [bx0, bx1, by0, by1] = self.boxes[tri as usize];
            // The pixels whose centre the box may hold (a pixel either side for rounding);
            // the test itself is the per-pixel loop's.
            let lo = |v: f64, start: u32| (v - 1.5).max(start as f64) as u32;
            let hi = |v: f64, end: u32| ((v + 0.5).max(0.0) as u32).min(end - 1);
            let [a, b, c] = self.mesh.corners(tri as usize);
            let (pa, pb, pc) = (pos(a), pos(b), pos(c));
            for y in lo(by0, y0)..=hi(by1, y_end) {
                let cy = y as f64 + 0.5;
                if !(by0..=by1).contains(&cy) {
                    continue;
                }
                for x in lo(bx0, x0)..=hi(bx1, x_end) {
                    let cx = x as f64 + 0.5;
                    if !(bx0..=bx1).contains(&cx) {
                        continue;
                    }
                    let i = (y - y0) as usize * tw + (x - x0) as usize;
                    let (o, d) = rays[i];
                    if let Some((t, b1, b2, front)) = intersect(o, d, pa, pb, pc) {
                        hits.push((i as u32, Frag { t, tri, b1, b2 }, front));
                    }
                }
            }
        }
        hits.sort_by(|p, q| {
            p.0.cmp(&q.0)
                .then(p.1.t.total_cmp(&q.1.t))
                .then(p.1.tri.cmp(&q.1.tri))
        });
        let mut group: Vec<(Frag, bool)> = Vec::new();
        let mut k = 0;
        for i in 0..rays.len() {
            group.clear();
            while k < hits.len() && hits[k].0 as usize == i {
                group.push((hits[k].1, hits[k].2));
                k += 1;
            }
            let (x, y) = (x0 + (i % tw) as u32, y0 + (i / tw) as u32);
            out.push(((y * w + x) as usize, peel(&group, count)));
        }
    }

    /// Pixel (x, y)'s first `count` layers alone, as a one-pixel [`Layers`] (index 0): peeled
    /// from the hits of its tile's triangles whose widened box holds the pixel's centre.
    pub fn pixel(&self, x: u32, y: u32, count: usize) -> Layers {
        let tris = &self.bins[((y / TILE) * self.tiles_x + x / TILE) as usize];
        let pos = |i: usize| self.mesh.positions[i].map(|v| v as f64);
        let (o, d) = self.cam.ray(x, y);
        let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
        let mut hits: Vec<(Frag, bool)> = tris
            .iter()
            .filter(|&&tri| {
                let [x0, x1, y0, y1] = self.boxes[tri as usize];
                (x0..=x1).contains(&cx) && (y0..=y1).contains(&cy)
            })
            .filter_map(|&tri| {
                let [a, b, c] = self.mesh.corners(tri as usize);
                intersect(o, d, pos(a), pos(b), pos(c))
                    .map(|(t, b1, b2, front)| (Frag { t, tri, b1, b2 }, front))
            })
            .collect();
        hits.sort_by(|p, q| p.0.t.total_cmp(&q.0.t).then(p.0.tri.cmp(&q.0.tri)));
        let (front, back) = peel(&hits, count).into_iter().unzip();
        Layers {
            count,
            width: 1,
            height: 1,
            front,
            back,
        }
    }
}

/// The layers of every pixel; screen tiles are counted on `watch`, and once it is stopped the
/// remaining tiles are left empty (the caller returns `Cancelled`).
pub fn trace(mesh: &Mesh, cam: &Camera, count: usize, watch: &Counter) -> Layers {
    let (w, h) = (cam.width, cam.height);
    let binned = Binned::new(mesh, cam);
    let tiles_x = binned.tiles_x;
    let plane = (w * h) as usize;
    watch.grow(binned.bins.len() as u64);
    let per_tile: Vec<Vec<PixelLayers>> = (0..binned.bins.len())
        .into_par_iter()
        .map(|b| {
            let (bx, by) = (b as u32 % tiles_x, b as u32 / tiles_x);
            let mut out = Vec::new();
            watch.add(1);
            // A tile no triangle covers has no layers: its pixels stay empty, untraced.
            if watch.stopped() || binned.bins[b].is_empty() {
                return out;
            }
            binned.tile(bx, by, count, &mut out);
            out
        })
        .collect();
    let mut layers = Layers {
        count,
        width: w as usize,
        height: h as usize,
        front: vec![None; plane * count],
        back: vec![None; plane * count],
    };
    for (px, ls) in per_tile.into_iter().flatten() {
        for (k, (f, b)) in ls.into_iter().enumerate() {
            layers.front[k * plane + px] = f;
            layers.back[k * plane + px] = b;
        }
    }
    layers
}

/// Layers from a pixel's hits sorted by distance.
fn peel(hits: &[(Frag, bool)], count: usize) -> Vec<(Option<Frag>, Option<Frag>)> {
    let mut out = Vec::with_capacity(count);
    let mut last = f64::NEG_INFINITY;
    for _ in 0..count {
        let front = hits
            .iter()
            .find(|(f, is_front)| *is_front && (last == f64::NEG_INFINITY || beyond(f.t, last)))
            .map(|h| h.0);
        let Some(f) = front else {
            out.push((None, None));
            continue;
        };
        let back = hits
            .iter()
            .find(|(b, is_front)| !*is_front && beyond(b.t, f.t))
            .map(|h| h.0);
        last = back.map_or(f64::INFINITY, |b| b.t);
        out.push((Some(f), back));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{build, Params, Shape};
    use crate::support::raytrace::camera::CameraParams;

    #[test]
    fn a_sphere_has_one_layer_whose_depths_are_the_chord() {
        // Closed form: a ray at distance ρ from the centre of a unit sphere meets it at
        // t = D·cos ∓ sqrt(1 − ρ²); the tessellation is within (1 − cos(π/64)) ≈ 1.2e-3 of it.
        let mesh = build(&Params {
            shape: Shape::Sphere,
            size: 1.0,
            segments: [128, 64],
            ..Default::default()
        })
        .unwrap();
        let cam = Camera::new(&CameraParams {
            eye: [0.0, 0.0, 4.0],
            orthographic: Some(1.2),
            resolution: [24, 24],
            ..Default::default()
        })
        .unwrap();
        let l = trace(&mesh, &cam, 2, &Counter::none());
        let plane = 24 * 24;
        for y in 0..24u32 {
            for x in 0..24u32 {
                let (o, _) = cam.ray(x, y);
                let rho2 = o[0] * o[0] + o[1] * o[1];
                let i = (y * 24 + x) as usize;
                assert!(l.front[plane + i].is_none(), "a convex mesh has one layer");
                if rho2 < 0.95 {
                    let half = (1.0 - rho2).sqrt();
                    let (f, b) = (l.front[i].unwrap(), l.back[i].unwrap());
                    assert!(
                        (f.t - (4.0 - half)).abs() < 3e-3,
                        "{} vs {}",
                        f.t,
                        4.0 - half
                    );
                    assert!((b.t - (4.0 + half)).abs() < 3e-3);
                } else if rho2 > 1.0 {
                    assert!(l.front[i].is_none());
                }
            }
        }
    }

    #[test]
    fn a_tile_traced_triangle_by_triangle_is_each_pixel_traced_alone() {
        // `trace` finds a tile's hits triangle by triangle; `Binned::pixel` pixel by pixel
        // (the lazy shadow map's way): the same layers, bit for bit, on a pinhole view of a
        // torus whose triangles straddle tiles and the image's edge.
        let mesh = build(&Params {
            shape: Shape::Torus,
            size: 1.0,
            minor: 0.4,
            segments: [40, 20],
        })
        .unwrap();
        let cam = Camera::new(&CameraParams {
            eye: [0.3, 1.4, 2.2],
            resolution: [83, 61],
            ..Default::default()
        })
        .unwrap();
        let l = trace(&mesh, &cam, 3, &Counter::none());
        let binned = Binned::new(&mesh, &cam);
        let plane = 83 * 61;
        let mut hit = 0;
        for y in 0..61u32 {
            for x in 0..83u32 {
                let one = binned.pixel(x, y, 3);
                let i = (y * 83 + x) as usize;
                for k in 0..3 {
                    assert_eq!(l.front[k * plane + i], one.front[k], "({x}, {y}) layer {k}");
                    assert_eq!(l.back[k * plane + i], one.back[k], "({x}, {y}) layer {k}");
                }
                hit += one.front[0].is_some() as usize;
            }
        }
        assert!(hit > plane / 4, "{hit}");
    }

    #[test]
    fn a_torus_seen_edge_on_has_two_layers() {
        let mesh = build(&Params {
            shape: Shape::Torus,
            size: 1.0,
            minor: 0.3,
            segments: [64, 32],
        })
        .unwrap();
        let cam = Camera::new(&CameraParams {
            eye: [0.0, 0.0, 5.0],
            orthographic: Some(1.5),
            resolution: [31, 31],
            ..Default::default()
        })
        .unwrap();
        let l = trace(&mesh, &cam, 3, &Counter::none());
        // The ring (axis y, radii 1 ± 0.3) seen along z: the ray through (x, 0) crosses the tube
        // on the near and the far side while |x| < 0.7 (two layers), once for |x| ∈ (0.7, 1.3)
        // (one layer), not at all beyond. Pixel 15 is x = 0, pixel 25 is x ≈ 0.97.
        let plane = 31 * 31;
        let row = 15 * 31;
        assert!(l.front[row + 15].is_some() && l.front[plane + row + 15].is_some());
        assert!(l.front[2 * plane + row + 15].is_none());
        assert!(l.front[row + 25].is_some() && l.front[plane + row + 25].is_none());
        assert!(l.front[row + 30].is_none());
    }
}
