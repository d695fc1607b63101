//! `render.reference`: the ground truth's renderer. Direct illumination of a mesh (typically the
//! true mesostructure from `mesh.displace`) by `render.mesh`'s one light, and with `bounces` the
//! light reflected between its surfaces (path tracing, a shadow ray at every vertex), with exact hard shadows
//! (a shadow ray per sample) and the capture's reflectance models (`btf.capture`'s Lambert and
//! Ward, the same parameters), seen by `render.mesh`'s camera: N samples per pixel, stratified
//! where N is a square, averaged (a box filter). No BTF, no MDF, no shadow map: nothing that the
//! renders it judges approximate.
//!
//! Radiometry is `btf.capture`'s times the light's irradiance: a sample that sees the surface at
//! x with shading normal n returns E · f(ωi, ωo) · max(0, n·ωi) · V(x, ωi). Surfaces are
//! one-sided: a sample that meets a triangle from behind returns black. With a `normals` input
//! (a tangent-space normal map over the tile, `heightfield.normals`'s) the shading normal is the
//! map's, in the mesh's tangent frame: normal mapping, what a user without a BTF would render. Rays are traced through
//! a compressed wide BVH (the `obvhs` crate) and intersected in f64 with the mesh's own
//! triangles. Every pixel is computed on its own from seeded sub-pixel positions, so the image
//! has the same bits whatever the thread count.
//!
//! With a `medium` input the closed mesh is filled with that homogeneous medium and rendered by
//! volumetric path tracing instead (`volume.rs`): the truth for translucent renders. The
//! `noise` output estimates the image's own sampling error from two independent halves of its
//! samples (even and odd sample indices: two seeds of the same hash), so a comparison against
//! the truth can say how much of its difference is the truth's noise.

use super::material::texel_taps;
use super::volume::{self, Medium};
use crate::reflectance::models::{self as brdf, Model};
use crate::support::geometry::{add, cross, dot, mul, normalize, sub, V3};
use crate::support::raytrace::camera::Camera;
use crate::support::raytrace::light::Light;
use crate::support::raytrace::tracer::{Hit, Tracer};
use crate::types::{Image, Mesh, NormalMap, ScatteringMaterial};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::Instant;

crate::view_params! {
    #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
    #[serde(default, deny_unknown_fields)]
    pub struct Params {
        view { camera, light, tiling, background, mm_per_unit }
        /// Reflectance model (as `btf.capture`'s).
        pub brdf: Model = Model::Lambert,
        /// Diffuse albedo (linear RGB) when no `albedo` image is connected.
        pub albedo: [f64; 3] = [0.6, 0.6, 0.6],
        /// Ward specular albedo ρs.
        #[schemars(range(min = 0.0, max = 1.0))]
        pub specular: f64 = 0.05,
        /// Ward roughness α.
        #[schemars(range(min = 0.001, max = 1.0))]
        pub roughness: f64 = 0.2,
        /// Samples per pixel (1 to 65536); a square number is stratified.
        #[schemars(range(min = 1, max = 65536))]
        pub samples: u32 = 16,
        /// Seed of the sub-pixel positions (and of the paths, with a medium or bounces).
        pub seed: u64 = 1,
        /// Reflections off the mesh after the direct one that a surface path follows (0, the
        /// default: direct light only). A path ends where it leaves the mesh.
        #[schemars(range(min = 0, max = 64))]
        pub bounces: u32 = 0,
        /// GGX roughness α (0.01 to 1) of the `medium`'s boundary where its η ≠ 1 (required there,
        /// ignored at η = 1): a rough dielectric, because light through a smooth one from a
        /// directional light cannot be sampled, and a lobe narrower than 0.01 makes next-event
        /// estimation through it noise.
        #[schemars(range(min = 0.01, max = 1.0))]
        pub boundary_roughness: Option<f64> = None,
        /// With a medium at η ≠ 1: keep the light the boundary reflects where the camera first meets
        /// it (a glossy highlight). False keeps only what crossed into the medium, the part
        /// `sss.render` draws.
        pub surface_reflection: bool = true,
    }
}

