//! What both exporters read the same way: `render.reference`'s parameters (flattened into each
//! export node's own, beside the scene file's `path`) and inputs, checked as the reference
//! checks them and turned into the renderer-neutral [`Scene`]: the camera and light as given,
//! the medium's coefficients in world units, and a surface's reflectance as the mix of two BSDFs
//! that renderers offer (neither Mitsuba 3 nor pbrt-v4 adds a diffuse and a glossy BSDF, both
//! blend them), plus the mesh (PLY: without vertex normals behind a rough boundary, which the
//! reference refracts on the triangles' own) and albedo map (EXR) written beside the scene file.

use crate::mesh::write::ply_with;
use crate::reflectance::models::Model;
use crate::render::reference::{check_albedo, Params as RenderParams, Reference};
use crate::render::volume::Medium as CheckedMedium;
use crate::support::formats::encode_exr;
use crate::support::raytrace::camera::CameraParams;
use crate::support::raytrace::environment::Environment;
use crate::support::raytrace::light::{Light, LightParams};
use crate::types::{Image, Mesh, ScatteringMaterial};
use mesoflow_runtime::{Artifact, Artifacts, Inputs, Node, NodeContext, NodeError, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// `export.mitsuba`'s parameters: where the scene file goes, and the render it describes.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
pub struct Params {
    /// The scene file, relative to the output folder. The mesh (`<stem>.ply`) and the albedo
    /// map (`<stem>_albedo.exr`) are written beside it and named relative to it.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
    /// `render.reference`'s parameters, the same names and defaults: the exported scene is
    /// the one that node renders from them.
    #[serde(flatten)]
    pub render: RenderParams,
}

/// The ports both exporters take: `render.reference`'s, less the normal map.
pub fn inputs() -> Vec<Port> {
    vec![
        Port::input("mesh", Mesh::TYPE, "the geometry, its normals the shading normals"),
        Port::optional(
            "albedo",
            Image::TYPE,
            "diffuse albedo over the tile (RGB), instead of `albedo`: written as an EXR texture",
        ),
        Port::optional(
            "medium",
            ScatteringMaterial::TYPE,
            "a homogeneous medium filling the closed mesh (sss.material, qh.fit_dipole), instead of the surface reflectance",
        ),
    ]
}

/// The output both exporters give.
pub fn outputs() -> Vec<Port> {
    vec![Port::output(
        "files",
        Artifacts::TYPE,
        "the scene file, the mesh and any texture, written under the output folder",
    )]
}

/// The `files` output: the scene's mesh and texture, and the scene file itself at `path`.
pub fn outputs_with(scene: Scene, path: &str, text: String) -> Outputs {
    let mut files = scene.files;
    files.push(Artifact {
        path: path.to_string(),
        bytes: text.into_bytes(),
    });
    Outputs::new().with("files", Artifacts { files })
}

/// A scene as both writers see it.
pub struct Scene {
    pub camera: CameraParams,
    pub light: LightParams,
    /// Unit direction towards a directional light.
    pub direction: [f64; 3],
    /// The environment, where the light is one (intensity applied; its rotation is its own).
    pub environment: Option<Arc<Environment>>,
    pub samples: u32,
    pub seed: u64,
    /// Reflections after the direct one a surface path follows (`render.reference`'s `bounces`).
    pub bounces: u32,
    /// The mesh's file name, relative to the scene file.
    pub mesh_file: String,
    pub look: Look,
    /// The mesh and texture files, paths relative to the output folder.
    pub files: Vec<Artifact>,
}

pub enum Look {
    Surface {
        diffuse: Diffuse,
        lobe: Option<Lobe>,
    },
    Medium(Medium),
}

/// The diffuse BSDF's reflectance: ρd / (1 − w) where a lobe takes the weight w.
pub enum Diffuse {
    Rgb([f64; 3]),
    /// An EXR texture (file name relative to the scene file), repeated `tiling` times per unit
    /// of texture coordinate.
    Texture {
        file: String,
        tiling: [f64; 2],
    },
}

/// The glossy BSDF of a Ward or GGX surface, mixed with the diffuse one: the mix
/// (1 − w)·diffuse + w·glossy equals ρd/π + ρs·lobe when the diffuse BSDF reflects ρd/(1 − w) and
/// the glossy one ρs/w, with w = ρs / (ρs + max ρd), so that both stay at most 1 exactly where
/// ρd + ρs ≤ 1.
pub struct Lobe {
    /// Ward (a Beckmann microfacet lobe in the renderers) or GGX.
    pub model: Model,
    pub alpha: f64,
    /// The glossy BSDF's share w of the mix.
    pub weight: f64,
    /// The glossy BSDF's reflectance scale, ρs / w.
    pub reflectance: f64,
}

/// A homogeneous medium in world units (mm⁻¹ × mm per unit).
pub struct Medium {
    pub sigma_s: [f64; 3],
    pub sigma_a: [f64; 3],
    pub g: f64,
    pub eta: f64,
    /// GGX α of a rough dielectric boundary (η ≠ 1); `None` at η = 1, an index-matched one.
    pub roughness: Option<f64>,
}

/// The environment's file beside the scene file: `texels` (RGB, row-major from the top) of
/// `width` × `height` as EXR; the name relative to the scene file.
pub fn environment_file(
    scene: &mut Scene,
    scene_path: &str,
    width: usize,
    height: usize,
    texels: Vec<f32>,
) -> Result<String, NodeError> {
    let (full, name) = beside(scene_path, "_environment.exr");
    let img = Image {
        width,
        height,
        channels: 3,
        data: texels,
    };
    let bytes =
        encode_exr(&img).map_err(|e| NodeError::Failed(format!("the environment's EXR: {e}")))?;
    scene.files.push(Artifact { path: full, bytes });
    Ok(name)
}

/// The file beside `scene_path` with `suffix` after its stem: (path under the output folder,
/// name relative to the scene file).
fn beside(scene_path: &str, suffix: &str) -> (String, String) {
    let p = std::path::Path::new(scene_path);
    let stem = p
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene")
        .to_string();
    let name = format!("{stem}{suffix}");
    let full = match p
        .parent()
        .and_then(|d| d.to_str())
        .filter(|d| !d.is_empty())
    {
        Some(dir) => format!("{dir}/{name}"),
        None => name.clone(),
    };
    (full, name)
}

/// The checks `export.*` adds to `render.reference`'s at validation: a background is only a
/// pixel value there, in the renderers it would be light.
pub fn check(path: &str, render: &RenderParams) -> Result<(), NodeError> {
    Reference.check(render)?;
    if render.background != [0.0; 3] {
        return Err(NodeError::param(
            "background",
            "must be black to export: in Mitsuba and pbrt a background is an emitter that lights the object too; the exported films keep alpha (Mitsuba) for compositing instead",
        ));
    }
    if !path.contains('.') {
        return Err(NodeError::param(
            "path",
            "needs a file name with an extension (e.g. `mitsuba/scene.xml`)",
        ));
    }
    Ok(())
}

/// Reads the inputs and builds the scene; every refusal names its port or parameter.
pub fn build(
    ctx: &NodeContext,
    path: &str,
    r: &RenderParams,
    inputs: &Inputs,
) -> Result<Scene, NodeError> {
    check(path, r)?;
    let mesh = inputs.get::<Mesh>("mesh")?;
    mesh.check().map_err(|e| NodeError::input("mesh", e))?;
    let light = Light::open(&r.light, ctx)?;
    let (mesh_path, mesh_file) = beside(path, ".ply");
    let mut files = Vec::new();
    let albedo = inputs.opt::<Image>("albedo")?;
    let look = match inputs.opt::<ScatteringMaterial>("medium")? {
        Some(m) => {
            if albedo.is_some() {
                return Err(NodeError::input(
                    "medium",
                    "a medium's boundary has no albedo: connect `albedo` to a surface export instead",
                ));
            }
            // The reference's own checks of the coefficients and the boundary.
            CheckedMedium::new(m, r.mm_per_unit, r.boundary_roughness, r.surface_reflection)
                .map_err(|e| NodeError::input("medium", e))?;
            // The reference's own test of an index-matched boundary.
            let matched = (m.eta - 1.0).abs() <= 1e-9;
            if !matched && !r.surface_reflection {
                return Err(NodeError::param(
                    "surface_reflection",
                    "must be true to export: Mitsuba and pbrt render the light a dielectric boundary reflects, with no switch to drop it",
                ));
            }
            let k = r.mm_per_unit;
            Look::Medium(Medium {
                sigma_s: m.sigma_s_prime.map(|s| s / (1.0 - m.g) * k),
                sigma_a: m.sigma_a.map(|a| a * k),
                g: m.g,
                eta: if matched { 1.0 } else { m.eta },
                roughness: if matched { None } else { r.boundary_roughness },
            })
        }
        None => surface(path, r, albedo, &mut files)?,
    };
    // The reference refracts at a rough boundary on the triangles' own normals: the mesh goes
    // without its vertex normals there, so both renderers do too.
    let normals = !matches!(&look, Look::Medium(m) if m.roughness.is_some());
    files.insert(
        0,
        Artifact {
            path: mesh_path,
            bytes: ply_with(mesh, normals),
        },
    );
    Ok(Scene {
        camera: r.camera.clone(),
        light: r.light.clone(),
        direction: light.direction,
        environment: light.environment.clone(),
        samples: r.samples,
        seed: r.seed,
        bounces: r.bounces,
        mesh_file,
        look,
        files,
    })
}

/// The diffuse reflectance (a colour or a texture) and the lobe's mix.
fn surface(
    path: &str,
    r: &RenderParams,
    albedo: Option<&Image>,
    files: &mut Vec<Artifact>,
) -> Result<Look, NodeError> {
    let (max_diffuse, port) = match albedo {
        Some(a) => {
            check_albedo(a)?;
            let max = a
                .data
                .chunks_exact(a.channels)
                .flat_map(|px| &px[..3])
                .fold(0.0f64, |m, v| m.max(*v as f64));
            (max, "input `albedo`")
        }
        None => (r.albedo.iter().fold(0.0f64, |m, v| m.max(*v)), "`albedo`"),
    };
    let rho_s = match r.brdf {
        Model::Lambert => 0.0,
        _ => r.specular,
    };
    if max_diffuse + rho_s > 1.0 {
        let msg = format!(
            "the diffuse albedo ({port}, up to {max_diffuse:.4}) plus the specular albedo ({rho_s}) is {:.4}: a renderer's reflectances are at most 1, and so must their sum be",
            max_diffuse + rho_s
        );
        return Err(match albedo {
            Some(_) => NodeError::input("albedo", msg),
            None => NodeError::param("albedo", msg),
        });
    }
    let lobe = (rho_s > 0.0).then(|| {
        let weight = rho_s / (rho_s + max_diffuse);
        Lobe {
            model: match r.brdf {
                Model::Ggx => Model::Ggx,
                _ => Model::Ward,
            },
            alpha: r.roughness,
            weight,
            reflectance: rho_s / weight,
        }
    });
    let scale = 1.0 / (1.0 - lobe.as_ref().map_or(0.0, |l| l.weight)).max(f64::MIN_POSITIVE);
    let diffuse = match albedo {
        Some(a) => {
            let rgb = Image {
                width: a.width,
                height: a.height,
                channels: 3,
                data: a
                    .data
                    .chunks_exact(a.channels)
                    .flat_map(|px| px[..3].iter().map(|v| (*v as f64 * scale) as f32))
                    .collect(),
            };
            let (at, file) = beside(path, "_albedo.exr");
            let bytes = encode_exr(&rgb).map_err(|e| NodeError::input("albedo", e))?;
            files.push(Artifact { path: at, bytes });
            Diffuse::Texture {
                file,
                tiling: r.tiling,
            }
        }
        None => Diffuse::Rgb(r.albedo.map(|v| v * scale)),
    };
    Ok(Look::Surface { diffuse, lobe })
}

/// The horizontal field of view, degrees, of a pinhole camera with vertical field `fov_y` on a
/// `width` × `height` image.
pub fn horizontal_fov(fov_y: f64, width: u32, height: u32) -> f64 {
    let half = (fov_y.to_radians() / 2.0).tan() * width as f64 / height as f64;
    2.0 * half.atan().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_sit_beside_the_scene_file() {
        assert_eq!(
            beside("mitsuba/scene.xml", ".ply"),
            ("mitsuba/scene.ply".to_string(), "scene.ply".to_string())
        );
        assert_eq!(
            beside("a.pbrt", "_albedo.exr"),
            ("a_albedo.exr".to_string(), "a_albedo.exr".to_string())
        );
    }

    #[test]
    fn a_square_image_has_the_same_field_both_ways() {
        assert!((horizontal_fov(40.0, 64, 64) - 40.0).abs() < 1e-12);
        // tan(h/2) = tan(20°)·4/3: 51.28°.
        let h = horizontal_fov(40.0, 400, 300);
        assert!(
            ((h / 2.0).to_radians().tan() - 20f64.to_radians().tan() * 4.0 / 3.0).abs() < 1e-12
        );
    }
}
