//! `export.pbrt`: the scene `render.reference` renders, as a pbrt-v4 scene file (`pbrt
//! scene.pbrt`) with its mesh (PLY) and albedo map (EXR) beside it.
//!
//! The mapping, each the closest pbrt-v4 has to the reference (pbrt is not installable here, so
//! these files are checked against pbrt-v4's scene-file grammar by `tests/export.rs`, not
//! rendered):
//! - the camera → `LookAt` after `Scale -1 1 1` (pbrt's camera space is left-handed: without
//!   the mirror the image is flipped left to right) and `perspective`, whose `fov` is the
//!   shorter image axis's (converted where the image is taller than wide), or `orthographic`
//!   with the view's `screenwindow`; a box pixel filter; `independent` samples;
//! - the lights → `distant` (from 0 towards the light's travel direction, `L` the irradiance) or
//!   `point` (`I`); pbrt-v4 normalises an RGB light's illuminant to 1 nit, which is what its
//!   sRGB film reads back as 1; an environment → `infinite` with its image resampled onto
//!   pbrt-v4's equal-area octahedral square (512 × 512, each texel the environment along its
//!   centre's direction, world axes as mesoflow's), which is what that light reads;
//! - direct light only → `path` with `maxdepth` 1; with `bounces` N, `maxdepth` N + 1;
//! - Lambert → `diffuse`; Ward and GGX → `mix` of `diffuse` and a `conductor` of GGX roughness α
//!   (pbrt-v4's only microfacet distribution, so Ward's Beckmann lobe becomes GGX of the same α)
//!   whose normal-incidence reflectance is the lobe's scale; pbrt's `diffuse` is two-sided where
//!   the reference's surfaces are one-sided (it sees no back faces of a closed mesh);
//! - a medium → `translucency: "volume"` (the default): the mesh bounds a `homogeneous` medium
//!   through a `MediumInterface`, behind an `interface` (η = 1) or rough `dielectric` material
//!   (on the triangles' own normals: the PLY has none there, as the reference refracts),
//!   rendered by `volpath` (the reference's own light transport); or `"subsurface"`: pbrt's
//!   `subsurface` material with the same σa, σs, g and η (its BSSRDF: faster, its own
//!   diffusion approximation).

use super::scene::{self, Diffuse, Look, Scene};
use crate::reflectance::models::Model;
use crate::render::reference::Params as RenderParams;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Translucency {
    /// A homogeneous medium inside the mesh, path traced (`volpath`): the reference's transport.
    #[default]
    Volume,
    /// pbrt's `subsurface` material (a BSSRDF) with the same coefficients.
    Subsurface,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
pub struct Params {
    /// The scene file, relative to the output folder. The mesh (`<stem>.ply`), the albedo map
    /// (`<stem>_albedo.exr`) and pbrt's image (`<stem>.exr`, where pbrt renders it) are named
    /// beside it.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
    /// How a `medium` is rendered: a path-traced volume (the reference's transport) or pbrt's
    /// subsurface material.
    #[serde(default)]
    pub translucency: Translucency,
    /// `render.reference`'s parameters, the same names and defaults.
    #[serde(flatten)]
    pub render: RenderParams,
}

pub struct ExportPbrt;

impl Node for ExportPbrt {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "export.pbrt",
            version: 1,
            doc: "Writes the scene render.reference renders from the same parameters as a pbrt-v4 scene with its mesh (PLY) and albedo map (EXR): camera, light, Lambert, Ward or GGX (a mix of diffuse and a rough conductor), or a homogeneous medium (path traced, or pbrt's subsurface material).",
            device: DevicePreference::Cpu,
            inputs: scene::inputs(),
            outputs: scene::outputs(),
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        scene::check(&p.path, &p.render)?;
        // The files are named in the scene by their names: pbrt's strings have no escapes.
        if p.path.contains('"') {
            return Err(NodeError::param(
                "path",
                "cannot hold a double quote: pbrt's scene files name files in quotes, with no escapes",
            ));
        }
        Ok(())
    }

    fn files(
        &self,
        p: &Params,
        base: &std::path::Path,
    ) -> Result<Vec<std::path::PathBuf>, NodeError> {
        Ok(p.render.light.files(base))
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mut s = scene::build(ctx, &p.path, &p.render, inputs)?;
        if let Some(env) = s.environment.clone() {
            let n = EQUAL_AREA_SIDE;
            let mut texels = Vec::with_capacity(n * n * 3);
            for y in 0..n {
                for x in 0..n {
                    let d = equal_area_direction(
                        (x as f64 + 0.5) / n as f64,
                        (y as f64 + 0.5) / n as f64,
                    );
                    texels.extend(env.radiance(d).map(|c| c as f32));
                }
            }
            let file = scene::environment_file(&mut s, &p.path, n, n, texels)?;
            s.light.environment = Some(file);
        }
        let image = std::path::Path::new(&p.path)
            .with_extension("exr")
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("pbrt.exr")
            .to_string();
        let text = write(&s, p.translucency, &image);
        Ok(scene::outputs_with(s, &p.path, text))
    }
}

