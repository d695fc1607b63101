//! `render.mesh`: a BTF-mapped mesh rendered with optional MDF silhouettes and shadows, into a
//! linear HDR image. The CPU path ray-casts the depth-peeled visibility layers and resolves them
//! with the shell test (`shade`); it is the reference for tests and the fallback without a GPU.
//! The GPU path (`gpu_render`) rasterises the same layers with depth peeling and resolves them
//! in a compute pass. `frame_ms` is wall time per frame (submit to completion, render targets
//! included), the median of `frames` (after an untimed first frame on the GPU that also provides
//! the image): one slow frame of several, a scheduler's hiccup, does not move it;
//! `gpu_ms` is the time between timestamps at the start of the first pass and the end of the
//! last, where the adapter supports timestamp queries. Under an environment light both paths
//! shade with `environment.rs`'s transfer and per-vertex lighting.

pub mod validity;

use super::environment::EnvShading;
use super::material::{Material, MdfLookup, Source};
use super::shade::{shell_sides, texel_aspect, PixelFootprint, Scene};
use crate::support::geometry::{bounding_sphere, normalize, sub};
use crate::support::progress::Counter;
use crate::support::raytrace::camera::Camera;
use crate::support::raytrace::footprint;
use crate::support::raytrace::layers;
use crate::support::raytrace::light::Light;
use crate::types::{Btf, BtfBasis, Image, Mdf, Mesh};
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
        view { camera, light, tiling, mm_per_unit, shadows, shadow_resolution, background }
        /// Shell thickness in world units: the depth the MDF's shell is mapped onto.
        #[schemars(range(min = 0.0))]
        pub shell: f64 = 0.05,
        /// Depth-peeling layers (2 covers a torus seen from most angles).
        #[schemars(range(min = 1, max = 8))]
        pub layers: u32 = 2,
        /// Use the `mdf` input when connected; false renders the plain mesh (for sweeps).
        pub use_mdf: bool = true,
        /// Look the BTF up at the hit's texel (offset by the MDF distance) rather than the entry
        /// texel. For BTFs rectified to the mesostructure; a BTF captured at the reference plane
        /// (`btf.capture`, measured data) already contains the parallax, so leave it off there.
        pub parallax: bool = false,
        /// Frames rendered for the timing metrics (the image is the last one).
        #[schemars(range(min = 1, max = 1000))]
        pub frames: u32 = 1,
        /// How sampled directions are interpolated: "rings" (bilinear between the bracketing rings
        /// of a ring-sampled set, the default) or "nearest" (the three nearest directions by
        /// inverse angle, what sets without rings always get; for comparisons).
        pub interpolation: Interpolation = Interpolation::Rings,
        /// Under an environment light: the spherical-harmonic bands the BTF and the environment
        /// are integrated in (`order`² functions; a pixel costs about that many directional
        /// lookups' arithmetic). See the BTF guide for the error each order leaves.
        #[schemars(range(min = 1, max = 12))]
        pub environment_order: u32 = 6,
        /// Read the BTF at the level of detail each pixel's footprint covers (box-filtered
        /// levels, blended between the two around it), so that a tile a few pixels wide is
        /// its mean, not an alias of one texel; false reads the texels themselves (the CPU
        /// path; the GPU path reads the texels themselves).
        pub footprint: bool = true,
    }
}

/// The direction interpolation of `render.mesh` (see `material.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// Bilinear in θ and φ between the bracketing rings, where the set has rings.
    #[default]
    Rings,
    /// The three nearest sampled directions, weighted by inverse angle.
    Nearest,
}

/// The largest image or shadow map the CPU path accepts, per side.
const CPU_MAX_SIDE: u32 = 16384;

pub struct RenderMesh;