pub struct Reference;

impl Node for Reference {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "render.reference",
            // 2: Ward's half vector is normalised before its cosine (btf::brdf; other rounding).
            // 3: a `medium` input (volumetric path tracing) and the `noise` estimate.
            // 4: a rough dielectric boundary for media at η ≠ 1 (the same image at η = 1).
            // (`bounces` 0, the default, renders version 4's image.)
            version: 4,
            doc: "Ground truth (or, with a normal map, normal mapping): direct light on a mesh (e.g. mesh.displace's true mesostructure) with exact hard shadows and the capture's Lambert or Ward reflectance, and with `bounces` the light reflected between its surfaces (path tracing); or, with a medium, volumetric path tracing of a translucent object (index-matched boundary at η = 1, rough dielectric otherwise). N samples per pixel, box filter, on the CPU, with its own noise estimate.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the geometry, its normals the shading normals"),
                Port::optional("albedo", Image::TYPE, "diffuse albedo over the tile (RGB), instead of `albedo`"),
                Port::optional("normals", NormalMap::TYPE, "tangent-space normals over the tile: normal mapping"),
                Port::optional("medium", ScatteringMaterial::TYPE, "a homogeneous medium filling the closed mesh (η = 1, or η ≠ 1 with `boundary_roughness`): volumetric path tracing instead of the surface reflectance"),
            ],
            outputs: vec![
                Port::output("image", Image::TYPE, "linear HDR radiance, RGB"),
                Port::output("coverage", Image::TYPE, "fraction of each pixel's samples that hit the mesh"),
                Port::output("covered", "Scalar", "fraction of all samples that hit the mesh"),
                Port::optional_output("noise", "Scalar", "estimated relative RMSE of the image from its own sampling, from two independent halves of the samples (absent with one sample)"),
                Port::optional_output("lost", "Scalar", "share of the medium's paths given up after a million scattering events (absent without a medium)"),
            ],
            disk_cache: true,
        }
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            (
                "bvh_seconds",
                "building the mesh's BVH, s (near 0 where the process kept it from a render of the same mesh; reading it where an earlier process stored it, `bvh_stored`)",
            ),
            (
                "bvh_stored",
                "1 where the BVH (a mesh of 100 000 triangles or more) was read from the disk cache, where an earlier process stored it; else 0",
            ),
            ("trace_seconds", "tracing the pixels, s (grows with pixels × samples)"),
            ("rays_per_second", "camera and shadow rays per second"),
            (
                "events_per_second",
                "scattering events per second (with a medium)",
            ),
        ]
    }

    fn files(
        &self,
        p: &Params,
        base: &std::path::Path,
    ) -> Result<Vec<std::path::PathBuf>, NodeError> {
        Ok(p.light.files(base))
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
        Light::check(&p.light)?;
        if !p.albedo.iter().all(|a| a.is_finite() && *a >= 0.0) {
            return Err(NodeError::param(
                "albedo",
                "must be finite and not negative",
            ));
        }
        if !p.tiling.iter().all(|t| t.is_finite() && *t > 0.0) {
            return Err(NodeError::param("tiling", "must be positive"));
        }
        if !p.background.iter().all(|b| b.is_finite()) {
            return Err(NodeError::param("background", "must be finite"));
        }
        if !(p.mm_per_unit > 0.0 && p.mm_per_unit.is_finite()) {
            return Err(NodeError::param("mm_per_unit", "must be a positive length"));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let medium = match inputs.opt::<ScatteringMaterial>("medium")? {
            Some(_) if p.bounces > 0 => {
                return Err(NodeError::param(
                    "bounces",
                    "is for a surface: with a `medium` every path already follows each scattering event to its end",
                ));
            }
            Some(m) => {
                if inputs.opt::<Image>("albedo")?.is_some()
                    || inputs.opt::<NormalMap>("normals")?.is_some()
                {
                    return Err(NodeError::input(
                        "medium",
                        "a medium's boundary is index-matched or a rough dielectric, with no albedo or normal map: connect `albedo` and `normals` to a surface render instead",
                    ));
                }
                Some(
                    Medium::new(m, p.mm_per_unit, p.boundary_roughness, p.surface_reflection)
                        .map_err(|e| NodeError::input("medium", e))?,
                )
            }
            None => None,
        };
        let albedo = inputs.opt::<Image>("albedo")?;
        if let Some(a) = albedo {
            check_albedo(a)?;
        }
        let normals = inputs.opt::<NormalMap>("normals")?;
        if let Some(n) = normals {
            if n.width == 0 || n.height == 0 || n.data.iter().any(|v| !v.is_finite()) {
                return Err(NodeError::input(
                    "normals",
                    "expected a non-empty map of finite normals",
                ));
            }
        }
        let camera = Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
        let light = Light::open(&p.light, ctx)?;
        let built = Instant::now();
        let scene = Tracer::in_context(mesh, Some(ctx));
        ctx.timing("bvh_seconds", built.elapsed().as_secs_f64());
        // 1 where the BVH was read from the disk cache an earlier process stored it in.
        let stored = scene.from == crate::support::raytrace::tracer::BvhFrom::Stored;
        ctx.timing("bvh_stored", f64::from(u8::from(stored)));
        let start = Instant::now();
        let (w, h) = (camera.width as usize, camera.height as usize);
        let done = std::sync::atomic::AtomicU64::new(0);
        let rows: Vec<Vec<Pixel>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let row = if ctx.is_cancelled() {
                    Vec::new()
                } else {
                    (0..w)
                        .map(|x| match &medium {
                            Some(m) => translucent(&scene, m, &camera, &light, p, x, y),
                            None => pixel(&scene, &camera, &light, p, (albedo, normals), x, y),
                        })
                        .collect()
                };
                let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                ctx.progress(n, h as u64);
                row
            })
            .collect();
        ctx.check_cancel()?;
        let mut image = Vec::with_capacity(w * h * 3);
        let mut coverage = Vec::with_capacity(w * h);
        let (mut hits, mut tally) = (0.0, volume::Tally::default());
        let (mut diff2, mut mean2) = (0.0, 0.0);
        let n = p.samples as f64;
        let halves = [
            (p.samples as f64 / 2.0).ceil(),
            (p.samples as f64 / 2.0).floor(),
        ];
        for px in rows.into_iter().flatten() {
            for k in 0..3 {
                let mean = (px.halves[0][k] + px.halves[1][k]) / n;
                image.push(mean as f32);
                mean2 += mean * mean;
                if halves[1] > 0.0 {
                    let d = px.halves[0][k] / halves[0] - px.halves[1][k] / halves[1];
                    diff2 += d * d;
                }
            }
            coverage.push(px.coverage as f32);
            hits += px.coverage;
            tally.add(&px.tally);
        }
        let seconds = start.elapsed().as_secs_f64().max(1e-9);
        ctx.timing("trace_seconds", seconds);
        ctx.timing("rays_per_second", tally.rays as f64 / seconds);
        if medium.is_some() {
            ctx.timing("events_per_second", tally.events as f64 / seconds);
        }
        let mut out = Outputs::new()
            .with(
                "image",
                Image {
                    width: w,
                    height: h,
                    channels: 3,
                    data: image,
                },
            )
            .with(
                "coverage",
                Image {
                    width: w,
                    height: h,
                    channels: 1,
                    data: coverage,
                },
            )
            .with("covered", Scalar(hits / (w * h).max(1) as f64));
        // Var(mean) ≈ (A − B)²/4 for two independent halves A, B of the samples.
        if p.samples > 1 && mean2 > 0.0 {
            out = out.with("noise", Scalar((diff2 / 4.0 / mean2).sqrt()));
        }
        if medium.is_some() {
            let paths = (w * h) as f64 * n;
            if tally.lost > 0 {
                ctx.warn(format!(
                    "{} of {paths} paths were given up after {} scattering events each",
                    tally.lost,
                    volume::MAX_EVENTS
                ));
            }
            out = out.with("lost", Scalar(tally.lost as f64 / paths));
        }
        Ok(out)
    }
}

