//! `sss.render`: a translucent mesh lit by one light, rendered with a diffusion profile the way
//! Jensen & Buhler 2002 do it:
//!
//! 1. irradiance sample points over the mesh (`points.rs`: blue noise), spaced a quarter of the
//!    smallest effective mean free path 1/σtr — no denser than the profile varies — with a cap on
//!    their number and a floor of 64 points per mesh;
//! 2. the transmitted irradiance E = Ft(θi)·I·cos θi at each, with shadows from a shadow map;
//! 3. per pixel, the exitance M(xo) = E(xo)·P(ρ₀) + Σ_{‖xi−xo‖ ≥ ρ₀} Rd(‖xi − xo‖)·E(xi)·ΔA,
//!    where P(ρ₀) is the profile's energy inside the disc of one sample's size around xo (there
//!    the irradiance is taken as xo's own: the profile's peak is never sampled by the sparse
//!    points). The sum runs over an octree with the `threshold` criterion on the CPU
//!    (`octree.rs`; 0 = brute force) and brute force in workgroup tiles on the GPU;
//! 4. radiance L = C·Ft(θo)·M with C = 1/(π(1 − Fdr,outside)) (seed 004's normalisation, so a
//!    diffuse exitance M leaves as M), plus, when asked, the single-scattering radiance of a
//!    locally flat semi-infinite medium (Hanrahan & Krueger 1993): α·Ft(θi)·Ft(θo)/η²·
//!    p(ωi′·ωo′)·I cos θi/(cos θi′ + cos θo′), with the refracted directions.
//!
//! Options measured against the volumetric truth (`render.reference` with a medium): light
//! that leaves one part of the object and enters another (`bounces`, `bounce.rs`), the entry
//! dipole's flux through the exit point's own normal (`geometry: exit_normal`, `geometry.rs`),
//! that corrected for the object's own boundary by the diffusion equation solved on a grid
//! inside the mesh (`geometry: body`, `body.rs`), the directional dipole (`geometry:
//! directional`, `directional.rs`), diffusion from where the light scatters along its
//! refracted ray rather than from one point under each sample (`sources: beam`, `beam.rs`),
//! single scattering traced through the mesh (`single_scattering_shape: traced`,
//! `single.rs`), the exact half-space's energy (`energy: half_space`, `energy.rs`) and the
//! exitance's angular shape (`emission`, `emission.rs`).
//! The defaults are the configuration that came closest to the volumetric truth over the guide's
//! scenes (`geometry: auto`, `sources: beam`, `emission: p1`, traced single scattering, two
//! bounces, with `sss.profile`'s default `pbd_multiple`); `Params::classic` is Jensen & Buhler's.
//! Silhouette pixels show the object over the share of the pixel it covers (`gather.rs`), as
//! the truth's samples do. An object fewer than six reduced mean free paths thick gets a
//! warning (`thickness.rs`): there the truth showed the light `exit_normal` and `body` send
//! through thin parts far too bright.
//!
//! Lengths: the mesh is in world units, `mm_per_unit` converts to the profile's millimetres.

use crate::support::geometry::V3;
use crate::support::progress::Counter;
use crate::support::raytrace::camera::Camera;
use crate::support::raytrace::footprint::{self, Footprint};
use crate::support::raytrace::layers::Frag;
use crate::support::raytrace::light::Light;
use crate::support::raytrace::tracer::Tracer;
use crate::types::{DiffusionProfile, Image, Mesh, ScatteringMaterial, SssLighting};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::Instant;

mod at_samples;
mod backlit;
mod beam;
mod body;
mod bounce;
mod directional;
mod emission;
mod energy;
mod expneg;
pub(crate) mod gather;
mod geometry;
pub mod lighting;
mod setup;
mod shading;
mod single;
#[cfg(test)]
mod tests;
mod thickness;

pub use emission::Emission;
pub use energy::Energy;
use gather::{gather_cpu, gather_gpu, View};
pub use geometry::Geometry;
pub use setup::shadow_map;
use setup::Setup;
use shading::finish;

