//! Resolving visibility layers into pixels: the MDF shell test and shading (CPU path; the GPU
//! resolve shader follows it). The mesh is the top of a shell of world thickness `shell`
//! extruded inwards. Along a pixel's ray, layer k's front face (distance t_f, MDF distance d_f
//! for the local view) and back face (t_b, d_b for the ray leaving through it) bound one pass
//! through the shell; the ray meets mesostructure in it when t_f + d_f < t_b − d_b (thesis
//! ch. 4; an open mesh has t_b = ∞). Otherwise the next layer is tried; a ray that passes all
//! of them shows the background, which is what carves the silhouette. At an open mesh's
//! boundary the shell has a side: the band under each boundary edge (an edge of one triangle
//! only, welded by position), from the edge down `shell` along its vertices' normals. A layer
//! without a back face is bounded by where its ray leaves through a side wall, so a ray that
//! would reach the mesostructure only beyond the mesh's edge misses.
//!
//! MDF distances are in MDF texels; one texel of depth is `shell / mdf.depth` world units. A hit
//! is shaded, as in the thesis, at (x, t_f + d_f): with the BTF at the entry texel x, whose
//! measured images already contain the parallax and masking the MDF describes (displacing the
//! lookup as well would apply that parallax twice), in the front face's tangent frame. With
//! `parallax` on, the lookup moves to the hit's own texel, d·(−ω_o.x, −ω_o.y) texels away in
//! texture space: right for a BTF rectified to the mesostructure (no parallax of its own). Light
//! is the irradiance times the shadow map's visibility. The shadow map holds the displaced depth
//! of the casters (the first mesostructure hit along each light ray), and is tested at the
//! receiver's reference surface point (x, t_f): a caster shadows it only if it lies in front of
//! the receiver's shell, so shadows between parts of the mesh and from silhouette mesostructure
//! appear, while the self-shadowing inside a tile, already in the BTF, is not applied twice.
use super::camera::Camera;
use super::layers::{Frag, Layers};
use super::light::Light;
use super::material::{Material, MdfLookup};
use crate::geometry::{add, cross, dot, mul, normalize, sub, V3};
use crate::types::Mesh;
use rayon::prelude::*;

/// A shadow map: distance along the light camera's ray to the displaced surface per texel.
pub struct ShadowMap {
    pub camera: Camera,
    pub depth: Vec<f64>,
    /// Depth bias, world units (two texels' footprint at the scene).
    pub bias: f64,
}

pub struct Scene<'a> {
    pub mesh: &'a Mesh,
    pub material: &'a Material<'a>,
    pub mdf: Option<MdfLookup<'a>>,
    pub light: Light,
    /// Tiles per unit of texture coordinate, (u, v).
    pub tiling: [f64; 2],
    pub shell: f64,
    pub background: [f64; 3],
    /// Shade at the hit's texel instead of the entry texel (for parallax-free BTFs).
    pub parallax: bool,
    /// The shell's side walls at the mesh's open boundary ([`shell_sides`]).
    pub sides: Vec<[V3; 4]>,
}

/// The shell's side walls: for every boundary edge (a, b) — an edge of one triangle only, its
/// ends welded by position — the quad a, b, b − shell·n_b, a − shell·n_a. Empty for a closed
/// mesh or a zero shell.
pub fn shell_sides(mesh: &Mesh, shell: f64) -> Vec<[V3; 4]> {
    if shell <= 0.0 {
        return Vec::new();
    }
    let key = |i: usize| mesh.positions[i].map(f32::to_bits);
    // Per edge, keyed by its ends' positions: one of its (a, b) and how many triangles use it.
    type Ends = ([u32; 3], [u32; 3]);
    let mut count: std::collections::HashMap<Ends, (usize, usize, u32)> =
        std::collections::HashMap::new();
    for t in 0..mesh.triangles() {
        let c = mesh.corners(t);
        for (a, b) in [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])] {
            let (ka, kb) = (key(a), key(b));
            if ka == kb {
                continue;
            }
            let e = if ka < kb { (ka, kb) } else { (kb, ka) };
            count.entry(e).or_insert((a, b, 0)).2 += 1;
        }
    }
    let mut edges: Vec<(usize, usize)> = count
        .into_values()
        .filter(|e| e.2 == 1)
        .map(|e| (e.0, e.1))
        .collect();
    edges.sort_unstable();
    let f = |v: [f32; 3]| v.map(|x| x as f64);
    edges
        .into_iter()
        .map(|(a, b)| {
            let (pa, pb) = (f(mesh.positions[a]), f(mesh.positions[b]));
            let na = normalize(f(mesh.normals[a])).unwrap_or([0.0, 0.0, 1.0]);
            let nb = normalize(f(mesh.normals[b])).unwrap_or([0.0, 0.0, 1.0]);
            [pa, pb, sub(pb, mul(nb, shell)), sub(pa, mul(na, shell))]
        })
        .collect()
}

