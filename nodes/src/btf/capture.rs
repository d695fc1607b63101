//! `btf.capture`: a synthetic BTF measurement of a periodic mesostructure tile, the built-in data
//! source. For every (view, light) pair and output texel, an orthographic view ray enters the
//! reference plane (the top of the mesostructure shell) at the texel and is cast down through the
//! periodic height field to its first hit (masking and parallax); the hit is shaded with the BRDF
//! and a shadow ray is cast to the directional light (self-shadowing). A view ray's hit does not
//! depend on the light, so each is cast once for all the lights of its view.
//!
//! Radiometry: the light has unit irradiance on a plane facing it, so a value is
//! f(ωi, ωo) · max(0, n·ωi) · visibility — for a flat Lambertian tile, ρ/π · cos θi.
//!
//! With `bounces` = N > 0 the capture also holds the light that reflects between the tile's
//! walls up to N more times before it leaves towards the viewer (`interreflect.rs`): a final
//! gather of `bounce_rays` seeded rays per height-field sample, cast once for all lights.

use super::directions::{DirectionSet, Named};
use super::interreflect::{self, Transport};
use crate::heightfield::raycast::{Caster, Miss};
use crate::reflectance::models::{self as brdf, Lobe, Model};
use crate::types::{BrdfMap, Btf, Direction, DirectionPair, HeightField, Image, WARD_PARAMS};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// View directions: "ubo81", {"thetas": [...], "phis": [...]} or [[θ, φ], ...], degrees.
    pub views: DirectionSet,
    /// Light directions, in the same forms as `views`.
    pub lights: DirectionSet,
    /// Output width in texels (height in proportion); default: the height field's width.
    #[schemars(range(min = 1, max = 8192))]
    pub resolution: Option<u32>,
    /// Reflectance model.
    pub brdf: Model,
    /// Diffuse albedo (linear RGB) when no `albedo` image is connected.
    pub albedo: [f64; 3],
    /// Specular albedo ρs (Ward), or the lobe's weight (GGX: 1 is the physical lobe).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub specular: f64,
    /// Roughness α (Ward: RMS slope of the microfacets; GGX: its α; anisotropic Ward: αu,
    /// along the image's x axis).
    #[schemars(range(min = 0.001, max = 1.0))]
    pub roughness: f64,
    /// Anisotropic Ward's αv, along the image's y axis; default: `roughness`.
    #[schemars(range(min = 0.001, max = 1.0))]
    pub roughness_v: Option<f64>,
    /// GGX: the refractive index of Schlick's Fresnel term (1.5: F0 = 0.04).
    #[schemars(range(min = 1.0, max = 10.0))]
    pub ior: f64,
    /// View direction [θ, φ] of the `preview` output (the nearest captured pair is shown).
    pub preview_view: [f64; 2],
    /// Light direction [θ, φ] of the `preview` output.
    pub preview_light: [f64; 2],
    /// Refuse a BTF larger than this (GB); default: 80% of physical memory.
    pub memory_budget_gb: Option<f64>,
    /// View rays per texel along each axis, averaged: a camera's pixel integrates its whole
    /// texel, so thin lit slivers on steep slopes under grazing light count by their area. 1
    /// (the default) samples the texel's centre only.
    #[schemars(range(min = 1, max = 16))]
    pub samples: u32,
    /// Diffuse interreflections inside the tile: how many more times light may reflect between
    /// its walls after the direct bounce. 0 (the default) holds the direct bounce only.
    #[schemars(range(min = 0, max = 32))]
    pub bounces: u32,
    /// With `bounces` > 0: gather rays per height-field sample (cosine-distributed, seeded);
    /// the indirect light's noise falls as 1/√rays.
    #[schemars(range(min = 1, max = 4096))]
    pub bounce_rays: u32,
    /// With `bounces` > 0: samples of the interreflections' grid per height-field sample along
    /// each axis (1 to 8); default: the steepest rise between neighbouring samples, in texels,
    /// rounded up, at most 4 (a wall several texels high within one cell needs a finer grid).
    #[schemars(range(min = 1, max = 8))]
    pub bounce_grid: Option<u32>,
    /// Seed of the gather rays.
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            views: DirectionSet::Named(Named::Ubo81),
            lights: DirectionSet::Named(Named::Ubo81),
            resolution: None,
            brdf: Model::Lambert,
            albedo: [0.6, 0.6, 0.6],
            specular: 0.05,
            roughness: 0.2,
            roughness_v: None,
            ior: 1.5,
            preview_view: [0.0, 0.0],
            preview_light: [45.0, 0.0],
            memory_budget_gb: None,
            samples: 1,
            bounces: 0,
            bounce_rays: 64,
            bounce_grid: None,
            seed: 1,
        }
    }
}

pub struct Capture;