crate::view_params! {
    #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
    #[serde(default, deny_unknown_fields)]
    pub struct Params {
        view { camera, light, mm_per_unit, shadows = true, shadow_resolution, background }
        /// Irradiance sample spacing in mm; default a quarter of the smallest 1/σtr.
        pub spacing: Option<f64> = None,
        /// Most irradiance samples (the spacing grows to respect it, with a warning).
        #[schemars(range(min = 64))]
        pub max_points: u32 = 200_000,
        /// Octree criterion ΔA/d² under which a node is one source (CPU); 0 = brute force.
        #[schemars(range(min = 0.0))]
        pub threshold: f64 = 0.05,
        /// Add single scattering (from the material's σs, g; on by default: the default
        /// profile, `pbd_multiple`, leaves it out for the render to add).
        pub single_scattering: bool = true,
        /// Where single scattering happens: `traced` (default; along the camera ray inside the
        /// mesh itself, the light attenuated by the real distance it travels inside: exact at
        /// η = 1; at η ≠ 1 directions are not bent inside) or `half_space` (Hanrahan & Krueger's
        /// flat semi-infinite medium under each point).
        pub single_scattering_shape: SingleShape = SingleShape::Traced,
        /// Seed of the sample points.
        pub seed: u64 = 1,
        /// Bounces of light leaving one part of the object and entering another (0 to 8): what a
        /// concave object's inner sides send each other (default 2; none where under 10⁻³ of the
        /// rays leaving the object return to it, as from a convex one).
        #[schemars(range(min = 0, max = 8))]
        pub bounces: u32 = 2,
        /// `auto` (default): `body` on a closed mesh, `exit_normal` on an open one (with a
        /// warning). `planar`: the profile at the straight distance, as on a flat half-space.
        /// `exit_normal`: scaled by the dipole's flux through the shaded point's own normal, so that
        /// light passes through thin and curved parts. `directional`: scaled by the directional
        /// dipole (Frisvad et al. 2014) over its value on a plane lit straight down, for the
        /// light's incident direction and the shape. `body`: `exit_normal` plus the light the
        /// object's own boundary lets out elsewhere, from the diffusion equation solved on a grid
        /// inside the mesh (the mesh must be closed; against a wide slab's closed form it is exact,
        /// where `exit_normal` transmits 38% too little). All but `planar` run the gather on the
        /// CPU.
        pub geometry: Geometry = Geometry::Auto,
        /// `diffusion` (default): the profile gathered over irradiance samples. `brdf`: the
        /// profile's total reflectance as a diffuse lobe with the Fresnel transmittances in and out,
        /// no samples and no gather: right where light scatters less far than a pixel covers.
        pub mode: Mode = Mode::Diffusion,
        /// `profile` (default): the profile's own total reflectance at every angle. `half_space`:
        /// each sample's light scaled so that the profile returns what a semi-infinite medium of
        /// the material reflects at that angle of incidence (Chandrasekhar's H function: exact for
        /// isotropic scattering behind an index-matched boundary, so η = 1 only; g ≠ 0 through the
        /// reduced albedo); the multiple scattering alone when `single_scattering` adds the first.
        pub energy: Energy = Energy::Profile,
        /// How the diffuse exitance leaves in angle: `p1` (default; diffusion theory's own
        /// radiance at the boundary,
        /// 1 + 3μ′/(2A) inside, refracted out, the same exitance: at η = 1, 1.25× face-on and 0.5×
        /// at grazing, as the exact half-space's 1.26× and 0.43×), `diffuse` (Jensen & Buhler's
        /// Ft(θo)·M/(π(1 − Fdr))) or `half_space` (η = 1 only:
        /// Chandrasekhar's exact shapes, the pixel's own light as a half-space lit at its incidence,
        /// the rest as the deep field; the multiple scattering's when `single_scattering` adds the
        /// first).
        pub emission: Emission = Emission::P1,
        /// Where the light entering at each sample starts to diffuse: `beam` (default; along the
        /// refracted light, where its second collisions happen: oblique light scatters shallower
        /// and sends its multiple scattering less far, as transport does; each beam ends where
        /// its ray leaves the mesh; the profile still sets how much, `beam.rs`) or `point`
        /// (Jensen et al. 2001's one source a reduced mean free path under the sample, whatever
        /// the light's angle). `beam` needs `geometry: auto`, `exit_normal` or `body`, and is
        /// meant with a profile of multiple scattering alone (`pbd_multiple`) and
        /// `single_scattering`.
        pub sources: Sources = Sources::Beam,
        /// Where the diffusion sum is gathered: `auto` (default) at the irradiance samples the
        /// view needs, each pixel interpolated from the samples around it, where those are fewer
        /// than the covered pixels (a view then costs the surface it sees, not its pixels), and
        /// per pixel elsewhere; `pixels`: per pixel always; `samples`: at the samples always.
        /// The pixel's own light (the near disc) is per pixel in every case (`at_samples.rs`).
        pub gather: GatherAt = GatherAt::Auto,
    }
}