/// One pixel's sums of its even and odd samples (two independent halves), the fraction of its
/// samples that hit, and what its rays did.
struct Pixel {
    halves: [[f64; 3]; 2],
    coverage: f64,
    tally: volume::Tally,
}

/// Sample `s` of pixel (x, y): the camera ray through its seeded, stratified sub-pixel position.
fn camera_ray(camera: &Camera, p: &Params, x: usize, y: usize, s: usize) -> (V3, V3) {
    let n = p.samples as usize;
    let side = (n as f64).sqrt().round() as usize;
    let pixel_id = (y * camera.width as usize + x) as u64;
    let h = crate::support::rng::hash(p.seed, &[pixel_id, s as u64]);
    let (jx, jy) = (
        crate::support::rng::unit(h),
        crate::support::rng::unit(crate::support::rng::mix(h)),
    );
    let (sx, sy) = if side * side == n {
        (
            ((s % side) as f64 + jx) / side as f64,
            ((s / side) as f64 + jy) / side as f64,
        )
    } else {
        (jx, jy)
    };
    camera.ray_at(x as f64 + sx, y as f64 + sy)
}

/// The `albedo` input's checks: a non-empty RGB image of finite, non-negative values (the
/// exports read it the same way).
pub fn check_albedo(a: &Image) -> Result<(), NodeError> {
    if a.channels < 3 || a.width == 0 || a.height == 0 {
        return Err(NodeError::input("albedo", "expected a non-empty RGB image"));
    }
    if a.data.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(NodeError::input(
            "albedo",
            "values must be finite and not negative",
        ));
    }
    Ok(())
}

