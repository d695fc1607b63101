//! `sss.lighting`: what a translucent render pays once for an object under a light, whatever
//! the camera (issue 56): the irradiance samples and their light, the bounces between parts
//! and `geometry: body`'s solved grid. Connected to `sss.render`'s `lighting` input it is a node
//! of its own, cached like any other, so a camera move re-renders from the cache and pays only
//! the per-pixel work (the view, the gather, the body's share, single scattering).
//!
//! Its parameters are `sss.render`'s that this work depends on, with the same names, defaults
//! and meaning. With `lighting` connected, `sss.render` takes them from the value; one set on the
//! render itself to something else than both its default and the lighting's is refused, naming
//! the parameter. The render from a cached lighting is the one-node render bit for bit (the
//! octree, beams and shadow map are rebuilt from the stored samples exactly as the one-node
//! render builds them after its bounces; tested).

use super::body::Body;
use super::bounce::Nearest;
use super::setup::{shadow_camera, Bounced, Setup};
use super::{prepare, Energy, Geometry, Homogeneous, Mode, Params, Prepared, Sources};
use crate::sss::octree::Source;
use crate::support::raytrace::light::Light;
use crate::support::raytrace::shadow::ShadowMap;
use crate::support::raytrace::tracer::Tracer;
use crate::types::{DiffusionProfile, LightBounced, Mesh, ScatteringMaterial, SssLighting};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::codec::Encoder;
use mesoflow_runtime::{
    Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar, Value,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value as Json;

crate::view_params! {
    /// `sss.render`'s parameters that do not depend on the camera (each documented there).
    #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
    #[serde(default, deny_unknown_fields)]
    pub struct LightingParams {
        view { light, mm_per_unit, shadows = true, shadow_resolution }
        /// Irradiance sample spacing in mm; default a quarter of the smallest 1/σtr.
        pub spacing: Option<f64> = None,
        /// Most irradiance samples.
        #[schemars(range(min = 64))]
        pub max_points: u32 = 200_000,
        /// Octree criterion ΔA/d² of the bounces' gather and, through `sss.render`, of the
        /// pixels' gather.
        #[schemars(range(min = 0.0))]
        pub threshold: f64 = 0.05,
        /// Whether the render adds single scattering (`energy: half_space` then scales the
        /// multiple scattering alone).
        pub single_scattering: bool = true,
        /// Seed of the sample points.
        pub seed: u64 = 1,
        /// Bounces of light between parts (0 to 8).
        #[schemars(range(min = 0, max = 8))]
        pub bounces: u32 = 2,
        /// `auto`, `planar`, `exit_normal`, `directional` or `body` (as `sss.render`'s); `auto`
        /// is resolved here, and the value holds the result.
        pub geometry: Geometry = Geometry::Auto,
        /// `profile` or `half_space`.
        pub energy: Energy = Energy::Profile,
        /// `beam` or `point`.
        pub sources: Sources = Sources::Beam,
    }
}

impl LightingParams {
    /// The render parameters these stand for (the rest `sss.render`'s defaults).
    fn render_params(&self) -> Result<Params, NodeError> {
        let mut p = serde_json::to_value(Params::default()).map_err(failed)?;
        let own = serde_json::to_value(self).map_err(failed)?;
        if let (Some(p), Some(own)) = (p.as_object_mut(), own.as_object()) {
            for (k, v) in own {
                p.insert(k.clone(), v.clone());
            }
        }
        serde_json::from_value(p).map_err(failed)
    }
}

fn failed(e: serde_json::Error) -> NodeError {
    NodeError::Failed(format!("sss.lighting's parameters: {e}"))
}

pub struct Lighting;

impl Node for Lighting {
    type Params = LightingParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "sss.lighting",
            // 2: the shadow map kept; the beams' kernels with `expneg`.
            version: 2,
            doc: "What a translucent render pays once for a mesh under a light, whatever the camera: the irradiance samples and their light, the bounces between parts, `geometry: body`'s grid. Connect it to sss.render's `lighting` input, so a camera move re-renders from the cache.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the translucent object"),
                Port::input("material", ScatteringMaterial::TYPE, "its medium"),
                Port::input("profile", DiffusionProfile::TYPE, "its diffusion profile"),
            ],
            outputs: vec![
                Port::output("lighting", SssLighting::TYPE, "for sss.render's `lighting` input"),
                Port::output("points", Scalar::TYPE, "irradiance samples"),
                Port::output("spacing", Scalar::TYPE, "their spacing, mm"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &LightingParams) -> Result<(), NodeError> {
        super::check_params(&p.render_params()?)
    }

    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[
            ("bounce_seconds", "wall time of the bounces, s"),
            (
                "body_seconds",
                "wall time of `geometry: body`'s grid and solve, s (absent otherwise)",
            ),
        ]
    }

    fn run(
        &self,
        ctx: &NodeContext,
        lp: &LightingParams,
        inputs: &Inputs,
    ) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        let material = inputs.get::<ScatteringMaterial>("material")?;
        let profile = inputs.get::<DiffusionProfile>("profile")?;
        let p = lp.render_params()?;
        let (value, warnings, timings) = light(mesh, material, profile, &p, Some(ctx))?;
        for w in warnings {
            ctx.warn(w);
        }
        for (name, s) in timings {
            ctx.timing(name, s);
        }
        let (points, spacing) = (value.len() as f64, value.spacing_mm);
        Ok(Outputs::new()
            .with("lighting", value)
            .with("points", Scalar(points))
            .with("spacing", Scalar(spacing)))
    }
}