/// Texels per side of the environment's equal-area image.
const EQUAL_AREA_SIDE: usize = 512;

/// pbrt-v4's equal-area square-to-sphere map (Clarberg 2008), (u, v) ∈ [0, 1]², v down the
/// image: the direction a texel of an `infinite` light's image holds.
pub fn equal_area_direction(u: f64, v: f64) -> [f64; 3] {
    let (u, v) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    let (up, vp) = (u.abs(), v.abs());
    let signed = 1.0 - (up + vp);
    let r = 1.0 - signed.abs();
    let phi = if r == 0.0 { 1.0 } else { (vp - up) / r + 1.0 } * std::f64::consts::FRAC_PI_4;
    let z = (1.0 - r * r).copysign(signed);
    let (c, s) = (phi.cos().copysign(u), phi.sin().copysign(v));
    let k = r * (2.0 - r * r).max(0.0).sqrt();
    [c * k, s * k, z]
}

fn nums(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
    parts.join(" ")
}

/// A quoted pbrt string (its grammar has no escapes; `check` refuses a path with a quote).
fn quoted(s: &str) -> String {
    format!("\"{s}\"")
}

/// The scene file's text; `image` is the film's file name.
pub fn write(s: &Scene, translucency: Translucency, image: &str) -> String {
    let mut x = String::new();
    let c = &s.camera;
    let [w, h] = c.resolution;
    let _ = writeln!(
        x,
        "# Written by mesoflow's export.pbrt: the scene render.reference renders from the same parameters (pbrt-v4)."
    );
    let _ = writeln!(
        x,
        "# pbrt's camera space is left-handed: the mirror keeps the image the right way round."
    );
    let _ = writeln!(x, "Scale -1 1 1");
    let _ = writeln!(
        x,
        "LookAt {}\n       {}\n       {}",
        nums(&c.eye),
        nums(&c.target),
        nums(&c.up)
    );
    match c.orthographic {
        None => {
            // pbrt's fov is the shorter image axis's.
            let fov = if h <= w {
                c.fov
            } else {
                scene::horizontal_fov(c.fov, w, h)
            };
            let _ = writeln!(x, "Camera \"perspective\" \"float fov\" [ {fov} ]");
        }
        Some(half) => {
            let a = half * w as f64 / h as f64;
            let _ = writeln!(
                x,
                "Camera \"orthographic\" \"float screenwindow\" [ {} ]",
                nums(&[-a, a, -half, half])
            );
        }
    }
    let _ = writeln!(
        x,
        "Sampler \"independent\" \"integer pixelsamples\" [ {} ] \"integer seed\" [ {} ]",
        s.samples,
        // pbrt's seed is an int.
        s.seed % (i32::MAX as u64)
    );
    let _ = writeln!(
        x,
        "Film \"rgb\" \"integer xresolution\" [ {w} ] \"integer yresolution\" [ {h} ] \"string filename\" [ {} ]",
        quoted(image)
    );
    let _ = writeln!(
        x,
        "PixelFilter \"box\" \"float xradius\" [ 0.5 ] \"float yradius\" [ 0.5 ]"
    );
    match &s.look {
        Look::Surface { .. } => {
            // pbrt's depth counts reflections: 1 is direct light, N + 1 adds N bounces.
            let _ = writeln!(
                x,
                "Integrator \"path\" \"integer maxdepth\" [ {} ]",
                s.bounces + 1
            );
        }
        Look::Medium(_) => {
            // No depth limit in the reference: paths end when they leave or are absorbed.
            let _ = writeln!(
                x,
                "Integrator \"volpath\" \"integer maxdepth\" [ 1000000000 ]"
            );
        }
    }
    let _ = writeln!(x, "\nWorldBegin\n");
    let i = s.light.intensity;
    match s.light.position {
        _ if s.environment.is_some() => {
            let file = s.light.environment.as_deref().unwrap_or_default();
            let _ = writeln!(
                x,
                "LightSource \"infinite\" \"string filename\" [ {} ]",
                quoted(file)
            );
        }
        None => {
            let _ = writeln!(
                x,
                "LightSource \"distant\" \"point3 from\" [ 0 0 0 ] \"point3 to\" [ {} ] \"rgb L\" [ {} ]",
                nums(&s.direction.map(|d| -d)),
                nums(&[i; 3])
            );
        }
        Some(at) => {
            let _ = writeln!(
                x,
                "LightSource \"point\" \"point3 from\" [ {} ] \"rgb I\" [ {} ]",
                nums(&at),
                nums(&[i; 3])
            );
        }
    }
    let shape = format!(
        "Shape \"plymesh\" \"string filename\" [ {} ]",
        quoted(&s.mesh_file)
    );
    match &s.look {
        Look::Surface { diffuse, lobe } => {
            let reflectance = match diffuse {
                Diffuse::Rgb(v) => format!("\"rgb reflectance\" [ {} ]", nums(v)),
                Diffuse::Texture { file, tiling } => {
                    let _ = writeln!(
                        x,
                        "Texture \"albedo\" \"spectrum\" \"imagemap\" \"string filename\" [ {} ] \"float uscale\" [ {} ] \"float vscale\" [ {} ] \"string filter\" [ \"bilinear\" ] \"string wrap\" [ \"repeat\" ] \"string encoding\" [ \"linear\" ]",
                        quoted(file),
                        tiling[0],
                        tiling[1]
                    );
                    "\"texture reflectance\" [ \"albedo\" ]".to_string()
                }
            };
            let _ = writeln!(
                x,
                "MakeNamedMaterial \"diffuse\" \"string type\" [ \"diffuse\" ] {reflectance}"
            );
            let name = match lobe {
                None => "diffuse",
                Some(l) => {
                    let note = match l.model {
                        Model::Ggx => "GGX",
                        _ => "Ward's lobe as GGX of the same roughness",
                    };
                    // pbrt's conductor from a reflectance r sets k = 2√r/√(1 − r): r < 1.
                    let r = l.reflectance.min(0.999);
                    let _ = writeln!(x, "# The glossy lobe: {note}.");
                    let _ = writeln!(
                        x,
                        "MakeNamedMaterial \"lobe\" \"string type\" [ \"conductor\" ] \"float roughness\" [ {} ] \"bool remaproughness\" false \"rgb reflectance\" [ {} ]",
                        l.alpha,
                        nums(&[r; 3])
                    );
                    let _ = writeln!(
                        x,
                        "MakeNamedMaterial \"surface\" \"string type\" [ \"mix\" ] \"string materials\" [ \"diffuse\" \"lobe\" ] \"float amount\" [ {} ]",
                        l.weight
                    );
                    "surface"
                }
            };
            let _ = writeln!(
                x,
                "\nAttributeBegin\n    NamedMaterial \"{name}\"\n    {shape}\nAttributeEnd"
            );
        }
        Look::Medium(m) => {
            let coefficients = format!(
                "\"rgb sigma_a\" [ {} ] \"rgb sigma_s\" [ {} ] \"float scale\" [ 1 ]",
                nums(&m.sigma_a),
                nums(&m.sigma_s)
            );
            let roughness = m.roughness.unwrap_or(0.0);
            match translucency {
                Translucency::Volume => {
                    let _ = writeln!(
                        x,
                        "MakeNamedMedium \"interior\" \"string type\" [ \"homogeneous\" ] {coefficients} \"float g\" [ {} ]",
                        m.g
                    );
                    let boundary = match m.roughness {
                        None => "Material \"interface\"".to_string(),
                        Some(alpha) => format!(
                            "Material \"dielectric\" \"float eta\" [ {} ] \"float roughness\" [ {alpha} ] \"bool remaproughness\" false",
                            m.eta
                        ),
                    };
                    let _ = writeln!(
                        x,
                        "\nAttributeBegin\n    MediumInterface \"interior\" \"\"\n    {boundary}\n    {shape}\nAttributeEnd"
                    );
                }
                Translucency::Subsurface => {
                    let _ = writeln!(
                        x,
                        "\nAttributeBegin\n    Material \"subsurface\" {coefficients} \"float g\" [ {} ] \"float eta\" [ {} ] \"float roughness\" [ {roughness} ] \"bool remaproughness\" false\n    {shape}\nAttributeEnd",
                        m.g, m.eta
                    );
                }
            }
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_path_pbrt_cannot_name_is_refused_by_name() {
        let p: Params = serde_json::from_value(serde_json::json!({ "path": "a\"b.pbrt" })).unwrap();
        let e = ExportPbrt.check(&p).unwrap_err().to_string();
        assert!(e.contains("path") && e.contains("quote"), "{e}");
        let p: Params = serde_json::from_value(serde_json::json!({ "path": "ok.pbrt" })).unwrap();
        assert!(ExportPbrt.check(&p).is_ok());
    }
}

#[cfg(test)]
mod equal_area_tests {
    use super::equal_area_direction;

    /// Unit directions, the square's centre straight up and its corners straight down, and
    /// equal areas: a uniform grid over the square averages z to 0 and z² to 1/3, as the
    /// uniform sphere does (midpoints of 400², error ~1e-5).
    #[test]
    fn the_equal_area_map_covers_the_sphere_evenly() {
        let up = equal_area_direction(0.5, 0.5);
        assert!((up[2] - 1.0).abs() < 1e-12);
        assert!((equal_area_direction(0.0, 0.0)[2] + 1.0).abs() < 1e-12);
        let n = 400;
        let (mut z, mut z2) = (0.0, 0.0);
        for y in 0..n {
            for x in 0..n {
                let d =
                    equal_area_direction((x as f64 + 0.5) / n as f64, (y as f64 + 0.5) / n as f64);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-9);
                z += d[2];
                z2 += d[2] * d[2];
            }
        }
        let m = (n * n) as f64;
        assert!(
            (z / m).abs() < 1e-3 && (z2 / m - 1.0 / 3.0).abs() < 1e-3,
            "{} {}",
            z / m,
            z2 / m
        );
    }
}