impl Node for RenderMesh {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "render.mesh",
            // 3: the mask output; lights beyond the sampled cone extrapolated, not clamped.
            // 4: directions looked up in the tile's own proportions where the UVs stretch it,
            // the MDF's shadows, shell sides rays enter by. 5: light past the macro horizon.
            // 6: the validity warnings (images unchanged; a cache hit repeats the warnings its
            // entry stored, so older entries rerun once to have them). 7: environment lights, and
            // the BTF read at the pixel's footprint. 8: environment lights shaded on the GPU too.
            // 9: the footprint's half-size boxes read brilinearly.
            version: 9,
            doc: "BTF-mapped mesh with MDF silhouettes (shell test, depth peeling) and shadow maps; linear HDR image and the mask of the pixels that show mesostructure.",
            device: DevicePreference::Gpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the mesh, top of the mesostructure shell"),
                Port::any_of("btf", &[Btf::TYPE, BtfBasis::TYPE], "material: raw BTF or PCA basis"),
                Port::optional("mdf", Mdf::TYPE, "mesostructure distance function of the same tile"),
            ],
            outputs: [
                vec![
                    Port::output("image", Image::TYPE, "linear HDR RGB"),
                    Port::output("coverage", "Scalar", "fraction of pixels showing mesostructure"),
                    Port::output("mask", Image::TYPE, "1 where a pixel shows mesostructure, else 0 (one channel)"),
                ],
                footprint::output_ports(true),
            ]
            .concat(),
            disk_cache: true,
        }
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
        let [w, h] = p.camera.resolution;
        if w > CPU_MAX_SIDE || h > CPU_MAX_SIDE {
            return Err(NodeError::param(
                "camera",
                format!(
                    "resolution {w}×{h} exceeds the CPU renderer's {CPU_MAX_SIDE} pixels per side"
                ),
            ));
        }
        Light::check(&p.light)?;
        for (name, v) in [("tiling", p.tiling[0]), ("tiling", p.tiling[1])] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(NodeError::param(name, "must be finite and not negative"));
            }
        }
        if !(1e-9..=1e9).contains(&p.mm_per_unit) {
            return Err(NodeError::param("mm_per_unit", "must be in [1e-9, 1e9] mm"));
        }
        // Peeled layers hold a front and a back fragment per pixel and layer (40 bytes each,
        // twice while they are binned per tile): about 180 bytes per pixel and layer. The
        // shadow map is lazy: 8 bytes a texel where a frame touches every block of it.
        let per_texel = 180 * u64::from(p.layers.max(1)) + 16;
        let pixels = u64::from(w) * u64::from(h);
        let texels = if p.shadows {
            u64::from(p.shadow_resolution).pow(2)
        } else {
            0
        };
        crate::support::memory::check_param(
            pixels.saturating_mul(per_texel),
            &format!("a {w} × {h} render with {} layers", p.layers),
            "camera",
        )?;
        crate::support::memory::check_param(
            texels.saturating_mul(8),
            &format!("a {0} × {0} shadow map", p.shadow_resolution),
            "shadow_resolution",
        )
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            ("frame_ms", "wall time per frame, the median of `frames`, ms"),
            ("gpu_ms", "mean GPU time per frame from timestamp queries, ms; absent where the adapter has none, and on the CPU"),
            ("fps", "frames per second (from frame_ms)"),
            ("layers_ms", "the view's visibility layers, ms a frame: on the CPU ray-cast depth peeling (wall time), on the GPU the peel passes (GPU time, where the adapter has timestamp queries)"),
            ("shade_ms", "the shading pass (shell test, MDF and BTF lookups, shadows), ms a frame: on the CPU wall time (with the shadow texels it traces), on the GPU the resolve pass's GPU time"),
            ("shadow_ms", "GPU, shadows on: the shadow map's peel passes and resolve, GPU time, ms a frame"),
            ("shadow_setup_ms", "CPU, shadows on: binning the mesh for the light camera and allocating the lazy map, ms a frame"),
            ("shadow_thread_ms", "CPU, shadows on: time spent tracing shadow texels, summed over threads (its share of shade_ms × threads is the shadows' share), ms a frame"),
            ("shadow_texels", "CPU, shadows on: shadow-map texels traced a frame (the rest of the map is never traced)"),
            ("environment_ms", "under an environment light, once before the frames: the BTF's transfer and the mesh's lighting with its visibility, ms"),
        ]
    }
    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let value = inputs.value("btf")?;
        let source = if let Some(b) = value.as_any().downcast_ref::<Btf>() {
            Source::Raw(b)
        } else if let Some(b) = value.as_any().downcast_ref::<BtfBasis>() {
            b.check().map_err(|e| NodeError::input("btf", e))?;
            Source::Basis {
                basis: b,
                owners: b.column_owners(),
            }
        } else {
            return Err(NodeError::input("btf", "expected a Btf or a BtfBasis"));
        };
        let mut material = Material::new(source);
        let gpu = gpu_for(ctx, &material, mesh, p);
        // The GPU path reads the texels themselves: the levels are for the CPU's.
        let on_cpu = gpu.is_none();
        if p.footprint && on_cpu {
            crate::support::memory::check_param(
                match &material.source {
                    Source::Raw(b) => b.data.len() as u64 * 4 / 3,
                    Source::Basis { basis, .. } => basis
                        .blocks
                        .iter()
                        .map(|b| b.maps.len() as u64 * 4 / 3)
                        .sum(),
                },
                "the BTF's levels of detail",
                "footprint",
            )?;
            material = material.with_levels(1);
        }
        let mdf = inputs.opt::<Mdf>("mdf")?.filter(|_| p.use_mdf);
        let mut mdf_lookup = mdf.map(MdfLookup::new);
        if p.interpolation == Interpolation::Nearest {
            material.view_table = None;
            material.light_table = None;
            if let Some(m) = mdf_lookup.as_mut() {
                m.rings = None;
            }
        }
        let camera = Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
        let [w, h] = p.camera.resolution;
        let degenerate = mesh.degenerate_triangles();
        if degenerate > 0 {
            ctx.warn(format!("{degenerate} zero-area triangles are skipped"));
        }
        let validity = validity::measure(
            mesh,
            &p.camera,
            &p.light,
            p.tiling,
            validity::Sampled {
                texels: [material.width, material.height],
                views: &material.views,
                lights: &material.lights,
            },
        );
        for w in validity.warnings(mdf_lookup.is_some().then_some(p.shell)) {
            ctx.warn(w);
        }
        let light = Light::open(&p.light, ctx)?;
        let mut scene = scene_for(mesh, &material, mdf_lookup, p, light.clone())?;
        if p.footprint && on_cpu {
            scene.footprint = Some(PixelFootprint::new(
                mesh,
                &camera,
                p.tiling,
                [material.width, material.height],
            ));
        }
        if let Some(env) = light.env() {
            let start = Instant::now();
            let tracer = crate::support::raytrace::tracer::Tracer::in_context(mesh, Some(ctx));
            scene.env = Some(EnvShading::new(
                &material,
                mesh,
                &tracer,
                env,
                p.environment_order as usize,
            )?);
            ctx.timing("environment_ms", start.elapsed().as_secs_f64() * 1e3);
        }
        let (data, mask, ms, gpu_ms) = match gpu {
            Some(gpu) => render_gpu(ctx, gpu, &scene, &camera, p)?,
            None => {
                let mut frame = (Vec::new(), Vec::new());
                let mut stages = Stages::default();
                // One counter for all frames: each frame's screen tiles add to its total.
                let watch = Counter::new(ctx, 0);
                let mut times = Vec::new();
                for _ in 0..p.frames {
                    ctx.check_cancel()?;
                    let started = Instant::now();
                    let (data, mask, s) = render_cpu_stages(&scene, &camera, p, &watch)?;
                    times.push(started.elapsed().as_secs_f64() * 1e3);
                    frame = (data, mask);
                    stages.add(&s);
                }
                let ms = median_ms(times);
                stages.record(ctx, p.frames, p.shadows);
                (frame.0, frame.1, ms, None)
            }
        };
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(NodeError::Failed(format!(
                "pixel {} is not finite: a bug, please report it with the graph",
                i / 3
            )));
        }
        ctx.timing("frame_ms", ms);
        ctx.timing("fps", 1e3 / ms.max(1e-9));
        if let Some(gpu_ms) = gpu_ms {
            ctx.timing("gpu_ms", gpu_ms);
        }
        let texture = footprint::Texture {
            tiling: p.tiling,
            texels: [material.width, material.height],
        };
        let fp = footprint::footprint(mesh, &camera, Some(texture), p.mm_per_unit);
        let out = Outputs::new()
            .with(
                "image",
                Image {
                    width: w as usize,
                    height: h as usize,
                    channels: 3,
                    data,
                },
            )
            .with("coverage", Scalar(coverage(&mask)))
            .with(
                "mask",
                Image {
                    width: w as usize,
                    height: h as usize,
                    channels: 1,
                    data: mask,
                },
            );
        Ok(footprint::with_metrics(out, fp.as_ref()))
    }
}

