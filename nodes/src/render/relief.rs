//! `render.relief`: relief mapping (Policarpo, Oliveira & Comba 2005) of a mesh textured with a
//! height map and Ward reflectance maps — seed 003's rendering of what `brdf.fit_ward` and
//! `heightfield.from_normals` recover. Per pixel, the view ray enters the mesh (the top of the
//! mesostructure) and is followed down through the height field in tangent space: a linear
//! search in `linear_steps` equal depth steps finds the first step below the surface, a binary
//! search of `binary_steps` halvings refines it. The hit is shaded with the Ward lobe of the maps
//! there, about the height field's normal, and a second linear search towards the light decides
//! self-shadowing. GPU (wgpu render pass, `relief.wgsl`) with a CPU path of the same formulas.
//!
//! Units follow `render.mesh`: the tile repeats `tiling` times per texture unit, and the height
//! field's range (max − min texels) is `shell` world units deep. Directions are mapped into the
//! tile's own proportions (the texel aspect) before the search, so a stretched mapping has flatter
//! or steeper bumps as the geometry says. Values are radiance for the light's irradiance:
//! E·f(ωi, ωo)·max(0, n·ωi)·visibility, as `btf.capture` measures with `bounces` 0: the relief
//! reflects the light once; light reflected between its walls is not modelled (a capture with
//! `bounces`, or `render.reference` with `bounces` on the true surface, holds it).

use super::relief_gpu;
pub use super::relief_scene::Relief;
use super::surface::{surface_at, Surface};
use crate::reflectance::models::{self as brdf, Model};
use crate::support::geometry::{dot, mul, normalize, V3};
use crate::support::progress::Counter;
use crate::support::raytrace::camera::Camera;
use crate::support::raytrace::layers::{self, Frag};
use crate::support::raytrace::light::Light;
use crate::support::rng;
use crate::types::{BrdfMap, HeightField, Image, Mesh, NormalMap, WARD_PARAMS};
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
        // A relief is one height field over the texture space: one tile unless the graph says
        // otherwise; its shadows come from the height field itself, so they are cheap and on.
        view { camera, light, tiling = [1.0, 1.0], shadows = true, background }
        /// World depth of the height field's range (max − min texels), as `render.mesh`'s shell.
        #[schemars(range(min = 0.0, max = 1e9))]
        pub shell: f64 = 0.05,
        /// Linear-search steps down through the relief (and towards the light for shadows).
        #[schemars(range(min = 1, max = 4096))]
        pub linear_steps: u32 = 16,
        /// Binary-search halvings after the linear search.
        #[schemars(range(min = 0, max = 32))]
        pub binary_steps: u32 = 6,
        /// Under an environment light: directions a pixel integrates it over, drawn in
        /// proportion to its radiance (a lattice turned per pixel), each with its own
        /// self-shadowing search.
        #[schemars(range(min = 1, max = 4096))]
        pub environment_samples: u32 = 64,
        /// Frames rendered for the timing metrics (the image is the last one).
        #[schemars(range(min = 1, max = 1000))]
        pub frames: u32 = 1,
    }
}

pub struct RenderRelief;