impl Node for Capture {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.capture",
            // 2: GGX and anisotropic Ward, per-texel `maps`; Ward's half vector normalised first
            // (the same value, other rounding). (`bounces` 0, the default, is version 2's BTF.)
            version: 2,
            doc: "Synthetic BTF of a periodic height field: view rays with masking and parallax, shadow rays, and optionally diffuse interreflections between the tile's walls; Lambert, Ward, anisotropic Ward or GGX with Fresnel, constant or per texel.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("height", HeightField::TYPE, "mesostructure tile, heights in texels"),
                Port::optional("albedo", Image::TYPE, "diffuse albedo map, same size as the height field"),
                Port::optional("maps", BrdfMap::TYPE, "per-texel ρd RGB, ρs, α (brdf.fit_ward's, or edited), same size; replaces albedo, specular and roughness"),
            ],
            outputs: vec![
                Port::output("btf", Btf::TYPE, "the captured BTF"),
                Port::output("preview", Image::TYPE, "the pair nearest (preview_view, preview_light)"),
                Port::optional_output("trapped", "Scalar", "share of the interreflection gather's rays that met the tile again: how much the mesostructure sees of itself (absent without bounces)"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        for (name, set) in [("views", &p.views), ("lights", &p.lights)] {
            set.validate().map_err(|e| NodeError::param(name, e))?;
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let hf = inputs.get::<HeightField>("height")?;
        let maps = inputs.opt::<BrdfMap>("maps")?;
        let (albedo, lobe_maps) = match maps {
            None => (
                albedo_planes(inputs.opt::<Image>("albedo")?, hf, p.albedo)?,
                None,
            ),
            Some(_) if inputs.opt::<Image>("albedo")?.is_some() => {
                return Err(NodeError::input(
                    "albedo",
                    "connect `albedo` or `maps`, not both",
                ));
            }
            Some(m) => map_planes(m, hf)?,
        };
        let width = p.resolution.map_or(hf.width, |r| r as usize);
        let height = ((width * hf.height) as f64 / hf.width as f64)
            .round()
            .max(1.0) as usize;
        let views = p.views.directions();
        let lights = p.lights.directions();
        let pairs: Vec<DirectionPair> = views
            .iter()
            .flat_map(|&view| {
                lights
                    .iter()
                    .map(move |&light| DirectionPair { view, light })
            })
            .collect();
        let bytes = pairs.len() as u128 * 3 * (width * height) as u128 * 4;
        if bytes > isize::MAX as u128 {
            return Err(NodeError::param(
                "resolution",
                format!("the BTF would need {bytes} bytes"),
            ));
        }
        let mut scene = Scene::new(hf, albedo, lobe_maps, p);
        let plane = width * height;
        // With bounces: the lights' light over the transport grid (three arrays of lights × RGB
        // f32 per sample) and the gather (12 bytes a ray cast, then up to 4 merged entries of 8).
        let grid = match p.bounces {
            0 => 1,
            _ => p
                .bounce_grid
                .unwrap_or_else(|| interreflect::default_grid(hf)) as u64,
        };
        let samples = (hf.width * hf.height) as u64 * grid * grid;
        let transport = if p.bounces > 0 {
            lights.len() as u64 * samples * 36 + samples * p.bounce_rays as u64 * 44
        } else {
            0
        };
        crate::support::memory::check(
            (pairs.len() * 3 * plane * 4) as u64 + transport,
            &format!("a BTF of {} pairs × {plane} texels × RGB f32", pairs.len()),
            p.memory_budget_gb,
        )?;
        if p.bounces > 0 {
            scene.indirect = Some(Transport::solve(
                ctx,
                hf,
                &scene.albedo,
                &lights,
                p.bounces as usize,
                p.bounce_rays as usize,
                grid as usize,
                p.seed,
            )?);
        }
        let trapped = scene.indirect.as_ref().map(|t| t.trapped);
        let mut data = vec![0f32; pairs.len() * 3 * plane];
        let (done, missed) = (AtomicU64::new(0), AtomicU64::new(0));
        let scale = (
            hf.width as f64 / width as f64,
            hf.height as f64 / height as f64,
        );
        // View-major pairs: each view's lights are one run of planes, rendered from the view
        // rays' hits found once for all its lights.
        data.par_chunks_mut(3 * plane * lights.len().max(1))
            .zip(&views)
            .try_for_each(|(out, &view)| {
                ctx.check_cancel()?;
                let m = scene.render_view(
                    ctx,
                    view,
                    &lights,
                    (width, height),
                    scale,
                    p.samples as usize,
                    out,
                )?;
                missed.fetch_add(m, Ordering::Relaxed);
                let n = lights.len() as u64;
                ctx.progress(done.fetch_add(n, Ordering::Relaxed) + n, pairs.len() as u64);
                Ok::<(), NodeError>(())
            })?;
        let missed = missed.into_inner();
        if missed > 0 {
            ctx.warn(format!(
                "{missed} view rays travelled {} texels without meeting the surface (near-horizontal views); those texels are black",
                scene.caster.max_distance
            ));
        }
        let btf = Btf {
            width,
            height,
            pairs,
            data,
        };
        let want_view = Direction::degrees(p.preview_view[0], p.preview_view[1]);
        let want_light = Direction::degrees(p.preview_light[0], p.preview_light[1]);
        let preview = btf.preview(btf.nearest_pair(&want_view, &want_light).unwrap_or(0));
        let mut out = Outputs::new().with("btf", btf).with("preview", preview);
        if let Some(t) = trapped {
            out = out.with("trapped", mesoflow_runtime::Scalar(t));
        }
        Ok(out)
    }
}

/// The albedo as three planes over the height field's samples.
fn albedo_planes(
    img: Option<&Image>,
    hf: &HeightField,
    constant: [f64; 3],
) -> Result<[Vec<f32>; 3], NodeError> {
    let n = hf.width * hf.height;
    let Some(img) = img else {
        return Ok(constant.map(|c| vec![c as f32; n]));
    };
    if (img.width, img.height) != (hf.width, hf.height) {
        return Err(NodeError::input(
            "albedo",
            format!(
                "is {}×{}, the height field {}×{}; they must match",
                img.width, img.height, hf.width, hf.height
            ),
        ));
    }
    let c = img.channels;
    Ok([0, 1, 2].map(|k| (0..n).map(|i| img.data[i * c + k.min(c - 1)]).collect()))
}

/// Per-texel Ward maps as albedo planes and (ρs, α) pairs.
#[allow(clippy::type_complexity)]
fn map_planes(
    m: &BrdfMap,
    hf: &HeightField,
) -> Result<([Vec<f32>; 3], Option<Vec<[f32; 2]>>), NodeError> {
    if (m.width, m.height) != (hf.width, hf.height) {
        return Err(NodeError::input(
            "maps",
            format!(
                "are {}×{}, the height field {}×{}; they must match",
                m.width, m.height, hf.width, hf.height
            ),
        ));
    }
    if let Some(i) = m.data.iter().position(|v| !v.is_finite()) {
        let px = i / WARD_PARAMS;
        return Err(NodeError::input(
            "maps",
            format!(
                "texel ({}, {}) has a non-finite parameter",
                px % m.width,
                px / m.width
            ),
        ));
    }
    let n = m.width * m.height;
    // A lobe outside these bounds is not a reflectance: ρs > 1 reflects more than arrives (and at
    // α → 0 overflows to infinity), α ≤ 0 has no normalisation.
    if let Some(i) = (0..n).find(|&i| !(0.0..=1.0).contains(&m.pixel(i)[3]) || m.pixel(i)[4] <= 0.0)
    {
        return Err(NodeError::input(
            "maps",
            format!(
                "texel ({}, {}) has ρs = {}, α = {}: a Ward lobe needs ρs in [0, 1] and α > 0",
                i % m.width,
                i / m.width,
                m.pixel(i)[3],
                m.pixel(i)[4]
            ),
        ));
    }
    let planes = [0, 1, 2].map(|c| (0..n).map(|i| m.pixel(i)[c] as f32).collect());
    let lobes = (0..n)
        .map(|i| [m.pixel(i)[3] as f32, m.pixel(i)[4].max(1e-3) as f32])
        .collect();
    Ok((planes, Some(lobes)))
}

/// The mesostructure as the shader sees it: surface, smooth normals, albedo, BRDF.
struct Scene<'a> {
    caster: Caster<'a>,
    top: f64,
    hf: &'a HeightField,
    /// Central-difference gradients at the samples, interpolated bilinearly for smooth shading.
    grad: Vec<[f32; 2]>,
    albedo: [Vec<f32>; 3],
    /// The lobe, where no per-texel maps are given.
    lobe: Lobe,
    /// Per-sample (ρs, α) from `maps`; αv keeps the lobe's αv/α ratio.
    lobe_maps: Option<Vec<[f32; 2]>>,
    /// With `bounces`: every light's indirect irradiance over the tile.
    indirect: Option<Transport>,
}