/// The nearest distance beyond `after` at which the ray (o, d) crosses a side wall; ∞ for none.
pub fn side_exit(sides: &[[V3; 4]], o: V3, d: V3, after: f64) -> f64 {
    let mut best = f64::INFINITY;
    for q in sides {
        for (p0, p1, p2) in [(q[0], q[1], q[2]), (q[0], q[2], q[3])] {
            if let Some((t, ..)) = super::layers::intersect(o, d, p0, p1, p2) {
                if t > after && t < best {
                    best = t;
                }
            }
        }
    }
    best
}

/// A hit as [`Scene::hit`] gives it, and its depth for the parallax-compensated view blend.
type DeepHit = (f64, f64, Surface, V3, Option<[f64; 2]>);

/// Position, texture coordinate and tangent frame (t, b, n) at a visibility sample.
pub struct Surface {
    pub p: V3,
    pub uv: [f64; 2],
    pub t: V3,
    pub b: V3,
    pub n: V3,
}

impl Scene<'_> {
    pub fn surface(&self, f: &Frag) -> Surface {
        let m = self.mesh;
        let [i0, i1, i2] = m.corners(f.tri as usize);
        let w = [1.0 - f.b1 - f.b2, f.b1, f.b2];
        let lerp3 = |a: &dyn Fn(usize) -> V3| {
            let (x, y, z) = (a(i0), a(i1), a(i2));
            add(add(mul(x, w[0]), mul(y, w[1])), mul(z, w[2]))
        };
        let p = lerp3(&|i| m.positions[i].map(|v| v as f64));
        let n0 = lerp3(&|i| m.normals[i].map(|v| v as f64));
        let t0 = lerp3(&|i| {
            let t = m.tangents[i];
            [t[0] as f64, t[1] as f64, t[2] as f64]
        });
        let hand = m.tangents[i0][3] as f64;
        let uv = [0, 1].map(|k| {
            (m.uvs[i0][k] as f64 * w[0] + m.uvs[i1][k] as f64 * w[1] + m.uvs[i2][k] as f64 * w[2])
                * self.tiling[k]
        });
        let n = normalize(n0).unwrap_or([0.0, 0.0, 1.0]);
        let t = normalize(sub(t0, mul(n, dot(n, t0))))
            .unwrap_or_else(|| normalize(cross(n, [0.0, 1.0, 0.3])).unwrap_or([1.0, 0.0, 0.0]));
        let b = mul(cross(n, t), hand);
        Surface { p, uv, t, b, n }
    }

    fn local(s: &Surface, v: V3) -> V3 {
        [dot(v, s.t), dot(v, s.b), dot(v, s.n)]
    }

    /// MDF distance in world units and in MDF texels for a ray arriving against `wo` (local,
    /// pointing to the viewer); 0 without an MDF.
    fn mdf_distance(&self, s: &Surface, wo: V3) -> (f64, f64) {
        match &self.mdf {
            Some(m) if m.mdf.depth > 0.0 => {
                let d = m.eval(s.uv[0], s.uv[1], wo);
                (d * self.shell / m.mdf.depth, d)
            }
            _ => (0.0, 0.0),
        }
    }

    /// Where the ray `(o, d)` first meets mesostructure, as (distance, distance to the front
    /// face, surface frame at the front face, local view); `None` if it passes every layer.
    pub fn hit(&self, layers: &Layers, px: usize, o: V3, d: V3) -> Option<(f64, f64, Surface, V3)> {
        self.hit_with_depth(layers, px, o, d)
            .map(|h| (h.0, h.1, h.2, h.3))
    }

    /// [`Scene::hit`] with the hit's depth along the view ray in tile units along u and v (for
    /// the parallax-compensated view blend; `None` without an MDF or with `parallax` lookups).
    fn hit_with_depth(&self, layers: &Layers, px: usize, o: V3, d: V3) -> Option<DeepHit> {
        let plane = layers.width * layers.height;
        for k in 0..layers.count {
            let Some(f) = layers.front[k * plane + px] else {
                break;
            };
            let s = self.surface(&f);
            let wo = local_up(Self::local(&s, mul(d, -1.0)));
            let (df, dtex) = self.mdf_distance(&s, wo);
            let tb = match layers.back[k * plane + px] {
                Some(b) => {
                    let sb = self.surface(&b);
                    let out = local_up(Self::local(&sb, d));
                    b.t - self.mdf_distance(&sb, out).0
                }
                // No back face: bounded by the shell's side, where the mesh has one.
                None => side_exit(&self.sides, o, d, f.t),
            };
            if df.is_finite() && f.t + df < tb {
                let mut s = s;
                let mut depth = None;
                if let Some(m) = &self.mdf {
                    let tile = [dtex / m.mdf.width as f64, dtex / m.mdf.height as f64];
                    if self.parallax {
                        // The hit lies d·(−ω_o.x, −ω_o.y) texels from the entry point.
                        s.uv[0] -= tile[0] * wo[0];
                        s.uv[1] -= tile[1] * wo[1];
                    } else if dtex > 0.0 {
                        depth = Some(tile);
                    }
                }
                return Some((f.t + df, f.t, s, wo, depth));
            }
        }
        None
    }

    /// Linear RGB of pixel `px` whose ray is (o, d); `None` where the ray meets no
    /// mesostructure (the background shows).
    pub fn shade(
        &self,
        layers: &Layers,
        px: usize,
        o: V3,
        d: V3,
        shadow: Option<&ShadowMap>,
    ) -> Option<[f64; 3]> {
        let (_, t_front, s, wo, depth) = self.hit_with_depth(layers, px, o, d)?;
        let p = add(o, mul(d, t_front));
        let (to_light, irradiance) = self.light.at(p);
        let wi = Self::local(&s, to_light);
        if wi[2] <= 0.0 {
            return Some([0.0; 3]);
        }
        let visible = shadow.is_none_or(|sm| sm.lit(p, wi[2]));
        if !visible {
            return Some([0.0; 3]);
        }
        let f = self.material.eval_at_depth(s.uv[0], s.uv[1], wo, wi, depth);
        Some(f.map(|c| c * irradiance))
    }
}