impl Node for RenderRelief {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "render.relief",
            // 2: environment lights.
            version: 2,
            doc: "Relief mapping (Policarpo et al. 2005) of a mesh with a height map and Ward maps: linear then binary search in tangent space, self-occlusion and self-shadowing (the light's direct reflection: light reflected between the relief's walls is not modelled); under an environment light, `environment_samples` directions a pixel, each self-shadowed (the mesh's own shadow on itself is not modelled); GPU render pass with a CPU path (environments on the CPU).",
            device: DevicePreference::Gpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the surface, with UVs and tangents"),
                Port::input("height", HeightField::TYPE, "the mesostructure tile, heights in texels"),
                Port::input("maps", BrdfMap::TYPE, "Ward parameters per texel, the height field's size"),
                Port::optional("normals", NormalMap::TYPE, "normals per texel (default: the height field's, by central differences)"),
            ],
            outputs: vec![
                Port::output("image", Image::TYPE, "linear HDR RGB"),
                Port::output("mask", Image::TYPE, "1 where the mesh is hit, else 0 (one channel)"),
                Port::output("coverage", "Scalar", "share of pixels that show the mesh"),
            ],
            disk_cache: true,
        }
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            ("frame_ms", "mean wall time per frame, ms"),
            ("gpu_ms", "mean GPU time per frame from timestamp queries, ms; absent where the adapter has none, and on the CPU"),
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
        if p.tiling.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(NodeError::param("tiling", "must be finite and positive"));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let scene = Relief::new(
            mesh,
            inputs.get::<HeightField>("height")?,
            inputs.get::<BrdfMap>("maps")?,
            inputs.opt::<NormalMap>("normals")?,
            p,
            Light::open(&p.light, ctx)?,
        )?;
        let camera = Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
        let [w, h] = p.camera.resolution;
        let start = Instant::now();
        let gpu = match ctx.gpu() {
            Some(_) if p.light.is_environment() => {
                ctx.warn("an environment light is shaded on the CPU: the GPU path shades a directional or point light only");
                None
            }
            gpu => gpu,
        };
        let (data, mask, gpu_ms) = match gpu {
            Some(gpu) => relief_gpu::render(gpu, &scene, &camera, p.frames)?,
            None => {
                let watch = Counter::new(ctx, 0);
                let mut frame = (Vec::new(), Vec::new());
                for _ in 0..p.frames {
                    ctx.check_cancel()?;
                    frame = render_cpu(&scene, &camera, &watch);
                    if watch.stopped() {
                        return Err(NodeError::Cancelled);
                    }
                }
                (frame.0, frame.1, None)
            }
        };
        let ms = start.elapsed().as_secs_f64() * 1e3 / p.frames as f64;
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(NodeError::Failed(format!(
                "pixel {} is not finite: a bug, please report it with the graph",
                i / 3
            )));
        }
        ctx.timing("frame_ms", ms);
        if let Some(g) = gpu_ms {
            ctx.timing("gpu_ms", g);
        }
        let coverage = mask.iter().map(|m| *m as f64).sum::<f64>() / mask.len().max(1) as f64;
        Ok(Outputs::new()
            .with(
                "image",
                Image {
                    width: w as usize,
                    height: h as usize,
                    channels: 3,
                    data,
                },
            )
            .with(
                "mask",
                Image {
                    width: w as usize,
                    height: h as usize,
                    channels: 1,
                    data: mask,
                },
            )
            .with("coverage", Scalar(coverage)))
    }
}

/// Occluders nearer the hit than this (texels, horizontally) do not shadow it: the shading
/// normal comes from central differences over ±1 texel, so the facets within that span are
/// already in its orientation. Testing them as well self-shadows bilinear facets next to a hit
/// whose smooth normal faces the light — acne along every terminator, which moved with the
/// search's resolution and kept renders at different step counts from converging.
const NORMAL_SUPPORT: f64 = 1.0;

impl<'a> Relief<'a> {
    pub fn new(
        mesh: &'a Mesh,
        hf: &HeightField,
        maps: &BrdfMap,
        normals: Option<&NormalMap>,
        p: &Params,
        light: Light,
    ) -> Result<Self, NodeError> {
        let (w, h) = (hf.width, hf.height);
        if (maps.width, maps.height) != (w, h) {
            return Err(NodeError::input(
                "maps",
                format!(
                    "are {}×{}, the height field {w}×{h}; they must match",
                    maps.width, maps.height
                ),
            ));
        }
        if let Some(i) = maps.data.iter().position(|v| !v.is_finite()) {
            let px = i / WARD_PARAMS;
            return Err(NodeError::input(
                "maps",
                format!("texel ({}, {}) has a non-finite parameter", px % w, px / w),
            ));
        }
        if let Some(i) = hf.data.iter().position(|v| !v.is_finite()) {
            return Err(NodeError::input(
                "height",
                format!("texel ({}, {}) is not finite", i % w, i / w),
            ));
        }
        let (lo, hi) = hf.min_max();
        let grad: Vec<[f32; 2]> = match normals {
            Some(n) if (n.width, n.height) != (w, h) => {
                return Err(NodeError::input(
                    "normals",
                    format!(
                        "is {}×{}, the height field {w}×{h}; they must match",
                        n.width, n.height
                    ),
                ));
            }
            Some(n) => n
                .data
                .chunks_exact(3)
                .enumerate()
                .map(|(i, c)| {
                    if !(c.iter().all(|v| v.is_finite()) && c[2] > 1e-3) {
                        return Err(NodeError::input(
                            "normals",
                            format!(
                                "texel ({}, {}) is not a height field's normal",
                                i % w,
                                i / w
                            ),
                        ));
                    }
                    // n = (−∂h/∂x, ∂h/∂y_up, 1)/len with ∂h/∂y_up = −∂h/∂y_grid.
                    Ok([-c[0] / c[2], c[1] / c[2]])
                })
                .collect::<Result<_, _>>()?,
            None => (0..h as isize)
                .flat_map(|y| (0..w as isize).map(move |x| (x, y)))
                .map(|(x, y)| {
                    [
                        0.5 * (hf.at_wrapped(x + 1, y) - hf.at_wrapped(x - 1, y)),
                        0.5 * (hf.at_wrapped(x, y + 1) - hf.at_wrapped(x, y - 1)),
                    ]
                })
                .collect(),
        };
        let depth = hi - lo;
        Ok(Relief {
            mesh,
            width: w,
            height: h,
            heights: hf.data.clone(),
            top: hi,
            depth,
            grad,
            maps: maps
                .data
                .chunks_exact(WARD_PARAMS)
                .map(|c| {
                    [
                        c[0] as f32,
                        c[1] as f32,
                        c[2] as f32,
                        c[3] as f32,
                        c[4].max(1e-3) as f32,
                    ]
                })
                .collect(),
            aspect: aspect(mesh, p.tiling, p.shell, w, h, depth as f64),
            tiling: p.tiling,
            light,
            environment_samples: p.environment_samples.max(1),
            linear_steps: p.linear_steps,
            binary_steps: p.binary_steps,
            shadows: p.shadows,
            background: p.background,
        })
    }