/// Where the diffusion sum is gathered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum GatherAt {
    /// At the samples where the view needs fewer of them than it covers pixels, else per pixel.
    #[default]
    Auto,
    /// Per pixel.
    Pixels,
    /// At the samples, interpolated to the pixels.
    Samples,
}

/// Where the light entering at a sample starts to diffuse.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Sources {
    /// One point 1/σt′ under the sample along its normal (Jensen et al. 2001).
    Point,
    /// The first scatterings along the refracted light (Habel et al. 2013's photon beam).
    #[default]
    Beam,
}

/// Where single scattering is evaluated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SingleShape {
    /// A flat semi-infinite medium under each point (Hanrahan & Krueger 1993).
    HalfSpace,
    /// The mesh itself, by ray tracing (`single.rs`).
    #[default]
    Traced,
}

/// How subsurface transport is rendered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Jensen & Buhler's gather of the diffusion profile.
    #[default]
    Diffusion,
    /// The profile's total diffuse reflectance, local to each point.
    Brdf,
}

/// Samples per mesh at least, whatever the spacing.
const MIN_POINTS: f64 = 64.0;

pub struct Render;

impl Node for Render {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "sss.render",
            // 4: the `geometry` parameter. 5: silhouette pixels covered in proportion;
            // `single_scattering_shape`, `geometry: directional`, `energy`. 6: `emission`.
            // 7: the thin-object warning (results unchanged; then a cache hit did not repeat a
            // node's warnings, so earlier results reran once; it does now). 8: `geometry: body`.
            // 9: `sources`. 10: `sources: beam` ends each beam where its ray leaves the mesh.
            // 11: the accurate configuration is the default (`geometry: auto`, `sources: beam`,
            // `emission: p1`, traced single scattering, two bounces; `Params::classic` the old).
            // 12: no bounces on an object that hardly sees itself (`bounce::NEGLIGIBLE`): a
            // convex mesh renders as with `bounces: 0`, in a quarter of the time.
            // 13: the `lighting` input (images unchanged without it); the beams' kernels with
            // `expneg` (within 4·10⁻¹⁶ of the library's exp, a quarter less gather time).
            // 14: `gather` (`auto`: through the samples where the view needs fewer than it
            // covers pixels; per pixel as before elsewhere). 15: one sample in four gathers.
            version: 15,
            doc: "Translucent mesh with a diffusion profile (Jensen & Buhler 2002): blue-noise irradiance samples, shadows, octree gather on the CPU or brute force on the GPU, optional single scattering; linear HDR image.",
            device: DevicePreference::Gpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the translucent object"),
                Port::input("material", ScatteringMaterial::TYPE, "its medium (η, and σs, g for single scattering)"),
                Port::input("profile", DiffusionProfile::TYPE, "its diffusion profile"),
                Port::optional("lighting", SssLighting::TYPE, "what does not depend on the camera, from sss.lighting (cached there): the render then takes its lighting parameters from it"),
            ],
            outputs: vec![
                Port::output("image", Image::TYPE, "linear HDR radiance"),
                Port::output("exitance", Image::TYPE, "diffuse exitance M per pixel (transmitted flux per area)"),
                Port::output("points", "Scalar", "irradiance samples used"),
                Port::optional_output("spacing", "Scalar", "their spacing, mm (absent in `brdf` mode: no samples)"),
                Port::output("terms", "Scalar", "mean profile evaluations per gather (a pixel's, or a sample's under `gather: samples`)"),
                Port::optional_output("body_spacing", "Scalar", "the cell of `geometry: body`'s grid, mm (absent otherwise)"),
            ]
            .into_iter()
            .chain(footprint::output_ports(false))
            .collect(),
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        check_params(p)
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            ("gather_seconds", "wall time of the per-pixel sums, s"),
            (
                "setup_seconds",
                "wall time of what the camera does not change: the BVH, the samples, their light, octree, beams and bounces, s",
            ),
            ("bounce_seconds", "the bounces' share of `setup_seconds`, s"),
            (
                "gathers",
                "the gathers the sum took: one a sample the view needs (`gather: samples`, and `auto` where they are fewer than the covered pixels), else one a covered pixel",
            ),
            ("covered_pixels", "the pixels that see the object"),
            (
                "shading_seconds",
                "wall time of each pixel's own light and single scattering, s",
            ),
            (
                "body_seconds",
                "wall time of `geometry: body`'s grid, solve and share of each pixel's exitance, s (absent otherwise; through the samples the share is in `gather_seconds`)",
            ),
        ]
    }
    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        let material = inputs.get::<ScatteringMaterial>("material")?;
        let profile = inputs.get::<DiffusionProfile>("profile")?;
        let watch = Counter::new(ctx, 0);
        let lit = inputs.opt::<SssLighting>("lighting")?;
        let merged = lit.map(|l| lighting::merged(p, l)).transpose()?;
        let p = merged.as_ref().unwrap_or(p);
        let r = render_lit(
            ctx.gpu(),
            mesh,
            material,
            profile,
            p,
            &Homogeneous,
            &watch,
            lit,
            Some(ctx),
        )?;
        for w in r.warnings {
            ctx.warn(w);
        }
        ctx.timing("gather_seconds", r.gather_seconds);
        ctx.timing("gathers", r.gathers as f64);
        ctx.timing("covered_pixels", r.covered as f64);
        ctx.timing("setup_seconds", r.setup_seconds);
        ctx.timing("bounce_seconds", r.bounce_seconds);
        ctx.timing("shading_seconds", r.shading_seconds);
        if let Some(s) = r.body_seconds {
            ctx.timing("body_seconds", s);
        }
        let out = Outputs::new()
            .with("image", r.image)
            .with("exitance", r.exitance)
            .with("points", Scalar(r.points as f64))
            .with("terms", Scalar(r.terms));
        let out = match r.spacing {
            Some(s) => out.with("spacing", Scalar(s)),
            None => out,
        };
        let out = match r.body_spacing {
            Some(s) => out.with("body_spacing", Scalar(s)),
            None => out,
        };
        Ok(footprint::with_metrics(out, r.footprint.as_ref()))
    }
}