impl<'a> Scene<'a> {
    fn new(
        hf: &'a HeightField,
        albedo: [Vec<f32>; 3],
        lobe_maps: Option<Vec<[f32; 2]>>,
        p: &Params,
    ) -> Self {
        let grad = hf.gradients();
        Scene {
            caster: Caster::new(hf),
            top: hf.min_max().1 as f64,
            hf,
            grad,
            albedo,
            lobe: Lobe {
                model: p.brdf,
                rho_s: p.specular,
                alpha: p.roughness,
                alpha_v: p.roughness_v.unwrap_or(p.roughness),
                ior: p.ior,
            },
            lobe_maps,
            indirect: None,
        }
    }

    /// Bilinear, periodic interpolation of per-texel values at grid point (x, y).
    fn lerp<const K: usize>(&self, x: f64, y: f64, at: impl Fn(usize) -> [f32; K]) -> [f64; K] {
        crate::heightfield::grid::bilerp(self.hf.width, self.hf.height, x, y, at)
    }

    /// Renders one view's pairs (one per light, in order) into `out`, three planes each, each
    /// texel the mean of `samples`² view rays on a grid over it; returns the number of view
    /// rays that missed, counted once per light. The view rays are cast once for all lights,
    /// a block of rows at a time, and the lights shade the block in parallel; a cancelled run
    /// stops between blocks.
    #[allow(clippy::too_many_arguments)]
    fn render_view(
        &self,
        ctx: &NodeContext,
        view: Direction,
        lights: &[Direction],
        (width, height): (usize, usize),
        (sx, sy): (f64, f64),
        samples: usize,
        out: &mut [f32],
    ) -> Result<u64, NodeError> {
        let plane = width * height;
        // Tangent frame (x right, y up the image) to grid (u right, v down the image).
        let to_grid = |d: [f64; 3]| [d[0], -d[1], d[2]];
        let wo = view.vector();
        let view_ray = to_grid([-wo[0], -wo[1], -wo[2]]);
        let n = samples.max(1);
        let share = 1.0 / (n * n) as f64;
        // Rows per block: the block's hits (n² per texel) stay within about 64 Ki.
        let rows = (65_536 / (width * n * n).max(1)).clamp(1, height.max(1));
        let mut missed = 0;
        let mut seen = Vec::with_capacity(rows * width * n * n);
        for y0 in (0..height).step_by(rows) {
            ctx.check_cancel()?;
            let y1 = (y0 + rows).min(height);
            seen.clear();
            for y in y0..y1 {
                for x in 0..width {
                    for (i, j) in (0..n * n).map(|k| (k % n, k / n)) {
                        let (fx, fy) = ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                        let (u0, v0) = ((x as f64 + fx) * sx - 0.5, (y as f64 + fy) * sy - 0.5);
                        let s = self.see([u0, v0], view_ray);
                        missed += s.is_none() as u64;
                        seen.push(s);
                    }
                }
            }
            out.par_chunks_mut(3 * plane)
                .zip(lights)
                .enumerate()
                .for_each(|(l, (out, light))| {
                    let wi = light.vector();
                    let light_ray = to_grid(wi);
                    let indirect = self.indirect.as_ref().map(|t| (t, l));
                    for (k, texel) in seen.chunks(n * n).enumerate() {
                        let (y, x) = (y0 + k / width, k % width);
                        let mut sum = [0.0; 3];
                        for c in texel
                            .iter()
                            .flatten()
                            .map(|s| self.shade(s, light_ray, wi, wo, indirect))
                        {
                            (0..3).for_each(|k| sum[k] += c[k] * share);
                        }
                        for (c, v) in sum.iter().enumerate() {
                            out[c * plane + y * width + x] = *v as f32;
                        }
                    }
                });
        }
        Ok(missed * lights.len() as u64)
    }