    /// Bilinear, periodic interpolation of per-texel values at grid point (x, y).
    fn lerp<const K: usize>(&self, x: f64, y: f64, at: impl Fn(usize) -> [f32; K]) -> [f64; K] {
        crate::heightfield::grid::bilerp(self.width, self.height, x, y, at)
    }

    /// Depth of the surface below the top at grid point (x, y), texels.
    fn surface_depth(&self, x: f64, y: f64) -> f64 {
        self.top as f64 - self.lerp(x, y, |i| [self.heights[i]])[0]
    }

    /// Radiance at a visibility sample, and whether the light reaches the hit.
    pub fn shade(&self, f: &Frag, ray_dir: V3) -> [f64; 3] {
        let Surface {
            p, uv, t, b, n, k, ..
        } = surface_at(self.mesh, self.tiling, &self.aspect, f);
        let local = |v: V3| [dot(v, t), dot(v, b), dot(v, n)];
        let canonical = |v: V3| normalize([v[0] * k[0], v[1] * k[1], v[2]]).unwrap_or(v);
        let mut wo = local(mul(ray_dir, -1.0));
        wo[2] = wo[2].max(1e-3);
        let wo = normalize(wo).unwrap_or([0.0, 0.0, 1.0]);
        let c = canonical(wo);
        // Grid position at depth s below the top: x along u, y down the image (tangent y is up).
        let (x0, y0) = (
            uv[0] * self.width as f64 - 0.5,
            (1.0 - uv[1]) * self.height as f64 - 0.5,
        );
        let (dx, dy) = (-c[0] / c[2], c[1] / c[2]);
        let at = |s: f64| (x0 + s * dx, y0 + s * dy);
        let d = self.depth as f64;
        let (mut lo, mut hi) = (0.0, d);
        let n_lin = self.linear_steps as f64;
        for i in 1..=self.linear_steps {
            let s = d * i as f64 / n_lin;
            let (x, y) = at(s);
            if s >= self.surface_depth(x, y) {
                hi = s;
                break;
            }
            lo = s;
        }
        for _ in 0..self.binary_steps {
            let mid = 0.5 * (lo + hi);
            let (x, y) = at(mid);
            if mid >= self.surface_depth(x, y) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let s_hit = hi;
        let (hx, hy) = at(s_hit);
        let [gx, gy] = self.lerp(hx, hy, |i| self.grad[i]);
        // The canonical normal (−∂h/∂x, ∂h/∂y_up, 1) in the tile's proportions, into local
        // world proportions by K (a plane n_c·c = 0 with c = K·l has local normal K·n_c).
        let nl = normalize([-gx * k[0], gy * k[1], 1.0]).unwrap_or([0.0, 0.0, 1.0]);
        let [r, g, bl, rho_s, alpha] = self.lerp(hx, hy, |i| self.maps[i]);
        // Radiance from world direction `to_light` carrying `e` (RGB irradiance on a surface
        // facing it), self-shadowed.
        let reflect = |to_light: V3, e: [f64; 3]| -> [f64; 3] {
            let wi = local(to_light);
            let cos_i = dot(nl, wi);
            if cos_i <= 0.0 || e.iter().all(|c| *c <= 0.0) {
                return [0.0; 3];
            }
            if self.shadows && !self.lit(hx, hy, s_hit, canonical(wi)) {
                return [0.0; 3];
            }
            let rgb = [r, g, bl];
            std::array::from_fn(|c| {
                e[c] * brdf::eval(Model::Ward, rgb[c], rho_s, alpha, nl, wi, wo) * cos_i
            })
        };
        match self.light.env() {
            None => {
                let (to_light, e) = self.light.at(p);
                reflect(to_light, [e; 3])
            }
            Some(env) => {
                // A rank-1 lattice (the R2 sequence) over the sampler's unit square, turned by
                // a hash of the hit so neighbouring pixels' errors do not line up; the hash of
                // the hit's position, not of a thread's order, keeps the bits at any count.
                let h = rng::hash(0x5e1ef, &[p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]);
                let (a, b) = (rng::unit(h), rng::unit(rng::mix(h)));
                let n = self.environment_samples;
                let mut sum = [0.0; 3];
                for i in 0..n {
                    let u = (a + i as f64 * 0.754_877_666_246_693).fract();
                    let v = (b + i as f64 * 0.569_840_290_998_053).fract();
                    if let Some((w, l, pdf)) = env.sample(u, v) {
                        let c = reflect(w, l.map(|x| x / pdf));
                        for k in 0..3 {
                            sum[k] += c[k];
                        }
                    }
                }
                sum.map(|c| c / n as f64)
            }
        }
    }

    /// Twice the depth interval the linear and binary searches leave, texels.
    pub fn slack(&self) -> f64 {
        2.0 * self.depth as f64
            / self.linear_steps as f64
            / f64::powi(2.0, self.binary_steps as i32)
    }

    /// Whether the light along canonical direction `l` reaches grid point (x, y) at depth s:
    /// `linear_steps` equal rises from s to the top, each tested against the surface.
    fn lit(&self, x: f64, y: f64, s: f64, l: V3) -> bool {
        if l[2] <= 0.0 {
            return false;
        }
        let (dx, dy) = (l[0] / l[2], -l[1] / l[2]);
        let speed = dx.hypot(dy);
        // The hit is known to within the searches' last interval: a surface closer above the
        // ray than twice that is the hit's own, not an occluder.
        let slack = self.slack();
        (1..=self.linear_steps).all(|i| {
            let rise = s * i as f64 / self.linear_steps as f64;
            let depth = s - rise;
            rise * speed < NORMAL_SUPPORT
                || self.surface_depth(x + rise * dx, y + rise * dy) >= depth - slack
        })
    }
}

/// The texel aspect per vertex: how many texels one world unit spans along u and v, over how many
/// texels of depth it spans along the normal (`shell` world units hold the `depth`-texel range).
/// Empty (all 1) for a flat tile or no shell.
pub fn aspect(
    mesh: &Mesh,
    tiling: [f64; 2],
    shell: f64,
    w: usize,
    h: usize,
    depth: f64,
) -> Vec<[f32; 2]> {
    if !(shell > 0.0 && depth > 0.0) {
        return Vec::new();
    }
    let along_normal = depth / shell;
    let k = |len: f32, tiles: f64, texels: usize| {
        if len > 0.0 {
            (tiles * texels as f64 / len as f64 / along_normal).clamp(1e-3, 1e3) as f32
        } else {
            1.0
        }
    };
    mesh.uv_scale()
        .into_iter()
        .map(|[lu, lv]| [k(lu, tiling[0], w), k(lv, tiling[1], h)])
        .collect()
}

/// The image (RGB) and mask of one frame on the CPU.
pub fn render_cpu(scene: &Relief, cam: &Camera, watch: &Counter) -> (Vec<f32>, Vec<f32>) {
    let layers = layers::trace(scene.mesh, cam, 1, watch);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut image = vec![0f32; 3 * w * h];
    let mut mask = vec![0f32; w * h];
    image
        .par_chunks_mut(3 * w)
        .zip(mask.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, mrow))| {
            for x in 0..w {
                let rgb = match layers.front[y * w + x] {
                    Some(f) => {
                        mrow[x] = 1.0;
                        scene.shade(&f, cam.ray(x as u32, y as u32).1)
                    }
                    None => scene.background,
                };
                for c in 0..3 {
                    row[3 * x + c] = rgb[c] as f32;
                }
            }
        });
    (image, mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::capture::{self, Capture};
    use crate::btf::directions::DirectionSet;
    use crate::support::raytrace::camera::CameraParams;
    use crate::support::raytrace::light::LightParams;
    use crate::types::Btf;
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    /// A unit plane facing +z, uv (0..1) along +x and +y.
    fn plane() -> Mesh {
        let p = crate::mesh::primitive::Params {
            shape: crate::mesh::primitive::Shape::Plane,
            size: 1.0,
            segments: [1, 1],
            ..Default::default()
        };
        crate::mesh::primitive::build(&p).unwrap()
    }

    /// Orthographic view of the unit plane, `n`×`n` pixels, from direction (θ, 0) in degrees.
    fn params(n: u32, theta: f64, light: [f64; 3], shell: f64) -> Params {
        let t = theta.to_radians();
        Params {
            camera: CameraParams {
                eye: [5.0 * t.sin(), 0.0, 5.0 * t.cos()],
                target: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov: 40.0,
                orthographic: Some(0.5),
                resolution: [n, n],
            },
            light: LightParams {
                direction: light,
                position: None,
                intensity: 1.0,
                ..Default::default()
            },
            shell,
            linear_steps: 512,
            binary_steps: 12,
            ..Params::default()
        }
    }

    fn render(
        hf: &HeightField,
        maps: &BrdfMap,
        p: &Params,
        gpu: Option<Arc<mesoflow_runtime::Gpu>>,
    ) -> Result<Vec<f32>, NodeError> {
        let mesh = plane();
        let inputs = Inputs::new()
            .with("mesh", Arc::new(mesh))
            .with("height", Arc::new(hf.clone()))
            .with("maps", Arc::new(maps.clone()));
        RenderRelief.check(p)?;
        let out =
            mesoflow_testkit::node::run_in(&NodeContext::detached(gpu), &RenderRelief, p, &inputs)?;
        Ok(out.value::<Image>("image").data.clone())
    }

    fn bumps(n: usize) -> HeightField {
        let p = crate::heightfield::procedural::Params {
            pattern: crate::heightfield::procedural::Pattern::Bumps,
            size: n as u32,
            count: 4,
            depth: 3.0,
            ..Default::default()
        };
        crate::heightfield::procedural::generate(&NodeContext::detached(None), &p).unwrap()
    }

    fn maps(n: usize) -> BrdfMap {
        BrdfMap {
            width: n,
            height: n,
            data: (0..n * n)
                .flat_map(|i| {
                    [
                        0.2 + 0.5 * ((i % n) as f64 / n as f64),
                        0.4,
                        0.3,
                        0.08,
                        0.25,
                    ]
                })
                .collect(),
        }
    }

    /// `btf.capture` of the tile seen from above (view (0°, 0°)) under `lights` (θ, φ in
    /// degrees), with the maps' Ward lobes.
    fn captured_from_above(hf: &HeightField, m: &BrdfMap, lights: Vec<[f64; 2]>) -> Btf {
        let cp = capture::Params {
            views: DirectionSet::List(vec![[0.0, 0.0]]),
            lights: DirectionSet::List(lights),
            brdf: Model::Ward,
            ..capture::Params::default()
        };
        let out = mesoflow_testkit::node::run(
            &Capture,
            &cp,
            &Inputs::new()
                .with("height", Arc::new(hf.clone()))
                .with("maps", Arc::new(m.clone())),
        )
        .unwrap();
        out.value::<Btf>("btf").clone()
    }

    #[test]
    fn seen_from_above_it_is_the_capture_of_the_same_tile() {
        // An n×n orthographic view of a plane mapped once with the n×n tile puts pixel (x, y)
        // on texel (x, y): what btf.capture, an exact ray caster written separately, measures at
        // view (0°, 0°). Shading, normals, maps and self-shadowing must agree to 1e-4, except
        // where the capture's shadow ray is stopped by the bilinear facet right next to the hit
        // (within the texel the shading normal spans, which relief.rs leaves to the normal):
        // 3.1% of the values at light (45°, 30°) were measured there, none at the others; bound
        // 5%. The searches (512 + 12 steps) find the surface to 3/512/4096 texel.
        let n = 32;
        let (hf, m) = (bumps(n), maps(n));
        let (lo, hi) = hf.min_max();
        // Texel aspect 1: one texel across (1/n world) is one texel deep.
        let shell = (hi - lo) as f64 / n as f64;
        for light in [[0.0, 0.0], [45.0, 30.0], [70.0, 200.0]] {
            let l = crate::types::Direction::degrees(light[0], light[1]).vector();
            let img = render(&hf, &m, &params(n as u32, 0.0, l, shell), None).unwrap();
            let b = captured_from_above(&hf, &m, vec![light]);
            let (mut off, mut worst) = (0, 0f32);
            for y in 0..n {
                for x in 0..n {
                    for c in 0..3 {
                        let want = b.data[c * n * n + y * n + x];
                        let got = img[3 * (y * n + x) + c];
                        let d = (got - want).abs();
                        if d > 1e-4 * want.max(1e-3) {
                            off += 1;
                        } else {
                            worst = worst.max(d);
                        }
                    }
                }
            }
            let share = off as f64 / (3 * n * n) as f64;
            eprintln!("light {light:?}: {share:.4} of values differ (facets next to the hit)");
            assert!(share < 0.05, "light {light:?}: {share}");
        }
    }

    #[test]
    fn under_the_sky_it_is_the_capture_summed_over_the_sky() {
        // Under an environment, each pixel seen from above is the capture's texel (an exact ray
        // caster written separately, as in the test above) summed over the environment's
        // directions: Σ L(ω) Δω · capture(ω), the sky box-filtered to 128 × 64 cells (the
        // 1 024 above the horizon captured as lights). Bounds set before the first run: the
        // tile's mean within 2% (the quadrature's cells average the sun, its shadows are read
        // at each cell's centre), each texel within 10% RMS (1 024 samples a pixel).
        use crate::support::raytrace::environment::{Environment, SkyParams, PROCEDURAL_SIZE};
        let n = 16;
        let (hf, m) = (bumps(n), maps(n));
        let (lo, hi) = hf.min_max();
        let shell = (hi - lo) as f64 / n as f64;
        let mut p = params(n as u32, 0.0, [0.0, 0.0, 1.0], shell);
        p.light.sky = Some(SkyParams::default());
        p.environment_samples = 1024;
        let img = render(&hf, &m, &p, None).unwrap();
        let (w, h) = PROCEDURAL_SIZE;
        let sky =
            Environment::new(w, h, &SkyParams::default().texels().unwrap(), 1.0, 0.0).unwrap();
        let cells: Vec<_> = sky
            .quadrature(128, 64)
            .into_iter()
            .filter(|(d, _, _)| d[2] > 0.0)
            .collect();
        let lights = cells
            .iter()
            .map(|(d, _, _)| [d[2].acos().to_degrees(), d[1].atan2(d[0]).to_degrees()])
            .collect();
        let b = captured_from_above(&hf, &m, lights);
        let texels = n * n;
        let (mut ours, mut truth, mut sq) = (0.0, 0.0, 0.0);
        for y in 0..n {
            for x in 0..n {
                for c in 0..3 {
                    let want: f64 = cells
                        .iter()
                        .enumerate()
                        .map(|(j, (_, l, dw))| {
                            l[c] * dw * b.data[(j * 3 + c) * texels + y * n + x] as f64
                        })
                        .sum();
                    let got = img[3 * (y * n + x) + c] as f64;
                    ours += got;
                    truth += want;
                    sq += ((got - want) / want.max(1e-6)).powi(2);
                }
            }
        }
        let mean = ours / truth - 1.0;
        let rms = (sq / (3 * texels) as f64).sqrt();
        eprintln!(
            "relief under the sky: mean {:+.2}%, per texel {:.2}% RMS",
            100.0 * mean,
            100.0 * rms
        );
        assert!(mean.abs() <= 0.02, "mean {mean}");
        assert!(rms <= 0.10, "per texel {rms}");
    }

    #[test]
    fn a_tilted_view_sees_the_floor_shifted_by_its_depth() {
        // A pillar 8 texels tall at texel (0, 0) puts the top 8 texels above a flat floor. Seen
        // from θ = 45° towards +x the ray entering at grid x meets the floor 8·tan 45° = 8 texels
        // towards −x; with light from straight above each pixel is ρd(x − 8)/π, ρd bilinear
        // between the texels (the closed form). Pixels whose path crosses the pillar's rows are
        // left out.
        let n = 32;
        let hf = HeightField::from_fn(n, n, |i, j| if (i, j) == (0, 0) { 8.0 } else { 0.0 });
        let stripes = |x: usize| 0.1 + (x % 5) as f64 / 5.0;
        let m = BrdfMap {
            width: n,
            height: n,
            data: (0..n * n)
                .flat_map(|i| [stripes(i % n), stripes(i % n), stripes(i % n), 0.0, 0.2])
                .collect(),
        };
        let res = 64;
        let img = render(
            &hf,
            &m,
            &params(res as u32, 45.0, [0.0, 0.0, 1.0], 8.0 / n as f64),
            None,
        )
        .unwrap();
        let cam = Camera::new(&params(res as u32, 45.0, [0.0, 0.0, 1.0], 0.0).camera).unwrap();
        let mut checked = 0;
        for py in 0..res {
            for px in 0..res {
                let (o, d) = cam.ray(px as u32, py as u32);
                let t = -o[2] / d[2];
                let (wx, wy) = (o[0] + t * d[0], o[1] + t * d[1]);
                if wx.abs() > 0.49 || wy.abs() > 0.49 {
                    continue;
                }
                let (gx, gy) = ((wx + 0.5) * n as f64 - 0.5, (0.5 - wy) * n as f64 - 0.5);
                if (gy.rem_euclid(n as f64)) < 2.0 || gy.rem_euclid(n as f64) > n as f64 - 2.0 {
                    continue;
                }
                let fx = gx - 8.0;
                let i = fx.floor();
                let a = fx - i;
                let wrap = |k: f64| (k as i64).rem_euclid(n as i64) as usize;
                let want = ((1.0 - a) * stripes(wrap(i)) + a * stripes(wrap(i + 1.0)))
                    / std::f64::consts::PI;
                let got = img[3 * (py * res + px)] as f64;
                assert!(
                    (got - want).abs() < 1e-3,
                    "pixel ({px}, {py}): {got} vs {want}"
                );
                checked += 1;
            }
        }
        assert!(checked > 1000, "{checked}");
    }

    #[test]
    fn gpu_and_cpu_paths_agree() {
        // The same formulas in f32 on the GPU against f64 on the CPU: the search's comparisons can
        // flip at a step that grazes the surface and the rasteriser's edge rules differ at the
        // outline, so a few pixels may differ; bounds as render.mesh's agreement test (0.5% of
        // the pixels by more than 1% of the peak, mean difference 5e-4 of the peak).
        let n = 32;
        let (hf, m) = (bumps(n), maps(n));
        let (lo, hi) = hf.min_max();
        let mut p = params(96, 35.0, [0.5, 0.3, 0.8], (hi - lo) as f64 / n as f64);
        p.linear_steps = 24;
        p.binary_steps = 6;
        let cpu = render(&hf, &m, &p, None).unwrap();
        let mut tested = 0;
        for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
            let Ok(gpu) = mesoflow_runtime::Gpu::with_backends(backends) else {
                continue;
            };
            let name = gpu.describe();
            let g = match render(&hf, &m, &p, Some(Arc::new(gpu))) {
                Ok(g) => g,
                Err(e) if e.to_string().contains("cannot build") => {
                    mesoflow_testkit::skip(&format!("{name}: {e}"));
                    continue;
                }
                Err(e) => panic!("{name}: {e}"),
            };
            let peak = cpu.iter().fold(0f32, |a, b| a.max(*b));
            let (mut sum, mut differing) = (0f64, 0);
            for (a, b) in cpu.chunks_exact(3).zip(g.chunks_exact(3)) {
                let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0f32, f32::max);
                sum += d as f64;
                differing += usize::from(d > 0.01 * peak);
            }
            let pixels = cpu.len() / 3;
            let (mean, frac) = (
                sum / pixels as f64 / peak as f64,
                differing as f64 / pixels as f64,
            );
            eprintln!("{name}: mean |diff| {mean:.2e} of peak, {frac:.4} of pixels differ by > 1%");
            assert!(frac < 0.005, "{name}: {frac}");
            assert!(mean < 5e-4, "{name}: {mean}");
            tested += 1;
        }
        crate::support::gpu::require_tested(tested);
    }
}