pub struct Rendered {
    pub image: Image,
    pub exitance: Image,
    pub points: usize,
    /// Sample spacing, mm (`None` in `brdf` mode).
    pub spacing: Option<f64>,
    /// Mean profile evaluations per covered pixel.
    pub terms: f64,
    /// The gathers the sum took: one a sample the view needs under `gather: samples`, else
    /// one a covered pixel.
    pub gathers: usize,
    /// The pixels that see the object.
    pub covered: usize,
    pub gather_seconds: f64,
    /// The BVH, the samples, their light, octree and beams, the bounces and the thickness
    /// (everything that does not depend on the camera but the body's grid), s.
    pub setup_seconds: f64,
    /// The bounces' share of `setup_seconds`, s.
    pub bounce_seconds: f64,
    /// The view's hits and each pixel's shading (its own light, single scattering), s.
    pub shading_seconds: f64,
    /// With `geometry: body`: the grid's build and solve and each pixel's share, s (outside
    /// `gather_seconds`, the profile's gather), and the grid's cell, mm.
    pub body_seconds: Option<f64>,
    pub body_spacing: Option<f64>,
    /// What one pixel covers on the surface (texels per pixel with the weights' texture).
    pub footprint: Option<Footprint>,
    pub warnings: Vec<String>,
}