    /// What a view ray entering the top at grid point `at` meets: the hit, its shading normal
    /// and tangent, albedo and lobe; `None` if it meets nothing.
    fn see(&self, at: [f64; 2], view_ray: [f64; 3]) -> Option<Seen> {
        let hit = self
            .caster
            .cast([at[0], at[1], self.top], view_ray, 0.0)
            .ok()?;
        let [gu, gv] = self.lerp(hit.u, hit.v, |i| self.grad[i]);
        // Normal in the tangent frame: ∂h/∂x = gu, ∂h/∂y = −gv.
        let len = (gu * gu + gv * gv + 1.0).sqrt();
        let n = [-gu / len, gv / len, 1.0 / len];
        let rho = self.lerp(hit.u, hit.v, |i| {
            [self.albedo[0][i], self.albedo[1][i], self.albedo[2][i]]
        });
        let lobe = match &self.lobe_maps {
            None => self.lobe,
            Some(m) => {
                let [rho_s, alpha] = self.lerp(hit.u, hit.v, |i| m[i]);
                Lobe {
                    rho_s,
                    alpha,
                    alpha_v: alpha * self.lobe.alpha_v / self.lobe.alpha,
                    ..self.lobe
                }
            }
        };
        Some(Seen {
            at: [hit.u, hit.v, hit.z],
            n,
            t: brdf::tangent(n),
            rho,
            lobe,
        })
    }

    /// Radiance of the seen point under the light along `wi` (grid direction `light_ray`),
    /// seen from `wo`: the direct light (zero where the light is behind the normal or blocked),
    /// plus, with `indirect` (the transport and this light's index in it: its irradiance from
    /// the tile's other walls), its diffuse reflection.
    fn shade(
        &self,
        s: &Seen,
        light_ray: [f64; 3],
        wi: [f64; 3],
        wo: [f64; 3],
        indirect: Option<(&Transport, usize)>,
    ) -> [f64; 3] {
        let mut out = self.direct(s, light_ray, wi, wo);
        if let Some((t, light)) = indirect {
            let e = t.at(light, s.at[0], s.at[1]);
            (0..3).for_each(|c| out[c] += s.rho[c] / std::f64::consts::PI * e[c]);
        }
        out
    }

