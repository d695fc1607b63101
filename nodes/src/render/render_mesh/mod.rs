//! `render.mesh`: a BTF-mapped mesh rendered with optional MDF silhouettes and shadows, into a
//! linear HDR image. The CPU path ray-casts the depth-peeled visibility layers and resolves them
//! with the shell test (`shade`); it is the reference for tests and the fallback without a GPU.
//! The GPU path (`gpu_render`) rasterises the same layers with depth peeling and resolves them
//! in a compute pass. `frame_ms` is wall time per frame (submit to completion, render targets
//! included) averaged over `frames` after an untimed first frame that also provides the image;
//! `gpu_ms` is the time between timestamps at the start of the first pass and the end of the
//! last, where the adapter supports timestamp queries.

use super::camera::{Camera, CameraParams};
use super::footprint;
use super::layers;
use super::light::{Light, LightParams};
use super::material::{Material, MdfLookup, Source};
use super::shade::{shell_sides, texel_aspect, Scene, ShadowMap};
use crate::geometry::{bounding_sphere, normalize, sub};
use crate::progress::Counter;
use crate::types::{Btf, BtfBasis, Image, Mdf, Mesh};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::Instant;

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Pinhole (`fov`) or orthographic camera, looking from `eye` at `target`.
    pub camera: CameraParams,
    /// A directional light, or a point light with `position`.
    pub light: LightParams,
    /// Texture tiles per unit of texture coordinate, [along u, along v].
    pub tiling: [f64; 2],
    /// Millimetres per world unit, for the footprint metric in mm (10⁻⁹ to 10⁹).
    #[schemars(range(min = 1e-9, max = 1e9))]
    pub mm_per_unit: f64,
    /// Shell thickness in world units: the depth the MDF's shell is mapped onto.
    #[schemars(range(min = 0.0))]
    pub shell: f64,
    /// Shadows from a shadow map of the (MDF-displaced) surface.
    pub shadows: bool,
    /// Shadow map size in texels (square).
    #[schemars(range(min = 1, max = 16384))]
    pub shadow_resolution: u32,
    /// Depth-peeling layers (2 covers a torus seen from most angles).
    #[schemars(range(min = 1, max = 8))]
    pub layers: u32,
    /// Linear RGB where no mesostructure is hit.
    pub background: [f64; 3],
    /// Use the `mdf` input when connected; false renders the plain mesh (for sweeps).
    pub use_mdf: bool,
    /// Look the BTF up at the hit's texel (offset by the MDF distance) rather than the entry
    /// texel. For BTFs rectified to the mesostructure; a BTF captured at the reference plane
    /// (`btf.capture`, measured data) already contains the parallax, so leave it off there.
    pub parallax: bool,
    /// Frames rendered for the timing metrics (the image is the last one).
    #[schemars(range(min = 1, max = 1000))]
    pub frames: u32,
    /// How sampled directions are interpolated: "rings" (bilinear between the bracketing rings
    /// of a ring-sampled set, the default) or "nearest" (the three nearest directions by
    /// inverse angle, what sets without rings always get; for comparisons).
    pub interpolation: Interpolation,
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