/// The scene `p` describes: the mesh as the top of its shell, the material, the MDF's lookup
/// (the tile's proportions come from the MDF it reads), the light, the shell's side walls (an
/// environment's shading is added by the caller).
pub fn scene_for<'a>(
    mesh: &'a Mesh,
    material: &'a Material<'a>,
    mdf: Option<MdfLookup<'a>>,
    p: &Params,
    light: Light,
) -> Result<Scene<'a>, NodeError> {
    let aspect = texel_aspect(mesh, p.tiling, p.shell, mdf.as_ref().map(|m| m.mdf));
    Ok(Scene {
        mesh,
        material,
        mdf,
        light,
        tiling: p.tiling,
        shell: p.shell,
        background: p.background,
        parallax: p.parallax,
        sides: shell_sides(mesh, p.shell),
        aspect,
        env: None,
        footprint: None,
    })
}

/// The shadow camera: orthographic along a directional light, a pinhole at a point light.
pub fn shadow_camera(scene: &Scene, size: u32) -> Result<Camera, NodeError> {
    let (c, r) = bounding_sphere(scene.mesh);
    let (dir, from) = match scene.light.position {
        Some(lp) => (
            normalize(sub(c, lp)).ok_or_else(|| {
                NodeError::param("light", "the point light is at the mesh's centre")
            })?,
            Some(lp),
        ),
        None => (scene.light.direction.map(|v| -v), None),
    };
    Camera::enclosing(c, r, dir, from, size).map_err(|e| NodeError::param("light", e))
}