/// One pixel of a translucent object: a volumetric path per sample.
fn translucent(
    scene: &Tracer,
    medium: &Medium,
    camera: &Camera,
    light: &Light,
    p: &Params,
    x: usize,
    y: usize,
) -> Pixel {
    let mut halves = [[0.0; 3]; 2];
    let mut tally = volume::Tally::default();
    let pixel_id = (y * camera.width as usize + x) as u64;
    for s in 0..p.samples as usize {
        let ray = camera_ray(camera, p, x, y, s);
        // The path's own stream, apart from the sub-pixel position's hash.
        let mut rng = crate::support::rng::Stream(crate::support::rng::hash(
            p.seed ^ 0x9a7e_5eed,
            &[pixel_id, s as u64],
        ));
        let l = volume::radiance(
            scene,
            medium,
            light,
            ray,
            p.background,
            &mut rng,
            &mut tally,
        );
        for k in 0..3 {
            halves[s % 2][k] += l[k];
        }
    }
    Pixel {
        halves,
        coverage: tally.hits as f64 / p.samples as f64,
        tally,
    }
}

/// One pixel of a surface: direct light, hard shadows, the capture's reflectance; with
/// `bounces`, the light that reached each seen point after up to that many reflections off the
/// mesh (a path per sample, cosine-sampled, the light's visibility tested at every vertex).
fn pixel(
    scene: &Tracer,
    camera: &Camera,
    light: &Light,
    p: &Params,
    maps: (Option<&Image>, Option<&NormalMap>),
    x: usize,
    y: usize,
) -> Pixel {
    let n = p.samples as usize;
    let mut halves = [[0.0; 3]; 2];
    let mut hits = 0usize;
    let mut rays = 0u64;
    let pixel_id = (y * camera.width as usize + x) as u64;
    // Where the pixel's last camera ray hit: the next one's first guess.
    let mut last = None;
    for s in 0..n {
        let (origin, dir) = camera_ray(camera, p, x, y, s);
        rays += 1;
        let found = scene.closest_near(origin, dir, last);
        last = found.as_ref().map(|h| h.slot).or(last);
        let Some(hit) = found else {
            halves[s % 2] = add(halves[s % 2], p.background);
            continue;
        };
        hits += 1;
        let Some(mut at) = Vertex::of(scene, &hit, dir, p, maps) else {
            continue; // one-sided: seen from behind
        };
        // The light's own stream at each vertex (an environment's sampled direction).
        let at_light = |bounce: u64| {
            crate::support::rng::hash(p.seed ^ 0x119_4700, &[pixel_id, s as u64, bounce])
        };
        let mut l = at.direct(scene, light, p, &mut rays, at_light(0));
        let mut throughput = [1.0; 3];
        for bounce in 0..p.bounces as u64 {
            // The path's own stream, apart from the sub-pixel position's hash.
            let h = crate::support::rng::hash(p.seed ^ 0xb0_07ce, &[pixel_id, s as u64, bounce]);
            // Cosine-weighted about the shading normal: f · cos / pdf = π f.
            let d = crate::support::geometry::cosine_direction(
                at.ns,
                crate::support::rng::unit(h),
                crate::support::rng::unit(crate::support::rng::mix(h)),
            );
            if dot(d, at.ng) <= 0.0 {
                break; // into the surface the shading normal leans over
            }
            let f = brdf::eval_rgb(p.brdf, at.rho, p.specular, p.roughness, at.ns, d, at.wo);
            throughput = [0, 1, 2].map(|k| throughput[k] * f[k] * std::f64::consts::PI);
            rays += 1;
            let Some(next) = scene.closest(add(at.pos, mul(at.ng, scene.epsilon)), d) else {
                // Left the mesh: a directional or point light sends nothing back, and an
                // environment's light along it is what the next-event sample at this vertex
                // already counted.
                break;
            };
            let Some(next) = Vertex::of(scene, &next, d, p, maps) else {
                break;
            };
            at = next;
            let direct = at.direct(scene, light, p, &mut rays, at_light(bounce + 1));
            l = [0, 1, 2].map(|k| l[k] + throughput[k] * direct[k]);
        }
        halves[s % 2] = add(halves[s % 2], l);
    }
    Pixel {
        halves,
        coverage: hits as f64 / n as f64,
        tally: volume::Tally {
            rays,
            ..Default::default()
        },
    }
}