/// Spatially varying factors a caller may add to the homogeneous render (quasi-homogeneous
/// materials): a multiplier of the irradiance entering at each sample (the mesostructure
/// entrance function), and per pixel a multiplier of the diffuse exitance leaving (the exiting
/// function) plus a local radiance to add (the local reflectance term). Directions are world
/// unit vectors: towards the light at the sample, towards the viewer at the pixel.
pub trait Weights: Sync {
    fn entrance(&self, at: &Frag, to_light: V3) -> [f64; 3];
    fn pixel(&self, px: usize, at: &Frag, to_viewer: V3) -> ([f64; 3], [f64; 3]);
    /// The texture on the surface, for the footprint's texels per pixel (none by default).
    fn texture(&self) -> Option<footprint::Texture> {
        None
    }
}

/// No mesostructure: the homogeneous render.
pub struct Homogeneous;

impl Weights for Homogeneous {
    fn entrance(&self, _: &Frag, _: V3) -> [f64; 3] {
        [1.0; 3]
    }
    fn pixel(&self, _: usize, _: &Frag, _: V3) -> ([f64; 3], [f64; 3]) {
        ([1.0; 3], [0.0; 3])
    }
}

/// The render on the GPU when one is given, else on the CPU.
pub fn render(
    gpu: Option<&mesoflow_runtime::Gpu>,
    mesh: &Mesh,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
) -> Result<Rendered, NodeError> {
    render_with(
        gpu,
        mesh,
        material,
        profile,
        p,
        &Homogeneous,
        &Counter::none(),
    )
}

/// `render` with entrance, exiting and local terms.
pub fn render_with(
    gpu: Option<&mesoflow_runtime::Gpu>,
    mesh: &Mesh,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
    weights: &dyn Weights,
    watch: &Counter,
) -> Result<Rendered, NodeError> {
    render_lit(gpu, mesh, material, profile, p, weights, watch, None, None)
}