/// A local direction nudged above the horizon: interpolated normals can put the view a hair
/// below it at silhouettes, where the tables have no data.
fn local_up(v: V3) -> V3 {
    if v[2] >= 1e-4 {
        return v;
    }
    let h = (v[0] * v[0] + v[1] * v[1]).sqrt().max(1e-12);
    let s = (1.0 - 1e-8f64).sqrt();
    [v[0] / h * s, v[1] / h * s, 1e-4]
}

/// Two shadow-map texels' footprint across the scene: enough for the slopes a texel spans.
pub fn shadow_bias(radius: f64, size: u32) -> f64 {
    2.0 * (2.0 * radius / size as f64)
}

impl ShadowMap {
    pub fn build(scene: &Scene, camera: Camera, layers: &Layers, radius: f64) -> ShadowMap {
        let (w, h) = (camera.width, camera.height);
        let depth = (0..(w * h) as usize)
            .into_par_iter()
            .map(|px| {
                let (o, d) = camera.ray(px as u32 % w, px as u32 / w);
                scene.hit(layers, px, o, d).map_or(f64::INFINITY, |h| h.0)
            })
            .collect();
        ShadowMap {
            bias: shadow_bias(radius, camera.width),
            camera,
            depth,
        }
    }

    /// Whether the light sees `p` (nearest shadow-map texel, biased comparison). The bias grows
    /// as the light grazes the surface (`cos_light`, local), where one texel spans more depth.
    pub fn lit(&self, p: V3, cos_light: f64) -> bool {
        let Some((x, y, t)) = self.camera.project(p) else {
            return true;
        };
        let (w, h) = (self.camera.width as f64, self.camera.height as f64);
        if !(0.0..w).contains(&x) || !(0.0..h).contains(&y) {
            return true;
        }
        let i = y as usize * self.camera.width as usize + x as usize;
        t <= self.depth[i] + self.bias / cos_light.max(0.1)
    }
}