/// A point a ray met on the front of the mesh, as the shading sees it.
struct Vertex {
    pos: V3,
    /// Geometric and shading normals.
    ng: V3,
    ns: V3,
    /// Towards where the ray came from.
    wo: V3,
    rho: [f64; 3],
}

impl Vertex {
    /// The point `hit` of a ray along `dir`; `None` where the ray met the triangle's back.
    fn of(
        scene: &Tracer,
        hit: &Hit,
        dir: V3,
        p: &Params,
        (albedo, normals): (Option<&Image>, Option<&NormalMap>),
    ) -> Option<Vertex> {
        let (_, ng) = scene.triangle(hit.tri);
        let wo = mul(dir, -1.0);
        if dot(ng, wo) <= 0.0 {
            return None;
        }
        let (pos, ns) = scene.mesh.interpolate(hit.tri, hit.b1, hit.b2);
        let mut ns = normalize(ns).unwrap_or(ng);
        if let Some(map) = normals {
            ns = mapped_normal(scene.mesh, hit, ns, map, p.tiling);
        }
        let rho = match albedo {
            Some(img) => {
                let uv = uv_at(scene.mesh, hit.tri, hit.b1, hit.b2);
                sample(img, uv[0] * p.tiling[0], uv[1] * p.tiling[1])
            }
            None => p.albedo,
        };
        Some(Vertex {
            pos,
            ng,
            ns,
            wo,
            rho,
        })
    }