impl Default for Params {
    fn default() -> Self {
        Params {
            camera: CameraParams::default(),
            light: LightParams::default(),
            tiling: [4.0, 4.0],
            mm_per_unit: 10.0,
            shell: 0.05,
            shadows: false,
            shadow_resolution: 1024,
            layers: 2,
            background: [0.0; 3],
            use_mdf: true,
            parallax: false,
            frames: 1,
            interpolation: Interpolation::Rings,
        }
    }
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
            version: 5,
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
        Light::new(&p.light)?;
        for (name, v) in [
            ("tiling", p.tiling[0]),
            ("tiling", p.tiling[1]),
            ("shell", p.shell),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(NodeError::param(name, "must be finite and not negative"));
            }
        }
        if !(1e-9..=1e9).contains(&p.mm_per_unit) {
            return Err(NodeError::param("mm_per_unit", "must be in [1e-9, 1e9] mm"));
        }
        // Peeled layers hold a front and a back fragment per pixel and layer (40 bytes each,
        // twice while they are binned per tile): about 180 bytes per pixel and layer, for the
        // image and for the shadow map, whose texels cost as much as pixels.
        let per_texel = 180 * u64::from(p.layers.max(1)) + 16;
        let pixels = u64::from(w) * u64::from(h);
        let texels = if p.shadows {
            u64::from(p.shadow_resolution).pow(2)
        } else {
            0
        };
        crate::memory::check_param(
            pixels.saturating_mul(per_texel),
            &format!("a {w} × {h} render with {} layers", p.layers),
            "camera",
        )?;
        crate::memory::check_param(
            texels.saturating_mul(per_texel),
            &format!("a {0} × {0} shadow map", p.shadow_resolution),
            "shadow_resolution",
        )
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            ("frame_ms", "mean wall time per frame, ms"),
            ("gpu_ms", "mean GPU time per frame from timestamp queries, ms; absent where the adapter has none, and on the CPU"),
            ("fps", "frames per second (from frame_ms)"),
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
        let light = Light::new(&p.light)?;
        let degenerate = mesh.degenerate_triangles();
        if degenerate > 0 {
            ctx.warn(format!("{degenerate} zero-area triangles are skipped"));
        }
        let scene = Scene {
            mesh,
            material: &material,
            mdf: mdf_lookup,
            light,
            tiling: p.tiling,
            shell: p.shell,
            background: p.background,
            parallax: p.parallax,
            sides: shell_sides(mesh, p.shell),
            aspect: texel_aspect(mesh, p.tiling, p.shell, mdf),
        };
        let (data, mask, ms, gpu_ms) = match ctx.gpu() {
            Some(gpu) => render_gpu(ctx, gpu, &scene, &camera, p)?,
            None => {
                let start = Instant::now();
                let mut frame = (Vec::new(), Vec::new());
                // One counter for all frames: each frame's screen tiles add to its total.
                let watch = Counter::new(ctx, 0);
                for _ in 0..p.frames {
                    ctx.check_cancel()?;
                    frame = render_cpu(&scene, &camera, p, &watch)?;
                }
                let ms = start.elapsed().as_secs_f64() * 1e3 / p.frames as f64;
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

/// One frame on the CPU: (RGB data, mask).
pub fn render_cpu(
    scene: &Scene,
    camera: &Camera,
    p: &Params,
    watch: &Counter,
) -> Result<(Vec<f32>, Vec<f32>), NodeError> {
    let count = p.layers.max(1) as usize;
    let shadow = if p.shadows {
        if p.shadow_resolution == 0 || p.shadow_resolution > CPU_MAX_SIDE {
            return Err(NodeError::param(
                "shadow_resolution",
                format!("must be in 1..={CPU_MAX_SIDE}"),
            ));
        }
        let cam = shadow_camera(scene, p.shadow_resolution)?;
        let l = layers::trace(scene.mesh, &cam, count, watch);
        let radius = bounding_sphere(scene.mesh).1;
        Some(ShadowMap::build(scene, cam, &l, radius))
    } else {
        None
    };
    let l = layers::trace(scene.mesh, camera, count, watch);
    if watch.stopped() {
        return Err(NodeError::Cancelled);
    }
    let (w, h) = (camera.width as usize, camera.height as usize);
    let pixels: Vec<([f64; 3], bool)> = (0..w * h)
        .into_par_iter()
        .map(|px| {
            let (o, d) = camera.ray((px % w) as u32, (px / w) as u32);
            let colour = scene.shade(&l, px, o, d, shadow.as_ref());
            (colour.unwrap_or(scene.background), colour.is_some())
        })
        .collect();
    let mask = pixels.iter().map(|p| p.1 as u8 as f32).collect();
    let data = pixels
        .iter()
        .flat_map(|(c, _)| c.map(|v| v as f32))
        .collect();
    Ok((data, mask))
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
    let shadow = if p.shadows {
        GpuRenderer::check_size(
            gpu,
            "shadow_resolution",
            p.shadow_resolution,
            p.shadow_resolution,
        )?;
        let cam = shadow_camera(scene, p.shadow_resolution)?;
        let bias = super::shade::shadow_bias(bounding_sphere(scene.mesh).1, p.shadow_resolution);
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
    let (mut gpu_total, mut gpu_frames) = (0.0, 0);
    let start = Instant::now();
    for k in 0..timed {
        ctx.check_cancel()?;
        if let (_, Some(g)) = r.frame(camera, sc, count, false)? {
            gpu_total += g;
            gpu_frames += 1;
        }
        ctx.progress(k as u64 + 1, timed as u64);
    }
    let ms = start.elapsed().as_secs_f64() * 1e3 / timed as f64;
    let gpu_ms = (gpu_frames > 0).then(|| gpu_total / gpu_frames as f64);
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
mod tests {
    use super::*;
    use crate::btf::directions::DirectionSet;
    use crate::mesh::primitive::{build, Params as MeshParams, Shape};
    use crate::types::{Direction, DirectionPair, HeightField};
    use std::sync::Arc;

    /// A BTF with the given views × lights over `n`×`n` texels, values from a hash.
    pub(crate) fn test_btf(n: usize, views: &[[f64; 2]], lights: &[[f64; 2]]) -> Btf {
        let pairs: Vec<DirectionPair> = views
            .iter()
            .flat_map(|v| {
                lights.iter().map(|l| DirectionPair {
                    view: Direction::degrees(v[0], v[1]),
                    light: Direction::degrees(l[0], l[1]),
                })
            })
            .collect();
        let data = (0..pairs.len() * 3 * n * n)
            .map(|i| crate::rng::unit(crate::rng::hash(7, &[i as u64])) as f32)
            .collect();
        Btf {
            width: n,
            height: n,
            pairs,
            data,
        }
    }

    fn render(
        mesh: Mesh,
        btf: Arc<dyn mesoflow_runtime::Value>,
        mdf: Option<Mdf>,
        p: &Params,
    ) -> Result<(Image, f64), NodeError> {
        let ctx = NodeContext::detached(None);
        let mut inputs = Inputs::new().with("mesh", Arc::new(mesh)).with("btf", btf);
        if let Some(m) = mdf {
            inputs = inputs.with("mdf", Arc::new(m));
        }
        // As the engine does: the parameter checks (`prepare`), then the run.
        RenderMesh.check(p)?;
        let out = RenderMesh.run(&ctx, p, &inputs)?;
        let img = out
            .get("image")
            .unwrap()
            .as_any()
            .downcast_ref::<Image>()
            .unwrap()
            .clone();
        let cov = out.get("coverage").unwrap().as_scalar().unwrap();
        Ok((img, cov))
    }

    fn plane_params(n: u32) -> Params {
        Params {
            camera: CameraParams {
                eye: [0.0, 0.0, 5.0],
                target: [0.0, 0.0, 0.0],
                orthographic: Some(1.0),
                resolution: [n, n],
                ..Default::default()
            },
            light: LightParams {
                direction: [1.0, 0.0, 1.0],
                position: None,
                intensity: 1.0,
            },
            tiling: [1.0, 1.0],
            ..Default::default()
        }
    }

    fn plane() -> Mesh {
        build(&MeshParams {
            shape: Shape::Plane,
            size: 2.0,
            segments: [1, 1],
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn a_plane_seen_head_on_reproduces_the_btf_view_texel_for_texel() {
        // Orthographic, 1 pixel per texel, pixel centres on texel centres: the local view is
        // exactly (θ = 0) and the light exactly (45°, 0°), so the pixel is that pair's texel.
        let btf = test_btf(8, &[[0.0, 0.0], [30.0, 0.0]], &[[45.0, 0.0], [45.0, 90.0]]);
        let (img, cov) = render(plane(), Arc::new(btf.clone()), None, &plane_params(8)).unwrap();
        assert_eq!(cov, 1.0);
        let pair = btf
            .pairs
            .iter()
            .position(|p| p.view.theta == 0.0 && p.light.phi == 0.0)
            .unwrap();
        let plane = btf.pair_image(pair);
        for y in 0..8 {
            for x in 0..8 {
                for c in 0..3 {
                    let want = plane[c * 64 + y * 8 + x];
                    let got = img.data[(y * 8 + x) * 3 + c];
                    // f32 storage, f64 arithmetic: only the bilinear weights' rounding (~1e-16).
                    assert!(
                        (got - want).abs() < 1e-6,
                        "({x}, {y}, {c}): {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_full_rank_basis_renders_what_the_raw_btf_renders() {
        let btf = test_btf(
            8,
            &[[0.0, 0.0], [30.0, 0.0], [30.0, 180.0]],
            &[[45.0, 0.0], [20.0, 90.0]],
        );
        let ctx = NodeContext::detached(None);
        let p: crate::btf::pca::Params = serde_json::from_str(r#"{"rank": 18}"#).unwrap();
        let out = crate::btf::pca::Pca
            .run(&ctx, &p, &Inputs::new().with("btf", Arc::new(btf.clone())))
            .unwrap();
        let basis = out.get("basis").unwrap().clone();
        let mut params = plane_params(16);
        params.camera.orthographic = None;
        params.camera.eye = [0.4, 0.3, 2.0];
        let (raw, _) = render(plane(), Arc::new(btf), None, &params).unwrap();
        let (pca, _) = render(plane(), basis, None, &params).unwrap();
        // Full rank reconstructs the BTF to f32 rounding of the factors (~1e-6 of values ≤ 1).
        let max = raw
            .data
            .iter()
            .zip(&pca.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(max < 1e-4, "max difference {max}");
    }

    /// MDF of a flat tile sunk `depth` texels below the reference plane, at many views.
    fn sunken_mdf(depth: f64) -> Mdf {
        let hf = HeightField::from_fn(8, 8, |_, _| 0.0);
        let p = crate::mdf::tabulate::Params {
            views: DirectionSet::Rings {
                thetas: vec![
                    0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0, 85.0, 88.0, 89.5,
                ],
                phis: (0..8).map(|k| k as f64 * 45.0).collect(),
            },
            depth: Some(depth),
            ..Default::default()
        };
        let ctx = NodeContext::detached(None);
        let out = crate::mdf::tabulate::Tabulate
            .run(&ctx, &p, &Inputs::new().with("height", Arc::new(hf)))
            .unwrap();
        out.get("mdf")
            .unwrap()
            .as_any()
            .downcast_ref::<Mdf>()
            .unwrap()
            .clone()
    }

    fn sphere() -> Mesh {
        build(&MeshParams {
            shape: Shape::Sphere,
            size: 1.0,
            segments: [96, 48],
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn a_sunken_mdf_shrinks_the_sphere_outline_by_the_shell_test_amount() {
        // Closed form for the shell test on a sphere of radius R with a flat mesostructure at
        // depth T (d = T/cos θ at both faces): a ray at distance ρ from the centre hits iff its
        // chord 2√(R²−ρ²) exceeds 2T·R/√(R²−ρ²), i.e. ρ² < R(R − T). Orthographic, so the
        // covered area shrinks from πR² to πR(R − T): a fraction T/R of the plain disc.
        let btf = test_btf(4, &[[0.0, 0.0]], &[[0.0, 0.0]]);
        let mut p = plane_params(160);
        p.camera.orthographic = Some(1.1);
        p.shell = 0.1;
        let (_, plain) = render(sphere(), Arc::new(btf.clone()), None, &p).unwrap();
        let (_, zero) = render(sphere(), Arc::new(btf.clone()), Some(sunken_mdf(0.0)), &p).unwrap();
        assert_eq!(plain, zero, "a zero-depth MDF changes nothing");
        let (_, deep) = render(sphere(), Arc::new(btf), Some(sunken_mdf(4.0)), &p).unwrap();
        let lost = (plain - deep) / plain;
        eprintln!("plain coverage {plain}, with the MDF {deep}: lost fraction {lost}");
        // The MDF blends views between sampled rings (d = T/cos θ is convex in θ, so a blend
        // overestimates it slightly near the outline) and the disc's edge is pixelated
        // (160 px across: ~2% of the ring's area): 15% of the 10% covers both.
        assert!(
            (lost - 0.1).abs() < 0.015,
            "lost fraction {lost}, expected 0.1"
        );
    }

    #[test]
    fn an_open_planes_shell_has_sides_rays_leave_and_enter_by_on_cpu_and_gpu() {
        // Closed form: the 2 × 2 plane over a flat mesostructure at the shell's bottom (0.1 below
        // it), seen orthographically at 45° from +x. What shows is that bottom: a ray entering
        // the top at x reaches it at x − 0.1, so entries within 0.1 of the far edge leave
        // through the shell's far side and miss, and rays passing under the near edge enter
        // through its side and meet the bottom up to 0.1 beyond it. The outline is the plain
        // plane's moved by 0.1: 5% of its pixels lost at the far edge, 5% gained at the near
        // one. (Without side walls nothing was lost; with walls that only bounded rays from
        // the top, nothing was gained.)
        let btf = test_btf(8, &[[0.0, 0.0]], &[[0.0, 0.0]]);
        let p = Params {
            camera: CameraParams {
                eye: [3.0, 0.0, 3.0],
                target: [0.0, 0.0, 0.0],
                // Not 1.6: its rows' centres would run exactly along the walls at y = ±1,
                // where f32 and f64 decide a ray in the wall's plane differently.
                orthographic: Some(1.61),
                resolution: [200, 200],
                ..Default::default()
            },
            shell: 0.1,
            ..plane_params(200)
        };
        let mdf = sunken_mdf(4.0);
        let material = Material::new(Source::Raw(&btf));
        let mesh = plane();
        let scene = |with_mdf: bool| Scene {
            mesh: &mesh,
            material: &material,
            mdf: with_mdf.then(|| MdfLookup::new(&mdf)),
            light: Light::new(&p.light).unwrap(),
            tiling: p.tiling,
            shell: p.shell,
            background: p.background,
            parallax: false,
            sides: shell_sides(&mesh, p.shell),
            aspect: Vec::new(),
        };
        let cam = Camera::new(&p.camera).unwrap();
        let plain = render_cpu(&scene(false), &cam, &p, &Counter::none())
            .unwrap()
            .1;
        let deep = render_cpu(&scene(true), &cam, &p, &Counter::none())
            .unwrap()
            .1;
        let count = |f: &dyn Fn(usize) -> bool| (0..plain.len()).filter(|&i| f(i)).count() as f64;
        let area = count(&|i| plain[i] > 0.5);
        let lost = count(&|i| plain[i] > 0.5 && deep[i] <= 0.5) / area;
        let gained = count(&|i| plain[i] <= 0.5 && deep[i] > 0.5) / area;
        // The plane's edges are pixelated (about 141 pixels across at 45°: 0.7% of its width).
        assert!(
            (lost - 0.05).abs() < 0.01 && (gained - 0.05).abs() < 0.01,
            "lost {lost}, gained {gained}, expected 0.05 each"
        );
        // The GPU path carves and extends the same outline. Only a missing capability may skip a
        // backend, with its message; any other error fails, and under MESOFLOW_REQUIRE_GPU=1 at
        // least one adapter must have rendered it.
        let mut tested = 0;
        for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
            let Ok(gpu) = mesoflow_runtime::Gpu::with_backends(backends) else {
                continue;
            };
            let ctx = NodeContext::detached(None);
            match render_gpu(&ctx, &gpu, &scene(true), &cam, &p) {
                Ok((_, m, _, _)) => {
                    let differ = count(&|i| (m[i] > 0.5) != (deep[i] > 0.5)) / area;

                    assert!(
                        differ < 0.002,
                        "{}: {differ} of the pixels differ",
                        gpu.describe()
                    );
                    tested += 1;
                }
                Err(e) if e.to_string().contains("cannot render") => {
                    mesoflow_testkit::skip(&format!("{}: {e}", gpu.describe()));
                }
                Err(e) => panic!("{}: {e}", gpu.describe()),
            }
        }
        crate::gpu::require_tested(tested);
    }

    /// One orthographic pixel looking at the origin from 45° above +x.
    fn one_ray_at_45_degrees() -> Camera {
        Camera::new(&CameraParams {
            eye: [3.0, 0.0, 3.0],
            target: [0.0, 0.0, 0.0],
            orthographic: Some(0.01),
            resolution: [1, 1],
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn parallax_moves_the_lookup_by_the_mdf_offset() {
        // A 45° orthographic view (φ = 0) of the plane's centre over a flat MDF sunk 4 texels:
        // d = 4/cos 45° along the ray, i.e. 4 texels towards −u; on an 8-texel tile that is
        // Δu = −0.5. Without `parallax` the lookup stays at the entry texel.
        let mdf = sunken_mdf(4.0);
        let btf = test_btf(8, &[[0.0, 0.0]], &[[0.0, 0.0]]);
        let material = Material::new(Source::Raw(&btf));
        let mesh = plane();
        let cam = one_ray_at_45_degrees();
        let layers = super::layers::trace(&mesh, &cam, 1, &Counter::none());
        for (parallax, want_u) in [(false, 0.5), (true, 0.0)] {
            let scene = Scene {
                mesh: &mesh,
                material: &material,
                mdf: Some(MdfLookup::new(&mdf)),
                light: Light::new(&LightParams::default()).unwrap(),
                tiling: [1.0, 1.0],
                shell: 0.1,
                background: [0.0; 3],
                parallax,
                sides: Vec::new(),
                aspect: Vec::new(),
            };
            let (o, d) = cam.ray(0, 0);
            let (_, _, s, wo) = scene.hit(&layers, 0, o, d).unwrap();
            assert!((wo[0] - 0.5f64.sqrt()).abs() < 1e-9 && wo[1].abs() < 1e-9);
            assert!(
                (s.uv[0] - want_u).abs() < 1e-6 && (s.uv[1] - 0.5).abs() < 1e-6,
                "{:?}",
                s.uv
            );
        }
    }

    #[test]
    fn a_stretched_tile_is_looked_up_in_its_own_proportions() {
        // A 4 × 1 quad carrying one 8-texel tile (tiling 1) under a 0.5 shell over a flat
        // floor 4 texels deep: one texel of depth is 1/8 world unit, one texel across is 1/2
        // along u and 1/8 along v, so k = (1/4, 1). Seen at 45° along u, the ray meets the
        // floor 0.5 below the top, 0.5 world units (1/8 of the quad) further along u; with the
        // tile's own proportions ignored the parallax would move the lookup a full tile
        // width × 0.5 = 4× too far.
        let mdf = sunken_mdf(4.0);
        let btf = test_btf(8, &[[0.0, 0.0]], &[[0.0, 0.0]]);
        let material = Material::new(Source::Raw(&btf));
        let mut mesh = Mesh {
            positions: vec![
                [-2., -0.5, 0.],
                [2., -0.5, 0.],
                [2., 0.5, 0.],
                [-2., 0.5, 0.],
            ],
            uvs: vec![[0., 0.], [1., 0.], [1., 1.], [0., 1.]],
            indices: vec![0, 1, 2, 0, 2, 3],
            ..Default::default()
        };
        mesh.compute_normals();
        mesh.compute_tangents();
        let aspect = texel_aspect(&mesh, [1.0, 1.0], 0.5, Some(&mdf));
        for k in &aspect {
            assert!(
                (k[0] - 0.25).abs() < 1e-6 && (k[1] - 1.0).abs() < 1e-6,
                "{k:?}"
            );
        }
        let cam = one_ray_at_45_degrees();
        let layers = super::layers::trace(&mesh, &cam, 1, &Counter::none());
        let scene = Scene {
            mesh: &mesh,
            material: &material,
            mdf: Some(MdfLookup::new(&mdf)),
            light: Light::new(&LightParams::default()).unwrap(),
            tiling: [1.0, 1.0],
            shell: 0.5,
            background: [0.0; 3],
            parallax: true,
            sides: Vec::new(),
            aspect,
        };
        let (o, d) = cam.ray(0, 0);
        let (t, t_front, s, _) = scene.hit(&layers, 0, o, d).unwrap();
        // 0.5 below the top at 45°: 0.5·√2 along the ray. The tile sees the ray at 14° from
        // its normal, between the MDF's rings at 0° and 15°, whose blend of 4/cos θ (convex)
        // is 0.2% long there: 0.5% bounds it.
        assert!(
            (t - t_front - 0.5 * 2f64.sqrt()).abs() < 4e-3,
            "{}",
            t - t_front
        );
        assert!((s.uv[0] - (0.5 - 0.125)).abs() < 1e-3, "{:?}", s.uv);
    }

    #[test]
    fn missing_hits_grazing_views_and_few_directions_stay_finite() {
        let btf = test_btf(4, &[[0.0, 0.0]], &[[30.0, 0.0]]);
        let mut mdf = sunken_mdf(2.0);
        mdf.data
            .iter_mut()
            .step_by(3)
            .for_each(|d| *d = f32::INFINITY);
        let mut p = plane_params(32);
        p.camera.orthographic = None;
        p.camera.eye = [0.0, -3.0, 0.05]; // θ ≈ 89° over the plane
        p.camera.target = [0.0, 0.0, 0.0];
        p.camera.up = [0.0, 0.0, 1.0];
        let (img, _) = render(plane(), Arc::new(btf.clone()), Some(mdf.clone()), &p).unwrap();
        assert!(img.data.iter().all(|v| v.is_finite()));
        // An MDF that never hits shows only background.
        mdf.data.iter_mut().for_each(|d| *d = f32::INFINITY);
        let (img, cov) = render(
            sphere(),
            Arc::new(btf.clone()),
            Some(mdf),
            &plane_params(16),
        )
        .unwrap();
        assert_eq!(cov, 0.0);
        assert!(img.data.iter().all(|v| *v == 0.0));
        // 1×1 works; a huge image is refused, naming the camera.
        let mut p = plane_params(1);
        let (img, _) = render(plane(), Arc::new(btf.clone()), None, &p).unwrap();
        assert_eq!(img.data.len(), 3);
        p.camera.resolution = [100_000, 10];
        let e = render(plane(), Arc::new(btf), None, &p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("camera") && e.contains("100000"), "{e}");
    }

    #[test]
    fn degenerate_triangles_are_skipped_without_nan() {
        let btf = test_btf(4, &[[0.0, 0.0]], &[[30.0, 0.0]]);
        let mut m = plane();
        let n = m.positions.len() as u32;
        m.positions.push([0.0, 0.0, 0.5]);
        m.normals.push([0.0, 0.0, 1.0]);
        m.uvs.push([0.5, 0.5]);
        m.tangents.push([1.0, 0.0, 0.0, 1.0]);
        m.indices.extend_from_slice(&[n, n, n, 0, 0, 1]);
        let (img, cov) = render(m, Arc::new(btf), None, &plane_params(8)).unwrap();
        assert_eq!(cov, 1.0);
        assert!(img.data.iter().all(|v| v.is_finite()));
    }

    /// A woven tile's BTF (few directions) and MDF, as the graphs build them.
    fn woven(size: u32) -> (Btf, Mdf) {
        let ctx = NodeContext::detached(None);
        let hp = crate::heightfield::procedural::Params {
            pattern: crate::heightfield::procedural::Pattern::Weave,
            size,
            count: 2,
            ..Default::default()
        };
        let hf: mesoflow_runtime::ValueRef =
            Arc::new(crate::heightfield::procedural::generate(&ctx, &hp).unwrap());
        let dirs = r#"{"thetas": [0, 30, 60, 80], "phis": [0, 60, 120, 180, 240, 300]}"#;
        let cp: crate::btf::capture::Params =
            serde_json::from_str(&format!(r#"{{"views": {dirs}, "lights": {dirs}}}"#)).unwrap();
        let btf = crate::btf::capture::Capture
            .run(&ctx, &cp, &Inputs::new().with("height", hf.clone()))
            .unwrap()
            .get("btf")
            .unwrap()
            .as_any()
            .downcast_ref::<Btf>()
            .unwrap()
            .clone();
        let mp: crate::mdf::tabulate::Params =
            serde_json::from_str(&format!(r#"{{"views": {dirs}}}"#)).unwrap();
        let mdf = crate::mdf::tabulate::Tabulate
            .run(&ctx, &mp, &Inputs::new().with("height", hf))
            .unwrap()
            .get("mdf")
            .unwrap()
            .as_any()
            .downcast_ref::<Mdf>()
            .unwrap()
            .clone();
        (btf, mdf)
    }

    #[test]
    fn gpu_and_cpu_renders_agree_on_every_backend() {
        let (btf, mdf) = woven(16);
        let torus = build(&MeshParams {
            shape: Shape::Torus,
            size: 0.9,
            minor: 0.35,
            segments: [48, 24],
        })
        .unwrap();
        let mut p = Params {
            camera: CameraParams {
                eye: [0.0, 1.6, 2.4],
                resolution: [96, 72],
                ..Default::default()
            },
            // A low light, so the ring shadows its own inner side.
            light: LightParams {
                direction: [1.0, 0.45, 0.2],
                ..Default::default()
            },
            // A thick shell, so the MDF's silhouettes cover enough pixels to matter.
            shell: 0.25,
            shadows: true,
            shadow_resolution: 256,
            ..Default::default()
        };
        let scene_in = |gpu: Option<&mesoflow_runtime::Gpu>, with_mdf: bool, p: &Params| {
            let material = Material::new(Source::Raw(&btf));
            let scene = Scene {
                mesh: &torus,
                material: &material,
                mdf: with_mdf.then(|| MdfLookup::new(&mdf)),
                light: Light::new(&p.light).unwrap(),
                tiling: p.tiling,
                shell: p.shell,
                background: p.background,
                parallax: p.parallax,
                sides: shell_sides(&torus, p.shell),
                // The torus's tiles are squeezed inside and stretched outside: the GPU must
                // map directions into the tile's proportions as the CPU does.
                aspect: texel_aspect(&torus, p.tiling, p.shell, with_mdf.then_some(&mdf)),
            };
            let cam = Camera::new(&p.camera).unwrap();
            let ctx = NodeContext::detached(None);
            match gpu {
                Some(g) => {
                    render_gpu(&ctx, g, &scene, &cam, p).map(|(d, m, _, t)| (d, coverage(&m), t))
                }
                None => render_cpu(&scene, &cam, p, &Counter::none())
                    .map(|(d, m)| (d, coverage(&m), None)),
            }
        };
        // The MDF must matter in this scene, or agreement with it would prove nothing.
        let (plain, ..) = scene_in(None, false, &p).unwrap();
        let (meso, ..) = scene_in(None, true, &p).unwrap();
        let changed = plain
            .iter()
            .zip(&meso)
            .filter(|(a, b)| (*a - *b).abs() > 1e-3)
            .count();
        eprintln!(
            "the MDF changes {changed} of {} values (depth {}, mean {})",
            plain.len(),
            mdf.depth,
            mdf.data.iter().map(|v| *v as f64).sum::<f64>() / mdf.data.len() as f64
        );
        assert!(changed > plain.len() / 50);
        // Likewise the shadows: the near side of the ring shadows the inner wall across the hole
        // (a thin crescent at this resolution, 90 values when written).
        let mut lit = p.clone();
        lit.shadows = false;
        let (unshadowed, ..) = scene_in(None, true, &lit).unwrap();
        let darker = unshadowed
            .iter()
            .zip(&meso)
            .filter(|(a, b)| *a - *b > 1e-3)
            .count();
        eprintln!("shadows darken {darker} values");
        assert!(darker > plain.len() / 500);
        let mut tested = 0;
        for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
            let Ok(gpu) = mesoflow_runtime::Gpu::with_backends(backends) else {
                continue;
            };
            for (with_mdf, shadows, parallax) in [
                (false, false, false),
                (true, false, false),
                (true, true, false),
                (true, false, true),
            ] {
                p.shadows = shadows;
                p.parallax = parallax;
                let (cpu, cpu_cov, _) = scene_in(None, with_mdf, &p).unwrap();
                let (gpu_img, gpu_cov, gpu_ms) = match scene_in(Some(&gpu), with_mdf, &p) {
                    Ok(r) => r,
                    // Only a missing capability may skip a backend, and only with its message.
                    Err(e) if e.to_string().contains("cannot render") => {
                        mesoflow_testkit::skip(&format!("{}: {e}", gpu.describe()));
                        break;
                    }
                    Err(e) => panic!("{e}"),
                };
                let peak = cpu.iter().fold(0f32, |a, b| a.max(*b));
                let pixels = cpu.len() / 3;
                let (mut sum, mut differing) = (0f64, 0);
                for (a, b) in cpu.chunks_exact(3).zip(gpu_img.chunks_exact(3)) {
                    let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0f32, f32::max);
                    sum += d as f64;
                    if d > 0.01 * peak {
                        differing += 1;
                    }
                }
                let mean = sum / pixels as f64 / peak as f64;
                let frac = differing as f64 / pixels as f64;
                eprintln!(
                    "{} mdf {with_mdf} shadows {shadows} parallax {parallax}: coverage CPU {cpu_cov:.4} GPU {gpu_cov:.4}, mean |diff| {mean:.2e} of peak, {frac:.4} of pixels differ by > 1%, GPU time {gpu_ms:?} ms",
                    gpu.describe()
                );
                // Where they may differ: the rasteriser's edge rules vs the f64 ray–triangle test
                // at silhouettes and shared edges, f32 vs f64 at the shell test's threshold and the
                // shadow comparison. Those are isolated pixels along outlines: 0.5% of the pixels
                // and a mean difference of 5e-5 of the peak bound them (lavapipe measured 0
                // pixels and 5e-6; the README quotes these bounds), while a wrong frame, lookup
                // or layer breaks whole regions and fails both.
                assert!(frac < 0.005, "{}: {frac} of pixels differ", gpu.describe());
                assert!(mean < 5e-5, "{}: mean difference {mean}", gpu.describe());
                assert!((cpu_cov - gpu_cov).abs() < 0.01);
                // Timestamps where the device has them, and a positive time.
                let stamps = gpu
                    .device
                    .features()
                    .contains(wgpu::Features::TIMESTAMP_QUERY);
                assert_eq!(gpu_ms.is_some(), stamps);
                assert!(
                    gpu_ms.is_none_or(|t| t > 0.0 && t.is_finite()),
                    "{gpu_ms:?}"
                );
                tested += 1;
            }
            // Past the device's texture limit: a clear refusal naming the parameter.
            let mut huge = p.clone();
            huge.camera.resolution = [1 << 20, 8];
            let e = scene_in(Some(&gpu), false, &huge).unwrap_err().to_string();
            assert!(e.contains("camera") && e.contains("exceeds"), "{e}");
        }
        crate::gpu::require_tested(tested);
    }
}
