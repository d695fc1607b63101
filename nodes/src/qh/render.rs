//! `qh.render`: a quasi-homogeneous material on a mesh (thesis eq. 5.60, Tong et al. 2005):
//!
//! L(xo, ωo) = ∫ R(xo, ωi, ωo) L(xo, ωi) dωi + fv(xo, ωo) ∫∫ Rd(‖xi − xo‖) L(xi, ωi) f(xi, ωi) dωi dxi
//!
//! The local term R is the local reflectance function, a `Btf` (or its PCA basis) tiled over the
//! mesh as `render.mesh` maps it, lit by the light with shadows. The global term is `sss.render`'s
//! diffusion gather with the homogeneous profile Rd, where the irradiance entering at each sample
//! is scaled by the mesostructure entrance function f and the exitance leaving each pixel by the
//! exiting function fv. Both are textures over the tile, given as images or derived from the
//! tile's `HeightField` by these rules (x along u, y down the tile's rows, z up, in texels):
//!
//! - f(x, ωi) = V(x, ωi) · max(0, n_h(x)·ωi) / cos θi: the light reaches the mesostructure facet
//!   at x only if the height field does not shadow it (V, exact ray cast), with the facet's own
//!   cosine instead of the macro-surface's — so the transmitted irradiance is that of the facet;
//! - fv(x, ωo) = V(x, ωo): diffuse light leaves towards the viewer only where the mesostructure
//!   does not mask it.
//!
//! A flat height field gives f = fv = 1, the homogeneous render; images, when given, are used as
//! they are (RGB, direction-independent, periodic bilinear lookup) and take precedence.

use crate::heightfield::raycast::Caster;
use crate::render::material::{texel_taps, Material, Source};
use crate::render::shade::{Scene, Surface};
use crate::sss::render::{self as sss_render, Weights};
use crate::support::geometry::{dot, V3};
use crate::support::progress::Counter;
use crate::support::raytrace::footprint;
use crate::support::raytrace::layers::Frag;
use crate::support::raytrace::light::Light;
use crate::support::raytrace::shadow::ShadowMap;
use crate::types::{Btf, BtfBasis, DiffusionProfile, HeightField, Image, Mesh, ScatteringMaterial};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

crate::view_params! {
    #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
    #[serde(default, deny_unknown_fields)]
    pub struct Params {
        view { camera, light, tiling, mm_per_unit, shadows = true, shadow_resolution, background }
        // The gather's own parameters default to `sss.render`'s.
        /// Irradiance sample spacing in mm; default a quarter of the smallest 1/σtr.
        pub spacing: Option<f64> = sss_render::Params::default().spacing,
        /// Most irradiance samples.
        #[schemars(range(min = 64))]
        pub max_points: u32 = sss_render::Params::default().max_points,
        /// Octree criterion ΔA/d² (CPU); 0 = brute force.
        #[schemars(range(min = 0.0))]
        pub threshold: f64 = sss_render::Params::default().threshold,
        /// Seed of the sample points.
        pub seed: u64 = sss_render::Params::default().seed,
        /// The global term: `diffusion` (gathered profile) or `brdf` (its total reflectance, local;
        /// for views where light scatters less far than a pixel covers).
        pub mode: sss_render::Mode = sss_render::Params::default().mode,
        /// The global term's geometry, as `sss.render`'s (default `auto`: `body` on a closed
        /// mesh, `exit_normal` on an open one).
        pub geometry: sss_render::Geometry = sss_render::Params::default().geometry,
        /// Where the entering light starts to diffuse, as `sss.render`'s (default `beam`).
        pub sources: sss_render::Sources = sss_render::Params::default().sources,
        /// The diffuse exitance's angular shape, as `sss.render`'s (default `p1`).
        pub emission: sss_render::Emission = sss_render::Params::default().emission,
        /// Bounces between parts of the object, as `sss.render`'s (default 2).
        #[schemars(range(min = 0, max = 8))]
        pub bounces: u32 = sss_render::Params::default().bounces,
    }
}