/// The lighting of `p`'s camera-independent part, its warnings and timings. With the run's
/// `ctx`, a large mesh's BVH comes from and goes to its disk cache (`Tracer::in_context`).
#[allow(clippy::type_complexity)]
fn light(
    mesh: &Mesh,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
    ctx: Option<&NodeContext>,
) -> Result<(SssLighting, Vec<String>, Vec<(&'static str, f64)>), NodeError> {
    super::check_inputs(mesh, profile, p)?;
    let light = Light::new(&p.light)?;
    let tracer = Tracer::in_context(mesh, ctx);
    let mut warnings = Vec::new();
    let prepared = prepare(
        &tracer,
        material,
        profile,
        p,
        &light,
        &Homogeneous,
        &mut warnings,
    )?;
    let mut timings = vec![("bounce_seconds", prepared.setup.bounce_seconds)];
    if prepared.body.is_some() {
        timings.push(("body_seconds", prepared.body_setup_seconds));
    }
    let value = to_value(&prepared, fingerprint(mesh, material, profile))?;
    Ok((value, warnings, timings))
}

/// blake3 of what a lighting was made for.
fn fingerprint(mesh: &Mesh, material: &ScatteringMaterial, profile: &DiffusionProfile) -> String {
    let mut h = blake3::Hasher::new();
    for v in [mesh as &dyn Value, material, profile] {
        let mut e = Encoder::default();
        v.encode(&mut e);
        h.update(&(e.bytes.len() as u64).to_le_bytes());
        h.update(&e.bytes);
    }
    h.finalize().to_hex().to_string()
}

/// The lighting parameters' names (`LightingParams`'s fields).
fn names() -> Vec<String> {
    serde_json::to_value(LightingParams::default())
        .ok()
        .and_then(|v| v.as_object().map(|o| o.keys().cloned().collect()))
        .unwrap_or_default()
}

fn to_value(prepared: &Prepared, made_for: String) -> Result<SssLighting, NodeError> {
    let Prepared {
        setup,
        params,
        body,
        ..
    } = prepared;
    let all = serde_json::to_value(params).map_err(failed)?;
    let own: serde_json::Map<String, Json> = names()
        .into_iter()
        .filter_map(|k| all.get(&k).map(|v| (k, v.clone())))
        .collect();
    let bounced = setup.bounced.as_ref().map(|b| {
        let (points, cell) = b.nearest.parts();
        LightBounced {
            cell,
            points: points.iter().flatten().copied().collect(),
            arriving: b.arriving.iter().flatten().copied().collect(),
        }
    });
    Ok(SssLighting {
        params: Json::Object(own).to_string(),
        made_for,
        area_each: setup.area_each,
        spacing_mm: setup.spacing_mm,
        sources: setup
            .sources
            .iter()
            .flat_map(|s| s.p.into_iter().chain(s.n).chain(s.power))
            .collect(),
        bounced,
        body: body.as_ref().map(|(b, _)| b.to_grid()),
        shadow: setup.shadow.as_ref().map(|m| m.depth.clone()),
    })
}

/// `p` with the lighting's parameters in place of its own: refused where `p` sets one to
/// something else than both its default and the lighting's, or asks for `mode: brdf`.
pub(super) fn merged(p: &Params, lit: &SssLighting) -> Result<Params, NodeError> {
    if p.mode == Mode::Brdf {
        return Err(NodeError::param(
            "mode",
            "`brdf` has no irradiance samples: disconnect `lighting`, or use `diffusion`",
        ));
    }
    let stored: serde_json::Map<String, Json> = serde_json::from_str(&lit.params)
        .map_err(|e| NodeError::input("lighting", format!("its parameters do not read: {e}")))?;
    let mut own = serde_json::to_value(p).map_err(failed)?;
    let default = serde_json::to_value(Params::default()).map_err(failed)?;
    let names = names();
    for (k, v) in &stored {
        if !names.contains(k) {
            return Err(NodeError::input(
                "lighting",
                format!("holds an unknown parameter `{k}`"),
            ));
        }
        let mine = &own[k.as_str()];
        if *mine != default[k.as_str()] && mine != v {
            return Err(NodeError::param(
                k,
                format!(
                    "is {mine} here and {v} in the connected `lighting`: with `lighting` connected it is set on the sss.lighting node"
                ),
            ));
        }
        own[k.as_str()] = v.clone();
    }
    serde_json::from_value(own)
        .map_err(|e| NodeError::input("lighting", format!("its parameters do not apply: {e}")))
}

/// The set-up the one-node render would have made, from a lighting made for this mesh,
/// material and profile, and `p` (already [`merged`]).
pub(super) fn rebuild(
    tracer: &Tracer,
    material: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
    light: &Light,
    lit: &SssLighting,
) -> Result<Prepared, NodeError> {
    if lit.made_for != fingerprint(tracer.mesh, material, profile) {
        return Err(NodeError::input(
            "lighting",
            "was made for another mesh, material or profile than this render's",
        ));
    }
    let sources = lit
        .sources
        .chunks_exact(9)
        .map(|s| Source {
            p: [s[0], s[1], s[2]],
            n: [s[3], s[4], s[5]],
            power: [s[6], s[7], s[8]],
        })
        .collect();
    // The stored depths on the camera they were traced from (a function of the mesh, the
    // light and the size alone).
    let shadow = match (&lit.shadow, p.shadows) {
        (Some(depth), true) => {
            let (camera, bias) = shadow_camera(tracer.mesh, light, p.shadow_resolution)?;
            let texels = camera.width as usize * camera.height as usize;
            if depth.len() != texels {
                return Err(NodeError::input(
                    "lighting",
                    format!(
                        "holds a shadow map of {} depths, not the {texels} its size makes",
                        depth.len()
                    ),
                ));
            }
            Some(ShadowMap {
                camera,
                depth: depth.clone(),
                bias,
            })
        }
        (None, true) => return Err(NodeError::input("lighting", "holds no shadow map")),
        (_, false) => None,
    };
    let mut setup = Setup::assemble(
        tracer,
        material,
        profile,
        p,
        light,
        (sources, lit.area_each, lit.spacing_mm),
        shadow,
    )?;
    setup.bounced = lit.bounced.as_ref().map(|b| Bounced {
        nearest: Nearest::at(
            b.points
                .chunks_exact(3)
                .map(|v| [v[0], v[1], v[2]])
                .collect(),
            b.cell,
        ),
        arriving: b
            .arriving
            .chunks_exact(3)
            .map(|v| [v[0], v[1], v[2]])
            .collect(),
    });
    let body = match (&lit.body, p.geometry) {
        (Some(grid), Geometry::Body) => {
            let body = Body::from_grid(grid, material, setup.beam.clone())?;
            Some((body, grid.h))
        }
        (None, Geometry::Body) => {
            return Err(NodeError::input(
                "lighting",
                "has no body grid for `geometry: body`",
            ))
        }
        _ => None,
    };
    Ok(Prepared {
        setup,
        params: p.clone(),
        body,
        body_setup_seconds: 0.0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{self, Shape};
    use crate::sss::profile;
    use crate::sss::render::{render, render_lit};
    use crate::support::progress::Counter;
    use crate::support::raytrace::camera::CameraParams;
    use mesoflow_runtime::codec::Decoder;

    fn scene() -> (Mesh, ScatteringMaterial, DiffusionProfile) {
        let mesh = primitive::build(&primitive::Params {
            shape: Shape::Torus,
            size: 1.0,
            minor: 0.4,
            segments: [48, 24],
        })
        .unwrap();
        let m = ScatteringMaterial {
            sigma_s_prime: [1.0, 1.5, 2.0],
            sigma_a: [0.05, 0.1, 0.2],
            eta: 1.3,
            g: 0.0,
        };
        let profile = profile::tabulate(&m, &profile::Params::default(), &Counter::none()).profile;
        (mesh, m, profile)
    }

    fn camera(eye: [f64; 3]) -> CameraParams {
        CameraParams {
            eye,
            target: [0.0, 0.0, 0.0],
            resolution: [24, 18],
            ..Default::default()
        }
    }

    /// The lighting through its disk encoding, as a cache hit in another process gives it.
    fn through_the_cache(l: &SssLighting) -> SssLighting {
        let mut e = Encoder::default();
        l.encode(&mut e);
        let v = SssLighting::decode(&mut Decoder::new(SssLighting::TYPE, &e.bytes)).unwrap();
        v.as_any().downcast_ref::<SssLighting>().unwrap().clone()
    }

    #[test]
    fn a_render_from_a_cached_lighting_is_the_one_node_render_bit_for_bit_from_any_camera() {
        let (mesh, m, profile) = scene();
        // A torus sees itself (the bounces run) and is closed (`auto` resolves to `body`).
        let lp = LightingParams {
            max_points: 1500,
            mm_per_unit: 5.0,
            shadow_resolution: 128,
            ..Default::default()
        };
        let (lit, _, _) = light(&mesh, &m, &profile, &lp.render_params().unwrap(), None).unwrap();
        assert!(lit.bounced.is_some() && lit.body.is_some());
        let lit = through_the_cache(&lit);
        for eye in [[0.0, 1.0, 3.0], [2.5, -1.0, 1.0]] {
            let p = Params {
                camera: camera(eye),
                ..lp.render_params().unwrap()
            };
            let one = render(None, &mesh, &m, &profile, &p).unwrap();
            let merged = merged(
                &Params {
                    camera: camera(eye),
                    ..Params::default()
                },
                &lit,
            )
            .unwrap();
            let two = render_lit(
                None,
                &mesh,
                &m,
                &profile,
                &merged,
                &Homogeneous,
                &Counter::none(),
                Some(&lit),
                None,
            )
            .unwrap();
            assert!(one.image.data.iter().any(|&v| v > 0.0));
            assert_eq!(one.image.data, two.image.data, "eye {eye:?}");
            assert_eq!(one.exitance.data, two.exitance.data);
        }
    }

    #[test]
    fn a_lighting_parameter_set_on_the_render_as_well_must_agree_and_another_object_is_refused() {
        let (mesh, m, profile) = scene();
        let lp = LightingParams {
            max_points: 200,
            bounces: 1,
            shadows: false,
            ..Default::default()
        };
        let (lit, _, _) = light(&mesh, &m, &profile, &lp.render_params().unwrap(), None).unwrap();
        // The render's default gives way; the same value agrees; another is refused by name.
        assert_eq!(merged(&Params::default(), &lit).unwrap().bounces, 1);
        let same = Params {
            bounces: 1,
            ..Params::default()
        };
        assert_eq!(merged(&same, &lit).unwrap().bounces, 1);
        let other = Params {
            bounces: 3,
            ..Params::default()
        };
        let e = merged(&other, &lit).unwrap_err().to_string();
        assert!(e.contains("bounces") && e.contains("sss.lighting"), "{e}");
        let brdf = Params {
            mode: Mode::Brdf,
            ..Params::default()
        };
        assert!(merged(&brdf, &lit)
            .unwrap_err()
            .to_string()
            .contains("mode"));
        // A lighting made for another material.
        let thicker = ScatteringMaterial {
            sigma_a: [0.5; 3],
            ..m.clone()
        };
        let p = merged(&Params::default(), &lit).unwrap();
        let e = render_lit(
            None,
            &mesh,
            &thicker,
            &profile,
            &p,
            &Homogeneous,
            &Counter::none(),
            Some(&lit),
            None,
        )
        .err()
        .expect("refused")
        .to_string();
        assert!(e.contains("another mesh, material or profile"), "{e}");
    }
}