    /// The light's reflection towards `wo`: E · f · cos θi where the light is in front of both
    /// normals' sides and a shadow ray reaches it; one shadow ray counted in `rays`. An
    /// environment is sampled once, from hash `h`, in proportion to its radiance
    /// (L · f · cos θi / pdf).
    fn direct(
        &self,
        scene: &Tracer,
        light: &Light,
        p: &Params,
        rays: &mut u64,
        h: u64,
    ) -> [f64; 3] {
        let (wi, irradiance) = match light.env() {
            Some(env) => {
                let u = crate::support::rng::unit(h);
                let v = crate::support::rng::unit(crate::support::rng::mix(h));
                match env.sample(u, v) {
                    Some((w, l, pdf)) => (w, l.map(|c| c / pdf)),
                    None => return [0.0; 3],
                }
            }
            None => {
                let (w, e) = light.at(self.pos);
                (w, [e; 3])
            }
        };
        let cos_i = dot(self.ns, wi);
        if cos_i <= 0.0 || dot(self.ns, self.wo) <= 0.0 {
            return [0.0; 3];
        }
        *rays += 1;
        let reach = light.reach(self.pos, wi);
        if scene.occluded(add(self.pos, mul(self.ng, scene.epsilon)), wi, reach) {
            return [0.0; 3];
        }
        let f = brdf::eval_rgb(
            p.brdf,
            self.rho,
            p.specular,
            p.roughness,
            self.ns,
            wi,
            self.wo,
        );
        [0, 1, 2].map(|k| irradiance[k] * f[k] * cos_i)
    }
}

/// The normal map's normal at the hit, in the mesh's tangent frame around `n` (tangent
/// orthogonalised against it, bitangent n × t with the tangent's handedness).
fn mapped_normal(mesh: &Mesh, hit: &Hit, n: V3, map: &NormalMap, tiling: [f64; 2]) -> V3 {
    let w = [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2];
    let c = mesh.corners(hit.tri);
    let mut t = [0.0; 3];
    for j in 0..3 {
        let q = mesh.tangents[c[j]];
        t = add(t, mul([q[0] as f64, q[1] as f64, q[2] as f64], w[j]));
    }
    let hand = mesh.tangents[c[0]][3] as f64;
    let Some(t) = normalize(sub(t, mul(n, dot(n, t)))) else {
        return n;
    };
    let b = mul(cross(n, t), hand);
    let uv = uv_at(mesh, hit.tri, hit.b1, hit.b2);
    let mut m = [0.0; 3];
    for (x, y, tw) in texel_taps(uv[0] * tiling[0], uv[1] * tiling[1], map.width, map.height) {
        let i = (y * map.width + x) * 3;
        for (k, mk) in m.iter_mut().enumerate() {
            *mk += tw * map.data[i + k] as f64;
        }
    }
    normalize(add(add(mul(t, m[0]), mul(b, m[1])), mul(n, m[2]))).unwrap_or(n)
}

fn uv_at(mesh: &Mesh, t: usize, b1: f64, b2: f64) -> [f64; 2] {
    let w = [1.0 - b1 - b2, b1, b2];
    let c = mesh.corners(t);
    [0, 1].map(|k| (0..3).map(|j| w[j] * mesh.uvs[c[j]][k] as f64).sum())
}