impl Params {
    /// The global term's parameters (no single scattering: the local term carries the surface).
    fn global(&self) -> sss_render::Params {
        sss_render::Params {
            camera: self.camera.clone(),
            light: self.light.clone(),
            mm_per_unit: self.mm_per_unit,
            spacing: self.spacing,
            max_points: self.max_points,
            threshold: self.threshold,
            single_scattering: false,
            single_scattering_shape: sss_render::SingleShape::HalfSpace,
            shadows: self.shadows,
            shadow_resolution: self.shadow_resolution,
            background: self.background,
            seed: self.seed,
            geometry: self.geometry,
            bounces: self.bounces,
            mode: self.mode,
            energy: sss_render::Energy::Profile,
            emission: self.emission,
            sources: self.sources,
            // Per pixel, as before `gather` existed: what the samples would change here is
            // measured on `sss.render`'s family only.
            gather: sss_render::GatherAt::Pixels,
        }
    }
}

pub struct QhRender;

impl Node for QhRender {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "qh.render",
            // 4: lights beyond the sampled cone extrapolated in the local term. 5: sss.render's
            // silhouette pixels covered in proportion. 6: the global term's `geometry`, `sources`,
            // `emission` and `bounces`, defaulting to sss.render's accurate configuration.
            // 7: the global term skips its bounces on an object that hardly sees itself.
            // 8: the beams' kernels with `expneg` (within 4·10⁻¹⁶ of the library's exp).
            version: 8,
            doc: "Quasi-homogeneous material on a mesh (thesis eq. 5.60): local reflectance (BTF) plus the homogeneous diffusion gather scaled by mesostructure entrance and exiting functions (images, or from a height field).",
            device: DevicePreference::Gpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the object"),
                Port::any_of("lrf", &[Btf::TYPE, BtfBasis::TYPE], "local reflectance function of the tile"),
                Port::input("material", ScatteringMaterial::TYPE, "the homogeneous medium (η)"),
                Port::input("profile", DiffusionProfile::TYPE, "its diffusion profile"),
                Port::optional("height", HeightField::TYPE, "the tile's mesostructure, for f and fv"),
                Port::optional("entrance", Image::TYPE, "entrance function f over the tile (overrides height)"),
                Port::optional("exiting", Image::TYPE, "exiting function fv over the tile (overrides height)"),
            ],
            outputs: vec![
                Port::output("image", Image::TYPE, "linear HDR radiance, local + global"),
                Port::output("global", Image::TYPE, "the global term's diffuse exitance before fv"),
                Port::output("points", "Scalar", "irradiance samples"),
            ]
            .into_iter()
            .chain(footprint::output_ports(true))
            .collect(),
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        sss_render::check_params(&p.global())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        let value = inputs.value("lrf")?;
        let source = if let Some(b) = value.as_any().downcast_ref::<Btf>() {
            Source::Raw(b)
        } else if let Some(b) = value.as_any().downcast_ref::<BtfBasis>() {
            b.check().map_err(|e| NodeError::input("lrf", e))?;
            Source::Basis {
                basis: b,
                owners: b.column_owners(),
            }
        } else {
            return Err(NodeError::input("lrf", "expected a Btf or a BtfBasis"));
        };
        let lrf = Material::new(source);
        let terms = Terms {
            entrance: inputs.opt::<Image>("entrance")?,
            exiting: inputs.opt::<Image>("exiting")?,
            height: inputs.opt::<HeightField>("height")?,
        };
        let r = render(
            ctx.gpu(),
            mesh,
            &lrf,
            inputs.get::<ScatteringMaterial>("material")?,
            inputs.get::<DiffusionProfile>("profile")?,
            &terms,
            p,
            &Counter::new(ctx, 0),
        )?;
        for w in r.warnings {
            ctx.warn(w);
        }
        let out = Outputs::new()
            .with("image", r.image)
            .with("global", r.exitance)
            .with("points", Scalar(r.points as f64));
        Ok(footprint::with_metrics(out, r.footprint.as_ref()))
    }
}

/// Where f and fv come from.
pub struct Terms<'a> {
    pub entrance: Option<&'a Image>,
    pub exiting: Option<&'a Image>,
    pub height: Option<&'a HeightField>,
}