/// The fraction of a mask's pixels that are set.
pub fn coverage(mask: &[f32]) -> f64 {
    mask.iter().filter(|m| **m > 0.5).count() as f64 / mask.len().max(1) as f64
}

/// What one CPU frame spent, by stage: the view's visibility layers, binning the mesh for the
/// light camera (with shadows), and the shading pass (the shell test, MDF and BTF lookups, and
/// the shadow texels traced on first use, whose time summed over threads is `shadow_thread_ms`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Stages {
    pub layers_ms: f64,
    pub shadow_setup_ms: f64,
    pub shade_ms: f64,
    pub shadow_thread_ms: f64,
    pub shadow_texels: u64,
}

impl Stages {
    /// The stages as the report's timings (the names `timings()` declares).
    fn record(&self, ctx: &NodeContext, frames: u32, shadows: bool) {
        let n = frames.max(1) as f64;
        ctx.timing("layers_ms", self.layers_ms / n);
        ctx.timing("shade_ms", self.shade_ms / n);
        if shadows {
            ctx.timing("shadow_setup_ms", self.shadow_setup_ms / n);
            ctx.timing("shadow_thread_ms", self.shadow_thread_ms / n);
            ctx.timing("shadow_texels", self.shadow_texels as f64 / n);
        }
    }