/// [`render_with`], the camera-independent part taken from `lighting` when given (made by
/// `sss.lighting` for this mesh, material, profile and `p`'s lighting parameters; `p` already
/// holds them, `lighting::merged`). With the run's `ctx`, a large mesh's BVH comes from and goes
/// to its disk cache (`Tracer::in_context`).
#[allow(clippy::too_many_arguments)]
pub(super) fn render_lit(
    gpu: Option<&mesoflow_runtime::Gpu>,
    mesh: &Mesh,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
    weights: &dyn Weights,
    watch: &Counter,
    lighting: Option<&SssLighting>,
    ctx: Option<&NodeContext>,
) -> Result<Rendered, NodeError> {
    check_inputs(mesh, profile, p)?;
    let camera = Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
    let light = Light::new(&p.light)?;
    let mut warnings = Vec::new();
    if p.single_scattering
        && p.mode == Mode::Diffusion
        && matches!(profile.model.as_str(), "pbd" | "montecarlo")
    {
        warnings.push(format!(
            "the `{}` profile holds single scattering already and `single_scattering` adds it again: give the render a `pbd_multiple` profile (sss.profile's default), or set `single_scattering: false`",
            profile.model
        ));
    }
    // One BVH for the bounces, the thickness, the body's inside test, the view and single
    // scattering.
    let setup_start = Instant::now();
    let tracer = Tracer::in_context(mesh, ctx);
    let prepared = match lighting {
        Some(lit) => lighting::rebuild(&tracer, material, profile, p, &light, lit)?,
        None => prepare(
            &tracer,
            material,
            profile,
            p,
            &light,
            weights,
            &mut warnings,
        )?,
    };
    let Prepared {
        setup,
        params,
        body,
        body_setup_seconds,
    } = prepared;
    let p = &params;
    if p.mode == Mode::Diffusion {
        let share = backlit::share(&setup.sources, &p.camera, p.mm_per_unit);
        warnings.extend(share.and_then(backlit::warning));
    }
    let setup_seconds = setup_start.elapsed().as_secs_f64() - body_setup_seconds;
    let view_start = Instant::now();
    let view = View::new(mesh, &camera, &tracer);
    let view_seconds = view_start.elapsed().as_secs_f64();
    let gather_start = Instant::now();
    let covered = view.hits.iter().filter(|h| h.is_some()).count();
    // Through the samples the gathers add the body's share themselves.
    let mut body_in_sums = false;
    let (mut sums, terms, gathers) = match (p.mode, gpu) {
        (Mode::Brdf, _) => (vec![[0.0; 3]; view.hits.len()], 0.0, 0),
        // The GPU gather knows the planar profile only.
        (Mode::Diffusion, Some(gpu)) if p.geometry == Geometry::Planar => (
            gather_gpu(gpu, &setup, &view)?,
            setup.sources.len() as f64,
            covered,
        ),
        (Mode::Diffusion, _) => {
            let share = body.as_ref().map(|(b, _)| {
                let octree = &setup.octree;
                move |x: V3, n: V3| b.exitance(octree, x, n)
            });
            let share = share.as_ref().map(|f| f as &at_samples::Share);
            let through = match p.gather {
                GatherAt::Pixels => None,
                at => at_samples::gather(
                    &setup,
                    &view,
                    p.threshold,
                    at == GatherAt::Auto,
                    share,
                    watch,
                ),
            };
            body_in_sums = through.is_some();
            through.unwrap_or_else(|| {
                let (sums, terms) = gather_cpu(&setup, &view, p.threshold, watch);
                (sums, terms, covered)
            })
        }
    };
    if watch.stopped() {
        return Err(NodeError::Cancelled);
    }
    let gather_seconds = gather_start.elapsed().as_secs_f64();
    let body_seconds = match &body {
        Some(_) if body_in_sums => Some(body_setup_seconds),
        Some((b, _)) => {
            let start = Instant::now();
            let octree = &setup.octree;
            sums.par_iter_mut().zip(&view.hits).for_each(|(sum, hit)| {
                if let Some((x, n, ..)) = hit {
                    let share = b.exitance(octree, x.map(|v| v * p.mm_per_unit), *n);
                    // What leaves is a flux out: the body's share takes away at most
                    // what the dipoles gave.
                    *sum = [0, 1, 2].map(|c| (sum[c] + share[c]).max(0.0));
                }
            });
            Some(body_setup_seconds + start.elapsed().as_secs_f64())
        }
        None => None,
    };
    let traced = (p.single_scattering && p.single_scattering_shape == SingleShape::Traced)
        .then_some(single::Traced {
            tracer: &tracer,
            unit: p.mm_per_unit,
        });
    let shading_start = Instant::now();
    let (image, exitance) = finish(
        &setup,
        &view,
        &sums,
        p,
        (material, &light),
        weights,
        traced.as_ref(),
    );
    let shading_seconds = view_seconds + shading_start.elapsed().as_secs_f64();
    if image
        .data
        .iter()
        .chain(&exitance.data)
        .any(|v| !v.is_finite())
    {
        return Err(NodeError::Failed(
            "a pixel is not finite: a bug, please report it with the graph".into(),
        ));
    }
    Ok(Rendered {
        image,
        exitance,
        points: setup.sources.len(),
        spacing: (p.mode == Mode::Diffusion).then_some(setup.spacing_mm),
        terms,
        gathers,
        covered,
        gather_seconds,
        setup_seconds,
        bounce_seconds: setup.bounce_seconds,
        shading_seconds,
        body_seconds,
        body_spacing: body.map(|b| b.1),
        footprint: footprint::footprint(mesh, &camera, weights.texture(), p.mm_per_unit),
        warnings,
    })
}

/// What a render of `p` shares between views: the set-up (samples, their light, octree,
/// beams, bounces), the parameters with `geometry: auto` resolved, and `geometry: body`'s grid.
struct Prepared {
    setup: Setup,
    params: Params,
    body: Option<(body::Body, f64)>,
    /// The body's build and solve, s.
    body_setup_seconds: f64,
}