    /// The direct light's part of [`Scene::shade`].
    fn direct(&self, s: &Seen, light_ray: [f64; 3], wi: [f64; 3], wo: [f64; 3]) -> [f64; 3] {
        let n = s.n;
        let cos_i = n[0] * wi[0] + n[1] * wi[1] + n[2] * wi[2];
        if cos_i <= 0.0 {
            return [0.0; 3];
        }
        let lit = matches!(self.caster.cast(s.at, light_ray, 1e-4), Err(Miss::Escaped));
        if !lit {
            return [0.0; 3];
        }
        brdf::eval_lobe_rgb(&s.lobe, s.rho, n, s.t, wi, wo).map(|f| f * cos_i)
    }
}

/// A view ray's hit, as every light shades it.
struct Seen {
    /// Grid coordinates and height of the hit.
    at: [f64; 3],
    /// Shading normal and tangent (tangent frame).
    n: [f64; 3],
    t: [f64; 3],
    rho: [f64; 3],
    lobe: Lobe,
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;
    use std::f64::consts::PI;

    fn field(n: usize, f: impl Fn(usize, usize) -> f32) -> HeightField {
        HeightField::from_fn(n, n, f)
    }

    fn capture(hf: HeightField, albedo: Option<Image>, p: &Params) -> Result<Btf, NodeError> {
        let mut inputs = Inputs::new().with("height", std::sync::Arc::new(hf));
        if let Some(a) = albedo {
            inputs = inputs.with("albedo", std::sync::Arc::new(a));
        }
        // As the engine does: the parameter checks, then the run.
        Capture.check(p)?;
        let out = mesoflow_testkit::node::run(&Capture, p, &inputs)?;
        Ok(out.value::<Btf>("btf").clone())
    }

    fn at(b: &Btf, pair: usize, c: usize, x: usize, y: usize) -> f64 {
        b.data[(pair * 3 + c) * b.width * b.height + y * b.width + x] as f64
    }

    /// Isotropic Ward for the flat normal, written from the domain notes' formula in θ/φ terms
    /// (independent of brdf::eval's vector form).
    fn ward_flat(rho_d: f64, rho_s: f64, alpha: f64, view: Direction, light: Direction) -> f64 {
        let (ti, to) = (light.theta, view.theta);
        let hx = ti.sin() * light.phi.cos() + to.sin() * view.phi.cos();
        let hy = ti.sin() * light.phi.sin() + to.sin() * view.phi.sin();
        let hz = ti.cos() + to.cos();
        let delta = (hx.hypot(hy)).atan2(hz);
        rho_d / PI
            + rho_s * (-(delta.tan().powi(2)) / (alpha * alpha)).exp()
                / (4.0 * PI * alpha * alpha * (ti.cos() * to.cos()).sqrt())
    }