    fn add(&mut self, o: &Stages) {
        self.layers_ms += o.layers_ms;
        self.shadow_setup_ms += o.shadow_setup_ms;
        self.shade_ms += o.shade_ms;
        self.shadow_thread_ms += o.shadow_thread_ms;
        self.shadow_texels += o.shadow_texels;
    }
}

/// One frame on the CPU: (RGB data, mask).
pub fn render_cpu(
    scene: &Scene,
    camera: &Camera,
    p: &Params,
    watch: &Counter,
) -> Result<(Vec<f32>, Vec<f32>), NodeError> {
    render_cpu_stages(scene, camera, p, watch).map(|(d, m, _)| (d, m))
}

/// One frame on the CPU: (RGB data, mask, the time each stage took).
pub fn render_cpu_stages(
    scene: &Scene,
    camera: &Camera,
    p: &Params,
    watch: &Counter,
) -> Result<(Vec<f32>, Vec<f32>, Stages), NodeError> {
    let count = p.layers.max(1) as usize;
    let mut stages = Stages::default();
    let clock = Instant::now();
    // Under an environment the mesh's shadows are in its lighting.
    let shadow_cam = if p.shadows && scene.env.is_none() {
        if p.shadow_resolution == 0 || p.shadow_resolution > CPU_MAX_SIDE {
            return Err(NodeError::param(
                "shadow_resolution",
                format!("must be in 1..={CPU_MAX_SIDE}"),
            ));
        }
        Some(shadow_camera(scene, p.shadow_resolution)?)
    } else {
        None
    };
    let binned = shadow_cam
        .as_ref()
        .map(|cam| layers::Binned::new(scene.mesh, cam));
    let shadow = binned
        .as_ref()
        .map(|b| scene.shadow_map(b, count, bounding_sphere(scene.mesh).1));
    stages.shadow_setup_ms = clock.elapsed().as_secs_f64() * 1e3;

    let clock = Instant::now();
    let l = layers::trace(scene.mesh, camera, count, watch);
    if watch.stopped() {
        return Err(NodeError::Cancelled);
    }
    stages.layers_ms = clock.elapsed().as_secs_f64() * 1e3;

    let clock = Instant::now();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let pixels: Vec<([f64; 3], bool)> = (0..w * h)
        .into_par_iter()
        .map(|px| {
            let (o, d) = camera.ray((px % w) as u32, (px / w) as u32);
            let colour = scene.shade(&l, px, o, d, shadow.as_ref());
            (colour.unwrap_or(scene.background), colour.is_some())
        })
        .collect();
    stages.shade_ms = clock.elapsed().as_secs_f64() * 1e3;
    if let Some(s) = &shadow {
        stages.shadow_thread_ms = s.thread_ms();
        stages.shadow_texels = s.traced();
    }
    let mask = pixels.iter().map(|p| p.1 as u8 as f32).collect();
    let data = pixels
        .iter()
        .flat_map(|(c, _)| c.map(|v| v as f32))
        .collect();
    Ok((data, mask, stages))
}

/// The median of frame times, ms (the mean of the middle two of an even count).
fn median_ms(mut times: Vec<f64>) -> f64 {
    times.sort_by(f64::total_cmp);
    match times.len() {
        0 => 0.0,
        n if n % 2 == 1 => times[n / 2],
        n => 0.5 * (times[n / 2 - 1] + times[n / 2]),
    }
}