/// The render: local + global, on the GPU when one is given.
#[allow(clippy::too_many_arguments)]
pub fn render(
    gpu: Option<&mesoflow_runtime::Gpu>,
    mesh: &Mesh,
    lrf: &Material,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    terms: &Terms,
    p: &Params,
    watch: &Counter,
) -> Result<sss_render::Rendered, NodeError> {
    for (name, img) in [("entrance", terms.entrance), ("exiting", terms.exiting)] {
        if let Some(i) = img {
            if i.channels < 3 || i.width == 0 || i.height == 0 {
                return Err(NodeError::input(name, "expected a non-empty RGB image"));
            }
            if i.data.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(NodeError::input(
                    name,
                    "values must be finite and not negative",
                ));
            }
        }
    }
    if !p.tiling.iter().all(|t| t.is_finite() && *t > 0.0) {
        return Err(NodeError::param("tiling", "must be positive"));
    }
    let l = &p.light;
    let light = Light::new(l)?;
    let scene = Scene {
        mesh,
        material: lrf,
        mdf: None,
        light,
        tiling: p.tiling,
        shell: 0.0,
        background: p.background,
        parallax: false,
        sides: Vec::new(),
        aspect: Vec::new(),
        env: None,
        footprint: None,
    };
    let shadow = if p.shadows {
        Some(sss_render::shadow_map(
            mesh,
            &Light::new(l)?,
            p.shadow_resolution,
        )?)
    } else {
        None
    };
    let weights = Qh {
        scene: &scene,
        terms,
        caster: terms.height.map(Caster::new),
        shadow,
    };
    sss_render::render_with(gpu, mesh, material, profile, &p.global(), &weights, watch)
}

struct Qh<'a> {
    scene: &'a Scene<'a>,
    terms: &'a Terms<'a>,
    caster: Option<Caster<'a>>,
    shadow: Option<ShadowMap>,
}

fn local(s: &Surface, v: V3) -> V3 {
    [dot(v, s.t), dot(v, s.b), dot(v, s.n)]
}

/// Bilinear periodic RGB lookup of a tile image at tiled texture coordinates.
fn texture(img: &Image, uv: [f64; 2]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (x, y, w) in texel_taps(uv[0], uv[1], img.width, img.height) {
        for (c, o) in out.iter_mut().enumerate() {
            *o += w * img.data[(y * img.width + x) * img.channels + c] as f64;
        }
    }
    out
}

impl Qh<'_> {
    /// The height-field point under tiled texture coordinates, in grid units (texel centres on
    /// integer points), and its normal.
    fn grid_point(&self, c: &Caster, hf: &HeightField, uv: [f64; 2]) -> ([f64; 3], [f64; 3]) {
        let x = uv[0] * hf.width as f64 - 0.5;
        let y = (1.0 - uv[1]) * hf.height as f64 - 0.5;
        let z = c.height(x, y);
        let dx = 0.5 * (c.height(x + 1.0, y) - c.height(x - 1.0, y));
        let dy = 0.5 * (c.height(x, y + 1.0) - c.height(x, y - 1.0));
        let l = (dx * dx + dy * dy + 1.0).sqrt();
        ([x, y, z], [-dx / l, -dy / l, 1.0 / l])
    }

    /// V(x, ω) and the facet cosine for a local direction (t, b, n frame; b is +v, rows go −y).
    fn visibility(&self, uv: [f64; 2], w: V3) -> Option<(f64, f64)> {
        let (c, hf) = (self.caster.as_ref()?, self.terms.height?);
        let (o, n) = self.grid_point(c, hf, uv);
        let d = [w[0], -w[1], w[2]];
        let facet = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).max(0.0);
        // Start a hair above the surface so the ray leaves its own facet.
        let lifted = [o[0], o[1], o[2] + 1e-6];
        let visible = match c.cast(lifted, d, 1e-6) {
            Ok(_) => 0.0,
            Err(_) => 1.0,
        };
        Some((visible, facet))
    }
}