    #[test]
    fn a_flat_tile_captures_the_brdf() {
        // A flat surface has no masking, parallax or shadows: every texel is f · cos θi.
        // Tolerance 1e-6 relative: the value is computed in f64 and stored as f32 (2^-24 ≈ 6e-8).
        let rings = DirectionSet::Rings {
            thetas: vec![0.0, 30.0, 60.0, 75.0],
            phis: vec![0.0, 100.0, 250.0],
        };
        for model in [Model::Lambert, Model::Ward] {
            let p = Params {
                views: rings.clone(),
                lights: rings.clone(),
                brdf: model,
                albedo: [0.2, 0.5, 0.8],
                ..Params::default()
            };
            let b = capture(field(6, |_, _| 3.0), None, &p).unwrap();
            assert_eq!(b.pairs.len(), 100);
            for (k, pair) in b.pairs.iter().enumerate() {
                for (c, rho) in [0.2, 0.5, 0.8].into_iter().enumerate() {
                    let f = match model {
                        Model::Lambert => rho / PI,
                        Model::Ward => {
                            ward_flat(rho, p.specular, p.roughness, pair.view, pair.light)
                        }
                        _ => unreachable!("only the fitted models are listed"),
                    };
                    let expected = f * pair.light.theta.cos();
                    for (x, y) in [(0, 0), (3, 2), (5, 5)] {
                        let got = at(&b, k, c, x, y);
                        assert!(
                            (got - expected).abs() <= 1e-6 * expected,
                            "{model:?} pair {k} channel {c}: {got} vs {expected}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn per_texel_maps_capture_each_texels_own_ward_brdf() {
        // A flat tile whose left half is one Ward material and right half another: every texel
        // is that texel's f · cos θi (the same closed form as above), so the maps are read per
        // texel, not blended, where neighbours agree.
        let (n, rings) = (
            8,
            DirectionSet::List(vec![[0.0, 0.0], [40.0, 30.0], [70.0, 200.0]]),
        );
        let mat = |x: usize| {
            if x < n / 2 {
                [0.2, 0.3, 0.4, 0.1, 0.15]
            } else {
                [0.5, 0.1, 0.05, 0.02, 0.4]
            }
        };
        let maps = BrdfMap {
            width: n,
            height: n,
            data: (0..n * n).flat_map(|i| mat(i % n)).collect(),
        };
        let p = Params {
            views: rings.clone(),
            lights: rings,
            brdf: Model::Ward,
            ..Params::default()
        };
        let inputs = Inputs::new()
            .with("height", std::sync::Arc::new(field(n, |_, _| 1.0)))
            .with("maps", std::sync::Arc::new(maps));
        let out = mesoflow_testkit::node::run(&Capture, &p, &inputs).unwrap();
        let b = out.value::<Btf>("btf");
        for (k, pair) in b.pairs.iter().enumerate() {
            for x in [1, 2, 5, 6] {
                let m = mat(x);
                for c in 0..3 {
                    let expected =
                        ward_flat(m[c], m[3], m[4], pair.view, pair.light) * pair.light.theta.cos();
                    let got = at(b, k, c, x, 3);
                    assert!(
                        (got - expected).abs() <= 1e-6 * expected,
                        "pair {k} texel {x} channel {c}: {got} vs {expected}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_tall_block_shadows_what_brute_force_visibility_says() {
        // Floor at 0, a 4×4 block 10 texels tall; light at θ = 75° from +x, view from above.
        let n = 32;
        let hf = field(n, |i, j| {
            if (14..18).contains(&i) && (14..18).contains(&j) {
                10.0
            } else {
                0.0
            }
        });
        let light = Direction::degrees(75.0, 0.0);
        let p = Params {
            views: DirectionSet::List(vec![[0.0, 0.0]]),
            lights: DirectionSet::List(vec![[75.0, 0.0]]),
            albedo: [1.0; 3],
            ..Params::default()
        };
        let b = capture(hf.clone(), None, &p).unwrap();
        // Reference: march from each flat floor sample towards the light in 1e-3 steps, testing
        // the bilinear surface directly; independent of the cell traversal. A floor sample is one
        // whose 3×3 neighbourhood is all floor (its shading normal is exactly vertical).
        let h = |u: f64, v: f64| {
            let (i, j) = (u.floor(), v.floor());
            let (fx, fy) = (u - i, v - j);
            let s = |a: f64, b: f64| hf.at_wrapped(a as isize, b as isize) as f64;
            s(i, j) * (1.0 - fx) * (1.0 - fy)
                + s(i + 1.0, j) * fx * (1.0 - fy)
                + s(i, j + 1.0) * (1.0 - fx) * fy
                + s(i + 1.0, j + 1.0) * fx * fy
        };
        let wi = light.vector();
        let dir = [wi[0], -wi[1], wi[2]];
        let (mut shadowed, mut matched) = (0, 0);
        for y in 0..n {
            for x in 0..n {
                let flat = (-1..=1).all(|dy| {
                    (-1..=1).all(|dx| hf.at_wrapped(x as isize + dx, y as isize + dy) == 0.0)
                });
                if !flat {
                    continue;
                }
                let mut t = 1e-3;
                let blocked = loop {
                    let (u, v, z) = (x as f64 + dir[0] * t, y as f64 + dir[1] * t, dir[2] * t);
                    if z > 10.0 {
                        break false;
                    }
                    if h(u, v) > z {
                        break true;
                    }
                    t += 1e-3;
                };
                let dark = at(&b, 0, 0, x, y) == 0.0;
                shadowed += blocked as usize;
                matched += (blocked == dark) as usize;
                assert_eq!(blocked, dark, "texel ({x}, {y})");
            }
        }
        // The block's shadow is 10 / tan 75° ≈ 2.7 texels long behind it: there must be some.
        assert!(shadowed >= 8, "only {shadowed} shadowed texels");
        assert!(matched > 500);
    }

    #[test]
    fn samples_average_the_texel_as_a_finer_capture_does() {
        // n × n rays per texel are the n × n texels of a capture at n times the resolution,
        // box-filtered: its point samples sit on the same grid (texel X of the fine capture at
        // (X + 0.5)/n − 0.5, subsample i of texel x at x + (i + 0.5)/n − 0.5). The block's
        // shadow and walls give texels that are partly lit, where the two differ from a single
        // ray. Tolerance: the fine capture is rounded to f32 before averaging.
        let n = 16;
        let hf = field(n, |i, j| {
            if (6..9).contains(&i) && (5..9).contains(&j) {
                5.0
            } else {
                0.0
            }
        });
        let base = Params {
            views: DirectionSet::List(vec![[0.0, 0.0], [40.0, 200.0]]),
            lights: DirectionSet::List(vec![[70.0, 30.0]]),
            albedo: [1.0; 3],
            ..Params::default()
        };
        let coarse = capture(
            hf.clone(),
            None,
            &Params {
                samples: 3,
                ..base.clone()
            },
        )
        .unwrap();
        let single = capture(hf.clone(), None, &base).unwrap();
        let fine = capture(
            hf,
            None,
            &Params {
                resolution: Some(3 * n as u32),
                ..base
            },
        )
        .unwrap();
        let mut partial = 0;
        for pair in 0..2 {
            for y in 0..n {
                for x in 0..n {
                    let mean = (0..9)
                        .map(|k| at(&fine, pair, 0, 3 * x + k % 3, 3 * y + k / 3))
                        .sum::<f64>()
                        / 9.0;
                    let got = at(&coarse, pair, 0, x, y);
                    assert!(
                        (got - mean).abs() < 1e-6,
                        "pair {pair} texel ({x}, {y}): {got} vs {mean}"
                    );
                    partial += ((got - at(&single, pair, 0, x, y)).abs() > 1e-3) as usize;
                }
            }
        }
        assert!(
            partial >= 10,
            "only {partial} texels differ from a single ray"
        );
    }

    #[test]
    fn a_tilted_view_shifts_the_floor_by_the_parallax_of_its_depth() {
        // A pillar 8 texels tall at sample (0, 0) puts the reference plane at z = 8 above a flat
        // floor. Seen from θ = 45° towards +x, the ray through texel x meets the floor 8·tan 45° = 8
        // texels towards −x, so the captured row shows the albedo shifted by 8 texels.
        let n = 32;
        let hf = field(n, |i, j| if (i, j) == (0, 0) { 8.0 } else { 0.0 });
        let stripes = |x: usize| 0.1 + (x % 5) as f32 / 5.0;
        let albedo = Image {
            width: n,
            height: n,
            channels: 1,
            data: (0..n * n).map(|k| stripes(k % n)).collect(),
        };
        let p = Params {
            views: DirectionSet::List(vec![[0.0, 0.0], [45.0, 0.0]]),
            lights: DirectionSet::List(vec![[0.0, 0.0]]),
            ..Params::default()
        };
        let b = capture(hf, Some(albedo), &p).unwrap();
        let y = 16; // far from the pillar's rows (−1..1 and their periodic copies)
        for x in 0..n {
            let top = at(&b, 0, 0, x, y);
            let tilted = at(&b, 1, 0, x, y);
            let expected_top = stripes(x) as f64 / PI;
            let expected_tilted = stripes((x + n - 8) % n) as f64 / PI;
            assert!(
                (top - expected_top).abs() < 1e-6,
                "x {x}: {top} vs {expected_top}"
            );
            assert!(
                (tilted - expected_tilted).abs() < 1e-6,
                "x {x}: {tilted} vs {expected_tilted}"
            );
        }
    }

    /// Periodic grooves along the image's y axis: a cosine `depth` texels deep over a period
    /// of `n` samples (smooth, so the shading normals are the surface's own).
    fn grooves(n: usize, depth: f32) -> HeightField {
        field(n, |i, _| {
            let x = i as f32 / n as f32;
            0.5 * depth * (1.0 + (2.0 * std::f32::consts::PI * x).cos())
        })
    }

    /// Reflected flux per unit area of the reference plane for each light of `b`, from its
    /// views: the midpoint rule in (cos θo, φo) over `m` × `m` views, which `quadrature` lists.
    fn flux(b: &Btf, m: usize) -> Vec<f64> {
        let lights = b.pairs.len() / (m * m);
        let plane = (b.width * b.height) as f64;
        (0..lights)
            .map(|l| {
                (0..m * m)
                    .map(|v| {
                        let k = v * lights + l;
                        let mean = (0..b.width * b.height)
                            .map(|t| b.data[k * 3 * b.width * b.height + t] as f64)
                            .sum::<f64>()
                            / plane;
                        mean * b.pairs[k].view.theta.cos() * (2.0 * PI / (m * m) as f64)
                    })
                    .sum()
            })
            .collect()
    }

    fn quadrature(m: usize) -> DirectionSet {
        DirectionSet::List(
            (0..m * m)
                .map(|k| {
                    let mu = ((k / m) as f64 + 0.5) / m as f64;
                    [
                        mu.acos().to_degrees(),
                        ((k % m) as f64 + 0.5) * 360.0 / m as f64,
                    ]
                })
                .collect(),
        )
    }

    #[test]
    fn a_flat_tile_gains_nothing_from_bounces() {
        // Every gather ray from a flat tile leaves it: the BTF is the direct one, bit for bit.
        let p = Params {
            views: DirectionSet::List(vec![[0.0, 0.0], [50.0, 120.0]]),
            lights: DirectionSet::List(vec![[30.0, 10.0], [70.0, 250.0]]),
            ..Params::default()
        };
        let direct = capture(field(8, |_, _| 2.0), None, &p).unwrap();
        let bounced = capture(
            field(8, |_, _| 2.0),
            None,
            &Params {
                bounces: 4,
                ..p.clone()
            },
        )
        .unwrap();
        assert_eq!(direct.data, bounced.data);
    }

    #[test]
    fn interreflections_add_light_but_never_make_energy() {
        // White (ρ = 1) Lambertian grooves lose no light: all that arrives leaves again, after
        // enough bounces. So the reflected flux over the hemisphere of views is at most the
        // irradiance cos θi of the reference plane, reaches it as bounces grow, and with one
        // bounce lies between the direct light's and that. The flux comes from the BTF itself by
        // a 16 × 16 midpoint rule, exact on the flat tile (checked to 2e-3). On the grooves
        // (a period of 24 samples, 12 deep, a transport grid of 2 per sample) what remains is
        // the grid's interpolation (shadow edges included), the rule on a view-dependent
        // radiance and the gather's noise: measured 0.12% over, 1.7% short (the grazing light
        // across the grooves, whose shadow edges the grid smears) and 0.13% over cos θi; the
        // bound allows 4% short and 1% over.
        let m = 16;
        let p = Params {
            views: quadrature(m),
            lights: DirectionSet::List(vec![[20.0, 0.0], [60.0, 0.0], [60.0, 90.0]]),
            albedo: [1.0; 3],
            bounce_rays: 256,
            ..Params::default()
        };
        let cos_i = [20f64, 60.0, 60.0].map(|t| t.to_radians().cos());
        let flat = flux(&capture(field(4, |_, _| 0.0), None, &p).unwrap(), m);
        for (f, c) in flat.iter().zip(cos_i) {
            assert!((f / c - 1.0).abs() < 2e-3, "flat: {f} vs {c}");
        }
        let at = |bounces| {
            flux(
                &capture(
                    grooves(24, 12.0),
                    None,
                    &Params {
                        bounces,
                        ..p.clone()
                    },
                )
                .unwrap(),
                m,
            )
        };
        let (direct, one, many) = (at(0), at(1), at(12));
        for l in 0..3 {
            let c = cos_i[l];
            eprintln!(
                "light {l}: direct {:.4} one {:.4} many {:.4} of {c:.4}",
                direct[l], one[l], many[l]
            );
            assert!(direct[l] < 0.9 * c, "the grooves trap light: {}", direct[l]);
            assert!(one[l] > direct[l] * 1.05 && one[l] < many[l], "{one:?}");
            assert!(many[l] <= c * 1.01, "energy made: {} of {c}", many[l]);
            assert!(many[l] >= c * 0.96, "energy lost: {} of {c}", many[l]);
        }
    }

    #[test]
    fn bounces_give_the_same_bits_at_any_thread_count() {
        let p = Params {
            views: DirectionSet::List(vec![[0.0, 0.0], [45.0, 30.0], [70.0, 200.0]]),
            lights: DirectionSet::List(vec![[30.0, 0.0], [60.0, 90.0]]),
            bounces: 3,
            bounce_rays: 16,
            samples: 2,
            ..Params::default()
        };
        let run = |threads| {
            mesoflow_testkit::threads::with_threads(threads, || {
                capture(grooves(16, 6.0), None, &p).unwrap()
            })
        };
        assert_eq!(run(1).data, run(3).data);
    }

    #[test]
    fn bad_inputs_are_errors_that_name_the_port_or_parameter() {
        let p = Params {
            views: DirectionSet::List(vec![[0.0, 0.0]]),
            lights: DirectionSet::List(vec![[0.0, 0.0]]),
            ..Params::default()
        };
        let small = Image {
            width: 2,
            height: 2,
            channels: 3,
            data: vec![0.5; 12],
        };
        let e = capture(field(4, |_, _| 0.0), Some(small), &p).unwrap_err();
        assert!(
            matches!(&e, NodeError::Input { port, .. } if port == "albedo"),
            "{e}"
        );
        let p = Params {
            lights: DirectionSet::List(vec![[90.0, 0.0]]),
            ..p
        };
        let e = capture(field(4, |_, _| 0.0), None, &p).unwrap_err();
        assert!(
            matches!(&e, NodeError::Param { param, .. } if param == "lights"),
            "{e}"
        );
        // 81 × 81 pairs at 1024² would be 82 GB: refused before allocating, with its size.
        let p = Params {
            resolution: Some(1024),
            memory_budget_gb: Some(8.0),
            ..Params::default()
        };
        let e = capture(field(4, |_, _| 0.0), None, &p).unwrap_err();
        assert!(e.to_string().contains("needs 82.56 GB"), "{e}");
    }
}