/// Bilinear periodic lookup of an RGB image at tile coordinates (u, v) (`render.mesh`'s texel
/// convention).
fn sample(img: &Image, u: f64, v: f64) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (x, y, w) in texel_taps(u, v, img.width, img.height) {
        let i = (y * img.width + x) * img.channels;
        for (o, v) in out.iter_mut().zip(&img.data[i..i + 3]) {
            *o += w * *v as f64;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{self, Shape};
    use crate::support::raytrace::camera::CameraParams;
    use crate::support::raytrace::light::LightParams;
    use mesoflow_testkit::node::OutputsExt;
    use std::f64::consts::PI;
    use std::sync::Arc;

    fn render(mesh: Mesh, p: &Params) -> (Image, Image, f64) {
        Reference.check(p).unwrap();
        let out =
            mesoflow_testkit::node::run(&Reference, p, &Inputs::new().with("mesh", Arc::new(mesh)))
                .unwrap();
        let img = |k: &str| {
            out.get(k)
                .and_then(|v| v.as_any().downcast_ref::<Image>())
                .cloned()
                .unwrap()
        };
        let covered = out.try_value::<Scalar>("covered").map_or(f64::NAN, |s| s.0);
        (img("image"), img("coverage"), covered)
    }

    fn plane() -> Mesh {
        primitive::build(&primitive::Params {
            shape: Shape::Plane,
            size: 2.0,
            minor: 0.0,
            segments: [4, 4],
        })
        .unwrap()
    }

    fn ortho(eye: [f64; 3], res: u32) -> CameraParams {
        CameraParams {
            eye,
            target: [0.0; 3],
            orthographic: Some(0.5),
            resolution: [res, res],
            ..Default::default()
        }
    }

    #[test]
    fn a_lit_lambert_plane_has_the_closed_form_radiance() {
        // E · ρ/π · cos θi: irradiance 2, albedo (0.2, 0.5, 0.8), light 60° from the normal.
        let t = 60f64.to_radians();
        let p = Params {
            camera: ortho([0.0, 0.3, 3.0], 8),
            light: LightParams {
                direction: [t.sin(), 0.0, t.cos()],
                position: None,
                intensity: 2.0,
                ..Default::default()
            },
            albedo: [0.2, 0.5, 0.8],
            samples: 4,
            ..Default::default()
        };
        let (img, cov, covered) = render(plane(), &p);
        assert_eq!(covered, 1.0);
        assert!(cov.data.iter().all(|&c| c == 1.0));
        for px in img.data.chunks_exact(3) {
            for (k, rho) in p.albedo.iter().enumerate() {
                let want = 2.0 * rho / PI * t.cos();
                assert!(
                    (px[k] as f64 - want).abs() < 1e-6 * want,
                    "{} vs {want}",
                    px[k]
                );
            }
        }
        // The Ward lobe: at the mirror direction the specular adds ρs/(4π α² cos θ) (tan δ = 0).
        let mirror = Params {
            camera: ortho([-(t.sin()) * 3.0, 0.0, t.cos() * 3.0], 4),
            brdf: Model::Ward,
            specular: 0.1,
            roughness: 0.3,
            ..p.clone()
        };
        let (img, ..) = render(plane(), &mirror);
        let want = 2.0 * t.cos() * (0.2 / PI + 0.1 / (4.0 * PI * 0.09 * t.cos()));
        let centre = &img.data[(2 * 4 + 2) * 3..];
        assert!(
            (centre[0] as f64 - want).abs() < 1e-4 * want,
            "{} vs {want}",
            centre[0]
        );
    }

    #[test]
    fn a_normal_map_tilts_the_shading_normal_in_the_tangent_frame() {
        // A constant map tilted 30° towards +u (the plane's +x): lit from 30° towards +x the
        // shading normal faces the light, E · ρ/π; lit from 30° towards −x, E · ρ/π · cos 60°.
        let a = 30f64.to_radians();
        let map = NormalMap {
            width: 2,
            height: 2,
            data: [a.sin() as f32, 0.0, a.cos() as f32].repeat(4),
        };
        for (sign, cos) in [(1.0, 1.0), (-1.0, 0.5)] {
            let p = Params {
                camera: ortho([0.0, 0.0, 3.0], 4),
                light: LightParams {
                    direction: [sign * a.sin(), 0.0, a.cos()],
                    position: None,
                    intensity: 2.0,
                    ..Default::default()
                },
                albedo: [0.5; 3],
                samples: 1,
                ..Default::default()
            };
            let out = mesoflow_testkit::node::run(
                &Reference,
                &p,
                &Inputs::new()
                    .with("mesh", Arc::new(plane()))
                    .with("normals", Arc::new(map.clone())),
            )
            .unwrap();
            let img = out.try_value::<Image>("image").unwrap();
            let want = 2.0 * 0.5 / PI * cos;
            assert!(
                (img.data[0] as f64 - want).abs() < 1e-5,
                "{} vs {want}",
                img.data[0]
            );
        }
    }

    #[test]
    fn hard_shadows_and_coverage_are_exact() {
        // A small square floating above a plane, lit straight down, seen straight down with 8 × 8
        // pixels over the unit square [−0.5, 0.5]²: the square covers [−0.25, 0.25]² at z = 0.5
        // and shadows exactly the plane under it; the view sees the square there instead. The
        // floater is one-sided facing up, so the pixels under it show its own radiance.
        let mut scene = plane();
        let mut top = primitive::build(&primitive::Params {
            shape: Shape::Plane,
            size: 0.5,
            minor: 0.0,
            segments: [1, 1],
        })
        .unwrap();
        let base = scene.positions.len() as u32;
        for q in &mut top.positions {
            q[2] = 0.5;
        }
        scene.positions.extend(&top.positions);
        scene.normals.extend(&top.normals);
        scene.uvs.extend(&top.uvs);
        scene.tangents.extend(&top.tangents);
        scene.indices.extend(top.indices.iter().map(|i| i + base));
        let p = Params {
            camera: ortho([0.0, 0.0, 3.0], 8),
            light: LightParams {
                direction: [0.0, 0.0, 1.0],
                position: None,
                intensity: 1.0,
                ..Default::default()
            },
            albedo: [0.5; 3],
            samples: 16,
            ..Default::default()
        };
        let (img, ..) = render(scene.clone(), &p);
        let lit = 0.5 / PI;
        for (i, px) in img.data.chunks_exact(3).enumerate() {
            assert!((px[0] as f64 - lit).abs() < 1e-6, "pixel {i}: {}", px[0]);
        }
        // Light from 45° in x: the shadow moves 0.5 along x, half of it out of the floater's
        // view; pixels entirely in shadow are black.
        let slanted = Params {
            light: LightParams {
                direction: [1.0, 0.0, 1.0],
                position: None,
                intensity: 1.0,
                ..Default::default()
            },
            ..p
        };
        let (img, ..) = render(scene, &slanted);
        let value = |x: usize, y: usize| img.data[(y * 8 + x) * 3] as f64;
        // Plane x in [−0.75, −0.25] under the shadow: pixel columns 0 and 1 (x −0.5 to −0.25),
        // rows 2 to 5 (y −0.25 to 0.25).
        for y in 2..6 {
            assert_eq!(value(0, y), 0.0);
            assert_eq!(value(1, y), 0.0);
        }
        let lit = 0.5 / PI * std::f64::consts::FRAC_1_SQRT_2;
        assert!((value(0, 0) - lit).abs() < 1e-6);
    }

    #[test]
    fn same_bits_for_any_thread_count_and_backgrounds_where_nothing_is_hit() {
        let torus = primitive::build(&primitive::Params {
            shape: Shape::Torus,
            size: 0.3,
            minor: 0.1,
            segments: [24, 12],
        })
        .unwrap();
        let p = Params {
            camera: CameraParams {
                eye: [0.0, 1.0, 1.2],
                target: [0.0; 3],
                resolution: [24, 18],
                ..Default::default()
            },
            brdf: Model::Ward,
            samples: 5,
            background: [0.25, 0.0, 0.0],
            ..Default::default()
        };
        let go = |threads| {
            mesoflow_testkit::threads::with_threads(threads, || render(torus.clone(), &p))
        };
        let (a, ca, covered) = go(1);
        let (b, cb, _) = go(3);
        assert_eq!(a.data, b.data);
        assert_eq!(ca.data, cb.data);
        assert!(covered > 0.05 && covered < 0.9, "{covered}");
        // Paths with bounces draw their directions from (pixel, sample, bounce) alone, and the
        // torus's inner ring reflects light onto itself, so they change the image but not the
        // bits with the thread count.
        let bounced = Params {
            bounces: 3,
            ..p.clone()
        };
        let go = |threads| {
            mesoflow_testkit::threads::with_threads(threads, || render(torus.clone(), &bounced))
        };
        let (c, _, _) = go(1);
        assert_eq!(c.data, go(2).0.data);
        assert_ne!(c.data, a.data);
        // A pixel no sample hits is the background.
        let i = ca.data.iter().position(|&c| c == 0.0).unwrap();
        assert_eq!(&a.data[i * 3..i * 3 + 3], &[0.25, 0.0, 0.0]);
        assert!(a.data.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}