/// Everything of a render that does not depend on the camera, computed.
fn prepare(
    tracer: &Tracer,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
    light: &Light,
    weights: &dyn Weights,
    warnings: &mut Vec<String>,
) -> Result<Prepared, NodeError> {
    let mesh = tracer.mesh;
    let setup = match p.mode {
        Mode::Diffusion => Setup::new(tracer, material, profile, p, light, weights, warnings)?,
        Mode::Brdf => Setup::local(mesh, material, profile, p, light)?,
    };
    // `geometry: auto` follows the shape in the set-up as `body` and `exit_normal` both do; which
    // of the two is decided by the mesh and its thickness.
    let mut params = p.clone();
    if p.mode == Mode::Diffusion {
        let thick = thickness::median_mm(tracer, &setup.sources, p.mm_per_unit);
        if p.geometry == Geometry::Auto {
            params.geometry = auto_geometry(mesh, material, thick, warnings);
        }
        warnings.extend(thick.and_then(|t| thickness::warning(t, material, params.geometry)));
    }
    let body_start = Instant::now();
    let body = if params.mode == Mode::Diffusion && params.geometry == Geometry::Body {
        let (body, report) = body::Body::new(
            tracer,
            mesh,
            &setup.octree,
            setup.beam.clone(),
            material,
            p.mm_per_unit,
        )?;
        warnings.extend(report.warnings);
        Some((body, report.spacing_mm))
    } else {
        None
    };
    Ok(Prepared {
        setup,
        params,
        body,
        body_setup_seconds: body_start.elapsed().as_secs_f64(),
    })
}

/// `geometry: auto`: `body` where the mesh has an inside to solve in and is thicker than the
/// extrapolation distance its boundary problem sets (z_b = 2AD: thinner, the problem lies mostly
/// outside the object and its grid grows to the cap for nothing), else `exit_normal`, with a
/// warning saying why.
fn auto_geometry(
    mesh: &Mesh,
    material: &ScatteringMaterial,
    thickness_mm: Option<f64>,
    warnings: &mut Vec<String>,
) -> Geometry {
    let torn = body::open_edges(mesh);
    let zb = body::extrapolation_mm(material);
    let why = match thickness_mm {
        _ if torn > 0 => format!(
            "{torn} edges border only one triangle, so the object has no inside for the body's diffusion problem"
        ),
        Some(t) if t < zb => format!(
            "the object is {t:.3} mm thick, less than the {zb:.3} mm the body's boundary lies outside it (z_b = 2AD)"
        ),
        _ => return Geometry::Body,
    };
    warnings.push(format!(
        "geometry: auto renders this mesh with `exit_normal`, not `body`: {why} (set `geometry` to silence this)"
    ));
    Geometry::ExitNormal
}

impl Params {
    /// Jensen & Buhler 2002's render, the cheapest gather: planar profile, one source under each
    /// sample, diffuse exit, no bounces, no single scattering (the defaults before version 11;
    /// with a `dipole` profile it is the classic model). Everything else as [`Params::default`].
    pub fn classic() -> Params {
        Params {
            single_scattering: false,
            single_scattering_shape: SingleShape::HalfSpace,
            bounces: 0,
            geometry: Geometry::Planar,
            emission: Emission::Diffuse,
            sources: Sources::Point,
            ..Params::default()
        }
    }
}

/// The mesh, the profile and the parameters checked before a render or a lighting starts.
fn check_inputs(mesh: &Mesh, profile: &DiffusionProfile, p: &Params) -> Result<(), NodeError> {
    mesh.check().map_err(|e| NodeError::input("mesh", e))?;
    if profile.radii.len() < 2 {
        return Err(NodeError::input("profile", "fewer than two radii"));
    }
    check_params(p)
}

/// The parameters' own rules: validated before any work (`Node::check`) and again by
/// [`render_with`] for callers that skip the engine.
pub fn check_params(p: &Params) -> Result<(), NodeError> {
    if !(p.mm_per_unit > 0.0 && p.mm_per_unit.is_finite()) {
        return Err(NodeError::param("mm_per_unit", "must be a positive length"));
    }
    if !(p.threshold >= 0.0 && p.threshold.is_finite()) {
        return Err(NodeError::param(
            "threshold",
            "must be finite and not negative",
        ));
    }
    if p.bounces > 8 {
        return Err(NodeError::param("bounces", "must be in [0, 8]"));
    }
    if p.sources == Sources::Beam
        && !matches!(
            p.geometry,
            Geometry::Auto | Geometry::ExitNormal | Geometry::Body
        )
    {
        return Err(NodeError::param(
            "sources",
            "beam needs geometry auto, exit_normal or body (the others take the profile's own shape at the sample; `sources: point` goes with them)",
        ));
    }
    Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
    Light::new(&p.light).map(drop)
}