/// The GPU the node renders on, if any: under an environment light only where the adapter can
/// hold the transfer and the lighting in one storage buffer (otherwise the CPU, with a warning
/// naming the sizes).
fn gpu_for<'c>(
    ctx: &'c NodeContext,
    material: &Material,
    mesh: &Mesh,
    p: &Params,
) -> Option<&'c mesoflow_runtime::Gpu> {
    let gpu = ctx.gpu()?;
    if !p.light.is_environment() {
        return Some(gpu);
    }
    let bytes = super::environment::gpu_bytes(
        material.width * material.height,
        material.views.len(),
        mesh.positions.len(),
        p.environment_order as usize,
    );
    let limit = gpu.device.limits().max_storage_buffer_binding_size;
    if bytes > limit {
        let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
        ctx.warn(format!(
            "the environment's transfer and lighting take {:.0} MiB, over {}'s storage buffer limit of {:.0} MiB: rendered on the CPU (a lower environment_order or a smaller BTF fits)",
            mib(bytes),
            gpu.describe(),
            mib(limit)
        ));
        return None;
    }
    Some(gpu)
}

/// A rendered frame on the GPU: RGB data, mask, wall ms per frame, GPU ms per frame from
/// timestamp queries where the device has them.
type GpuFrame = (Vec<f32>, Vec<f32>, f64, Option<f64>);

/// `frames` frames on the GPU.
pub fn render_gpu(
    ctx: &NodeContext,
    gpu: &mesoflow_runtime::Gpu,
    scene: &Scene,
    camera: &Camera,
    p: &Params,
) -> Result<GpuFrame, NodeError> {
    use super::gpu_render::GpuRenderer;
    GpuRenderer::check_size(gpu, "camera", camera.width, camera.height)?;
    // Under an environment the mesh's shadows are in its lighting.
    let shadow = if p.shadows && scene.env.is_none() {
        GpuRenderer::check_size(
            gpu,
            "shadow_resolution",
            p.shadow_resolution,
            p.shadow_resolution,
        )?;
        let cam = shadow_camera(scene, p.shadow_resolution)?;
        let bias = crate::support::raytrace::shadow::shadow_bias(
            bounding_sphere(scene.mesh).1,
            p.shadow_resolution,
        );
        Some((cam, bias))
    } else {
        None
    };
    let r = GpuRenderer::new(gpu, scene)?;
    let count = p.layers.max(1);
    let sc = shadow.as_ref().map(|(c, b)| (c, *b));
    // A first frame compiles pipelines, warms caches and provides the image; the timed frames
    // render the same image without reading it back.
    let (rgba, _) = r.frame(camera, sc, count, true)?;
    let timed = p.frames.max(1);
    let mut stages: Vec<super::gpu_render::GpuStages> = Vec::new();
    let mut times = Vec::new();
    for k in 0..timed {
        ctx.check_cancel()?;
        let started = Instant::now();
        if let (_, Some(g)) = r.frame(camera, sc, count, false)? {
            stages.push(g);
        }
        times.push(started.elapsed().as_secs_f64() * 1e3);
        ctx.progress(k as u64 + 1, timed as u64);
    }
    let ms = median_ms(times);
    // The same stage breakdown as the CPU path's, in GPU time (means over the timed frames).
    let mean = |f: &dyn Fn(&super::gpu_render::GpuStages) -> f64| {
        stages.iter().map(f).sum::<f64>() / stages.len().max(1) as f64
    };
    if !stages.is_empty() {
        ctx.timing("layers_ms", mean(&|s| s.layers_ms));
        ctx.timing("shade_ms", mean(&|s| s.shade_ms));
        if shadow.is_some() {
            ctx.timing("shadow_ms", mean(&|s| s.shadow_ms.unwrap_or(0.0)));
        }
    }
    let gpu_ms = (!stages.is_empty()).then(|| mean(&|s| s.total_ms));
    let mask = rgba
        .chunks_exact(4)
        .map(|c| (c[3] > 0.5) as u8 as f32)
        .collect();
    let data = rgba
        .chunks_exact(4)
        .flat_map(|c| [c[0], c[1], c[2]])
        .collect();
    Ok((data, mask, ms, gpu_ms))
}

#[cfg(test)]
mod tests;