impl Weights for Qh<'_> {
    fn texture(&self) -> Option<footprint::Texture> {
        Some(footprint::Texture {
            tiling: self.scene.tiling,
            texels: [self.scene.material.width, self.scene.material.height],
        })
    }

    fn entrance(&self, at: &Frag, to_light: V3) -> [f64; 3] {
        let s = self.scene.surface(at);
        if let Some(img) = self.terms.entrance {
            return texture(img, s.uv);
        }
        let wi = local(&s, to_light);
        if wi[2] <= 0.0 {
            return [0.0; 3];
        }
        match self.visibility(s.uv, wi) {
            Some((v, facet)) => [v * facet / wi[2]; 3],
            None => [1.0; 3],
        }
    }

    fn pixel(&self, _px: usize, at: &Frag, to_viewer: V3) -> ([f64; 3], [f64; 3]) {
        let s = self.scene.surface(at);
        let wo = local(&s, to_viewer);
        let exit = if let Some(img) = self.terms.exiting {
            texture(img, s.uv)
        } else if wo[2] <= 0.0 {
            [0.0; 3]
        } else {
            match self.visibility(s.uv, wo) {
                Some((v, _)) => [v; 3],
                None => [1.0; 3],
            }
        };
        // The local reflectance under the light, with shadows (as render.mesh shades).
        let light = &self.scene.light;
        let (to_light, irradiance) = light.at(s.p);
        let wi = local(&s, to_light);
        let lit =
            wi[2] > 0.0 && wo[2] > 0.0 && self.shadow.as_ref().is_none_or(|m| m.lit(s.p, wi[2]));
        let local_term = if lit {
            self.scene
                .material
                .eval(s.uv[0], s.uv[1], wo, wi)
                .map(|c| c * irradiance)
        } else {
            [0.0; 3]
        };
        (exit, local_term)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{self, Shape};
    use crate::sss::profile;
    use crate::support::raytrace::camera::CameraParams;
    use crate::support::raytrace::light::LightParams;
    use crate::types::{Direction, DirectionPair};

    /// A 4×4 BTF whose every texel and direction pair holds `value`.
    fn constant_btf(value: f32) -> Btf {
        let dirs = [
            (0.0, 0.0),
            (45.0, 0.0),
            (45.0, 90.0),
            (45.0, 180.0),
            (45.0, 270.0),
            (80.0, 0.0),
        ];
        let mut pairs = Vec::new();
        for v in dirs {
            for l in dirs {
                pairs.push(DirectionPair {
                    view: Direction::degrees(v.0, v.1),
                    light: Direction::degrees(l.0, l.1),
                });
            }
        }
        Btf {
            width: 4,
            height: 4,
            data: vec![value; pairs.len() * 48],
            pairs,
        }
    }

    fn medium() -> ScatteringMaterial {
        ScatteringMaterial {
            sigma_s_prime: [1.0, 1.5, 2.0],
            sigma_a: [0.05, 0.1, 0.2],
            eta: 1.3,
            g: 0.0,
        }
    }

    fn scene() -> (Mesh, ScatteringMaterial, DiffusionProfile, Params) {
        let mesh = primitive::build(&primitive::Params {
            shape: Shape::Sphere,
            size: 1.0,
            segments: [48, 24],
            ..Default::default()
        })
        .unwrap();
        let m = medium();
        let prof = profile::tabulate(
            &m,
            &profile::Params {
                model: profile::Model::Dipole,
                ..Default::default()
            },
            &crate::support::progress::Counter::none(),
        )
        .profile;
        let p = Params {
            camera: CameraParams {
                eye: [0.0, 0.5, 4.0],
                resolution: [16, 16],
                ..Default::default()
            },
            light: LightParams {
                direction: [1.0, 0.8, 0.3],
                position: None,
                intensity: 3.0,
                ..Default::default()
            },
            shadow_resolution: 128,
            mm_per_unit: 5.0,
            max_points: 3000,
            // The weights' algebra holds for any global term; the classic one is the cheapest.
            geometry: sss_render::Geometry::Planar,
            sources: sss_render::Sources::Point,
            emission: sss_render::Emission::Diffuse,
            bounces: 0,
            ..Default::default()
        };
        (mesh, m, prof, p)
    }

    fn flat(n: usize) -> HeightField {
        HeightField::from_fn(n, n, |_, _| 2.0)
    }

    #[test]
    fn flat_mesostructure_and_a_black_lrf_give_the_homogeneous_render() {
        // Flat height field: V = 1 and the facet normal is the surface's, so f = fv = 1 exactly;
        // a zero LRF adds nothing. The result must be sss.render's, bit for bit, with the
        // global term's defaults (the body, the beam's sources, P1's exit, two bounces).
        let (mesh, m, _, p) = scene();
        let d = Params::default();
        let p = Params {
            geometry: d.geometry,
            sources: d.sources,
            emission: d.emission,
            bounces: d.bounces,
            max_points: 1000,
            ..p
        };
        let prof = profile::tabulate(&m, &profile::Params::default(), &Counter::none()).profile;
        let btf = constant_btf(0.0);
        let lrf = Material::new(Source::Raw(&btf));
        let hf = flat(16);
        let terms = Terms {
            entrance: None,
            exiting: None,
            height: Some(&hf),
        };
        let qh = render(None, &mesh, &lrf, &m, &prof, &terms, &p, &Counter::none()).unwrap();
        let homogeneous = sss_render::render(None, &mesh, &m, &prof, &p.global()).unwrap();
        assert_eq!(qh.image.data, homogeneous.image.data);
    }

    #[test]
    fn entrance_images_scale_the_global_term_and_the_lrf_adds_the_local_term() {
        let (mesh, m, prof, p) = scene();
        let black = constant_btf(0.0);
        let lrf = Material::new(Source::Raw(&black));
        let none = Terms {
            entrance: None,
            exiting: None,
            height: None,
        };
        let base = render(None, &mesh, &lrf, &m, &prof, &none, &p, &Counter::none()).unwrap();
        // The global term is linear in the entering irradiance: f = 0.5 halves the exitance.
        let half = Image {
            width: 2,
            height: 2,
            channels: 3,
            data: vec![0.5; 12],
        };
        let terms = Terms {
            entrance: Some(&half),
            exiting: None,
            height: None,
        };
        let halved = render(None, &mesh, &lrf, &m, &prof, &terms, &p, &Counter::none()).unwrap();
        for (a, b) in halved.exitance.data.iter().zip(&base.exitance.data) {
            assert!(
                (a - 0.5 * b).abs() <= 1e-6 * b.abs().max(1e-6),
                "{a} vs {b}"
            );
        }
        // A constant LRF k adds k·I wherever the light and the viewer both see the surface
        // (the BTF's direction blend of equal values is that value).
        let k = 0.25f32;
        let bright = constant_btf(k);
        let lrf = Material::new(Source::Raw(&bright));
        let lit = render(None, &mesh, &lrf, &m, &prof, &none, &p, &Counter::none()).unwrap();
        let added: Vec<f32> = lit
            .image
            .data
            .iter()
            .zip(&base.image.data)
            .map(|(a, b)| a - b)
            .collect();
        let max = added.iter().fold(0f32, |a, b| a.max(*b));
        assert!((max - k * 3.0).abs() < 1e-5, "{max}");
        assert!(added.iter().all(|v| *v >= -1e-6 && *v <= k * 3.0 + 1e-5));
    }

    #[test]
    fn a_woven_mesostructure_masks_and_shadows_but_stays_finite() {
        let (mesh, m, prof, mut p) = scene();
        let btf = constant_btf(0.0);
        let lrf = Material::new(Source::Raw(&btf));
        let weave = crate::heightfield::procedural::generate(
            &NodeContext::detached(None),
            &crate::heightfield::procedural::Params {
                pattern: crate::heightfield::procedural::Pattern::Weave,
                size: 32,
                depth: 6.0,
                count: 2,
                ..Default::default()
            },
        )
        .unwrap();
        // Grazing light: the weave shadows much of the tile.
        p.light.direction = [1.0, 0.05, 0.0];
        let terms = Terms {
            entrance: None,
            exiting: None,
            height: Some(&weave),
        };
        let woven = render(None, &mesh, &lrf, &m, &prof, &terms, &p, &Counter::none()).unwrap();
        let hf = flat(32);
        let flat_terms = Terms {
            entrance: None,
            exiting: None,
            height: Some(&hf),
        };
        let plain = render(
            None,
            &mesh,
            &lrf,
            &m,
            &prof,
            &flat_terms,
            &p,
            &Counter::none(),
        )
        .unwrap();
        assert!(woven.image.data.iter().all(|v| v.is_finite() && *v >= 0.0));
        let sum = |d: &[f32]| d.iter().map(|v| *v as f64).sum::<f64>();
        let (w, f) = (sum(&woven.image.data), sum(&plain.image.data));
        eprintln!("woven / flat radiance: {:.3}", w / f);
        assert!(w < f && w > 0.0, "{w} vs {f}");
        let bad = Image {
            width: 1,
            height: 1,
            channels: 3,
            data: vec![f32::NAN; 3],
        };
        let terms = Terms {
            entrance: Some(&bad),
            exiting: None,
            height: None,
        };
        assert!(
            render(None, &mesh, &lrf, &m, &prof, &terms, &p, &Counter::none())
                .is_err_and(|e| e.to_string().contains("entrance"))
        );
    }
}
