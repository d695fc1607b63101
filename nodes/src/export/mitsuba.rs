//! `export.mitsuba`: the scene `render.reference` renders, as a Mitsuba 3 scene file (XML,
//! `mitsuba scene.xml` or `mi.load_file`) with its mesh (PLY) and albedo map (EXR) beside it.
//!
//! The mapping, each the closest Mitsuba 3 has to the reference:
//! - pinhole camera → `perspective` (vertical `fov`); orthographic → `orthographic` scaled to
//!   the view's half-height; a box pixel filter; `independent` samples, `$spp` and `$seed`
//!   defaults so `-Dspp=…` overrides them;
//! - the directional light → `directional` (its travel direction, the same irradiance); a point
//!   light → `point` (the same intensity and 1/r²); an environment → `envmap` of its lat-long
//!   image (EXR beside the scene, the intensity applied) turned onto mesoflow's convention
//!   (Mitsuba's envmap looks up along +y with u = atan2(x, −z)/2π; mesoflow's up is +z, u from
//!   +x towards +y) and by the light's rotation, hidden from the camera (`hide_emitters`) as
//!   the reference's background is not the environment;
//! - direct light only → `direct` (one emitter sample, no BSDF samples: the light is a delta, and
//!   an environment is sampled by its radiance as the reference does);
//!   with `bounces` N → `path` at `max_depth` N + 2 (Mitsuba counts the camera segment and the
//!   direct bounce), no Russian roulette;
//! - Lambert → `diffuse` (exact; a texture is a bilinear, repeating `bitmap` of linear values,
//!   its v turned over: Mitsuba's v = 0 is an image's top row, mesoflow's its bottom row);
//!   Ward → `blendbsdf` of `diffuse` and `roughconductor` (Beckmann α, Fresnel 1: Ward's lobe
//!   and Beckmann's agree at the peak and part at grazing angles); GGX → the same with a GGX
//!   `roughconductor` of η = 1.5, k = 0 (exact Fresnel for Schlick's, separable Smith masking
//!   for the height-correlated one). The differences are measured in `tests/export.rs`;
//! - a medium → the mesh as the boundary (`null` at η = 1, `roughdielectric` GGX on the
//!   triangles' own normals otherwise) of a `homogeneous` medium with a Henyey–Greenstein phase,
//!   rendered by `volpathmis` with no depth limit and no Russian roulette (it stops paths
//!   through dense media at random, as the reference does not).

use super::scene::{self, Diffuse, Look, Scene};
use crate::reflectance::models::Model;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs};
use std::fmt::Write as _;

pub struct ExportMitsuba;

impl Node for ExportMitsuba {
    type Params = scene::Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "export.mitsuba",
            version: 1,
            doc: "Writes the scene render.reference renders from the same parameters as a Mitsuba 3 scene (XML) with its mesh (PLY) and albedo map (EXR): camera, light, Lambert (exact), Ward or GGX (the closest Mitsuba BSDFs, a blend of diffuse and rough conductor), or a homogeneous medium inside an index-matched or rough dielectric boundary.",
            device: DevicePreference::Cpu,
            inputs: scene::inputs(),
            outputs: scene::outputs(),
            disk_cache: true,
        }
    }

    fn files(
        &self,
        p: &scene::Params,
        base: &std::path::Path,
    ) -> Result<Vec<std::path::PathBuf>, NodeError> {
        Ok(p.render.light.files(base))
    }

    fn check(&self, p: &scene::Params) -> Result<(), NodeError> {
        scene::check(&p.path, &p.render)
    }

    fn run(
        &self,
        ctx: &NodeContext,
        p: &scene::Params,
        inputs: &Inputs,
    ) -> Result<Outputs, NodeError> {
        let mut s = scene::build(ctx, &p.path, &p.render, inputs)?;
        let env_file = match s.environment.clone() {
            Some(env) => {
                let texels = env.radiance.iter().flatten().copied().collect();
                Some(scene::environment_file(
                    &mut s, &p.path, env.width, env.height, texels,
                )?)
            }
            None => None,
        };
        let xml = write(&s, env_file.as_deref());
        Ok(scene::outputs_with(s, &p.path, xml))
    }
}

fn v3(v: [f64; 3]) -> String {
    format!("{}, {}, {}", v[0], v[1], v[2])
}

fn rgb(name: &str, v: [f64; 3]) -> String {
    format!(r#"<rgb name="{name}" value="{}"/>"#, v3(v))
}

/// An attribute value with XML's five special characters escaped.
fn attr(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

/// The scene file's text.
/// `env_file`: the environment's image, relative to the scene file, where the light is one.
pub fn write(s: &Scene, env_file: Option<&str>) -> String {
    let mut x = String::new();
    let c = &s.camera;
    let [w, h] = c.resolution;
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="utf-8"?>"#);
    let _ = writeln!(
        x,
        "<!-- Written by mesoflow's export.mitsuba: the scene render.reference renders from the same parameters. mitsuba -Dspp=256 this.xml -->"
    );
    let _ = writeln!(x, r#"<scene version="3.0.0">"#);
    let _ = writeln!(x, r#"    <default name="spp" value="{}"/>"#, s.samples);
    let _ = writeln!(x, r#"    <default name="seed" value="{}"/>"#, s.seed);
    match &s.look {
        Look::Surface { .. } if s.bounces > 0 => {
            // Mitsuba counts the camera segment and the direct bounce; no Russian roulette,
            // so every path runs to its depth as the reference's do.
            let _ = writeln!(x, r#"    <integrator type="path">"#);
            let _ = writeln!(
                x,
                r#"        <integer name="max_depth" value="{}"/>"#,
                s.bounces + 2
            );
            let _ = writeln!(
                x,
                r#"        <integer name="rr_depth" value="1073741824"/>"#
            );
            if env_file.is_some() {
                let _ = writeln!(x, r#"        <boolean name="hide_emitters" value="true"/>"#);
            }
        }
        Look::Surface { .. } => {
            let _ = writeln!(x, r#"    <integrator type="direct">"#);
            let _ = writeln!(x, r#"        <integer name="emitter_samples" value="1"/>"#);
            let _ = writeln!(x, r#"        <integer name="bsdf_samples" value="0"/>"#);
            if env_file.is_some() {
                let _ = writeln!(x, r#"        <boolean name="hide_emitters" value="true"/>"#);
            }
        }
        Look::Medium(_) => {
            let _ = writeln!(x, r#"    <integrator type="volpathmis">"#);
            let _ = writeln!(x, r#"        <integer name="max_depth" value="-1"/>"#);
            let _ = writeln!(
                x,
                r#"        <integer name="rr_depth" value="1073741824"/>"#
            );
            if env_file.is_some() {
                let _ = writeln!(x, r#"        <boolean name="hide_emitters" value="true"/>"#);
            }
        }
    }
    let _ = writeln!(x, "    </integrator>");
    match c.orthographic {
        None => {
            let _ = writeln!(x, r#"    <sensor type="perspective">"#);
            let _ = writeln!(x, r#"        <float name="fov" value="{}"/>"#, c.fov);
            let _ = writeln!(x, r#"        <string name="fov_axis" value="y"/>"#);
            let _ = writeln!(x, r#"        <transform name="to_world">"#);
        }
        Some(half) => {
            // Mitsuba's orthographic view spans x in [−1, 1] and y in [−1/a, 1/a] before its
            // transform, a = width / height: a uniform scale of half × a gives half-height half.
            let k = half * w as f64 / h as f64;
            let _ = writeln!(x, r#"    <sensor type="orthographic">"#);
            let _ = writeln!(x, r#"        <transform name="to_world">"#);
            let _ = writeln!(x, r#"            <scale x="{k}" y="{k}" z="1"/>"#);
        }
    }
    let _ = writeln!(
        x,
        r#"            <lookat origin="{}" target="{}" up="{}"/>"#,
        v3(c.eye),
        v3(c.target),
        v3(c.up)
    );
    let _ = writeln!(x, "        </transform>");
    let _ = writeln!(x, r#"        <sampler type="independent">"#);
    let _ = writeln!(
        x,
        r#"            <integer name="sample_count" value="$spp"/>"#
    );
    let _ = writeln!(x, r#"            <integer name="seed" value="$seed"/>"#);
    let _ = writeln!(x, "        </sampler>");
    let _ = writeln!(x, r#"        <film type="hdrfilm">"#);
    let _ = writeln!(x, r#"            <integer name="width" value="{w}"/>"#);
    let _ = writeln!(x, r#"            <integer name="height" value="{h}"/>"#);
    let _ = writeln!(
        x,
        r#"            <string name="pixel_format" value="rgba"/>"#
    );
    let _ = writeln!(x, r#"            <rfilter type="box"/>"#);
    let _ = writeln!(x, "        </film>");
    let _ = writeln!(x, "    </sensor>");
    let i = s.light.intensity;
    match (s.light.position, env_file, &s.environment) {
        (_, Some(file), Some(env)) => {
            // Mitsuba's local direction (x, y, z) is mesoflow's (−z, x, y) before the rotation
            // about +z: its up +y is mesoflow's +z, its u = 0 (−z) is mesoflow's +x.
            let (c, sn) = (env.rotation.cos(), env.rotation.sin());
            let m = [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
            let r = [[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]];
            let mut t = [[0.0; 3]; 3];
            for a in 0..3 {
                for b in 0..3 {
                    t[a][b] = (0..3).map(|k| r[a][k] * m[k][b]).sum::<f64>();
                }
            }
            let _ = writeln!(x, r#"    <emitter type="envmap">"#);
            let _ = writeln!(
                x,
                r#"        <string name="filename" value="{}"/>"#,
                attr(file)
            );
            let _ = writeln!(x, r#"        <transform name="to_world">"#);
            let _ = writeln!(
                x,
                r#"            <matrix value="{} {} {} 0 {} {} {} 0 {} {} {} 0 0 0 0 1"/>"#,
                t[0][0], t[0][1], t[0][2], t[1][0], t[1][1], t[1][2], t[2][0], t[2][1], t[2][2]
            );
            let _ = writeln!(x, "        </transform>");
        }
        (None, ..) => {
            let _ = writeln!(x, r#"    <emitter type="directional">"#);
            // Mitsuba's direction is the one the light travels in.
            let _ = writeln!(
                x,
                r#"        <vector name="direction" value="{}"/>"#,
                v3(s.direction.map(|d| -d))
            );
            let _ = writeln!(x, "        {}", rgb("irradiance", [i; 3]));
        }
        (Some(at), ..) => {
            let _ = writeln!(x, r#"    <emitter type="point">"#);
            let _ = writeln!(x, r#"        <point name="position" value="{}"/>"#, v3(at));
            let _ = writeln!(x, "        {}", rgb("intensity", [i; 3]));
        }
    }
    let _ = writeln!(x, "    </emitter>");
    let _ = writeln!(x, r#"    <shape type="ply">"#);
    let _ = writeln!(
        x,
        r#"        <string name="filename" value="{}"/>"#,
        attr(&s.mesh_file)
    );
    match &s.look {
        Look::Surface { diffuse, lobe } => {
            let diffuse_bsdf = |indent: &str| -> String {
                let mut d = format!("{indent}<bsdf type=\"diffuse\">\n");
                match diffuse {
                    Diffuse::Rgb(v) => {
                        let _ = writeln!(d, "{indent}    {}", rgb("reflectance", *v));
                    }
                    Diffuse::Texture { file, tiling } => {
                        let _ = writeln!(
                            d,
                            r#"{indent}    <texture type="bitmap" name="reflectance">"#
                        );
                        let _ = writeln!(
                            d,
                            r#"{indent}        <string name="filename" value="{}"/>"#,
                            attr(file)
                        );
                        let _ =
                            writeln!(d, r#"{indent}        <boolean name="raw" value="true"/>"#);
                        let _ = writeln!(
                            d,
                            r#"{indent}        <string name="filter_type" value="bilinear"/>"#
                        );
                        let _ = writeln!(
                            d,
                            r#"{indent}        <string name="wrap_mode" value="repeat"/>"#
                        );
                        // Mitsuba reads a texture's rows from v = 0 at the image's top;
                        // mesoflow (as OpenGL and pbrt) from v = 0 at its bottom.
                        let _ = writeln!(d, r#"{indent}        <transform name="to_uv">"#);
                        let _ = writeln!(
                            d,
                            r#"{indent}            <scale x="{}" y="{}"/>"#,
                            tiling[0], -tiling[1]
                        );
                        let _ = writeln!(d, r#"{indent}            <translate x="0" y="1"/>"#);
                        let _ = writeln!(d, "{indent}        </transform>");
                        let _ = writeln!(d, "{indent}    </texture>");
                    }
                }
                let _ = writeln!(d, "{indent}</bsdf>");
                d
            };
            match lobe {
                None => x.push_str(&diffuse_bsdf("        ")),
                Some(l) => {
                    let _ = writeln!(x, r#"        <bsdf type="blendbsdf">"#);
                    let _ = writeln!(
                        x,
                        r#"            <float name="weight" value="{}"/>"#,
                        l.weight
                    );
                    x.push_str(&diffuse_bsdf("            "));
                    let _ = writeln!(x, r#"            <bsdf type="roughconductor">"#);
                    let (distribution, fresnel) = match l.model {
                        Model::Ggx => (
                            "ggx",
                            r#"<float name="eta" value="1.5"/><float name="k" value="0"/>"#,
                        ),
                        _ => ("beckmann", r#"<string name="material" value="none"/>"#),
                    };
                    let _ = writeln!(
                        x,
                        r#"                <string name="distribution" value="{distribution}"/>"#
                    );
                    let _ = writeln!(
                        x,
                        r#"                <float name="alpha" value="{}"/>"#,
                        l.alpha
                    );
                    let _ = writeln!(x, "                {fresnel}");
                    let _ = writeln!(
                        x,
                        "                {}",
                        rgb("specular_reflectance", [l.reflectance; 3])
                    );
                    let _ = writeln!(x, "            </bsdf>");
                    let _ = writeln!(x, "        </bsdf>");
                }
            }
        }
        Look::Medium(m) => {
            match m.roughness {
                None => {
                    let _ = writeln!(x, r#"        <bsdf type="null"/>"#);
                }
                Some(alpha) => {
                    let _ = writeln!(x, r#"        <boolean name="face_normals" value="true"/>"#);
                    let _ = writeln!(x, r#"        <bsdf type="roughdielectric">"#);
                    let _ = writeln!(
                        x,
                        r#"            <string name="distribution" value="ggx"/>"#
                    );
                    let _ = writeln!(x, r#"            <float name="alpha" value="{alpha}"/>"#);
                    let _ = writeln!(
                        x,
                        r#"            <float name="int_ior" value="{}"/>"#,
                        m.eta
                    );
                    let _ = writeln!(x, r#"            <float name="ext_ior" value="1"/>"#);
                    let _ = writeln!(x, "        </bsdf>");
                }
            }
            // An RGB value must lie in [0, 1]: the extinction is a colour times a scale.
            let sigma_t = [0, 1, 2].map(|c| m.sigma_s[c] + m.sigma_a[c]);
            let scale = sigma_t.iter().fold(0.0f64, |a, b| a.max(*b));
            let _ = writeln!(x, r#"        <medium type="homogeneous" name="interior">"#);
            let _ = writeln!(x, r#"            <float name="scale" value="{scale}"/>"#);
            let _ = writeln!(
                x,
                "            {}",
                rgb("sigma_t", sigma_t.map(|t| t / scale))
            );
            let _ = writeln!(
                x,
                "            {}",
                rgb("albedo", [0, 1, 2].map(|c| m.sigma_s[c] / sigma_t[c]))
            );
            let _ = writeln!(x, r#"            <phase type="hg">"#);
            let _ = writeln!(x, r#"                <float name="g" value="{}"/>"#, m.g);
            let _ = writeln!(x, "            </phase>");
            let _ = writeln!(x, "        </medium>");
        }
    }
    let _ = writeln!(x, "    </shape>");
    let _ = writeln!(x, "</scene>");
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attribute_values_are_escaped() {
        assert_eq!(attr(r#"a&b"<'>.ply"#), "a&amp;b&quot;&lt;&apos;&gt;.ply");
    }

    /// A sky becomes an `envmap` of the EXR written beside the scene, hidden from the camera;
    /// pbrt's an `infinite` light of its equal-area image. The EXR reads back as the sky's
    /// texels (the light's intensity applied), and the transform takes Mitsuba's up (+y) to
    /// mesoflow's (+z).
    #[test]
    fn an_environment_is_written_beside_the_scene() {
        use mesoflow_testkit::node::{run, OutputsExt};
        let mesh = crate::mesh::primitive::build(
            &serde_json::from_value(serde_json::json!({"shape": "plane"})).unwrap(),
        )
        .unwrap();
        let inputs = Inputs::new().with("mesh", std::sync::Arc::new(mesh));
        let p: scene::Params = serde_json::from_value(serde_json::json!({
            "path": "m/scene.xml", "light": {"sky": {}, "intensity": 2.0}, "bounces": 2
        }))
        .unwrap();
        let out = run(&ExportMitsuba, &p, &inputs).unwrap();
        let files = out.value::<mesoflow_runtime::Artifacts>("files");
        let names: Vec<&str> = files.files.iter().map(|f| f.path.as_str()).collect();
        assert!(names.contains(&"m/scene_environment.exr"), "{names:?}");
        let xml = String::from_utf8(files.files.last().unwrap().bytes.clone()).unwrap();
        assert!(xml.contains(r#"<emitter type="envmap">"#), "{xml}");
        assert!(xml.contains(r#"value="scene_environment.exr""#));
        assert!(xml.contains(r#"<boolean name="hide_emitters" value="true"/>"#));
        // Columns of the to_world matrix: local +y (Mitsuba's up) → world +z.
        assert!(
            xml.contains(r#"<matrix value="0 0 -1 0 1 0 0 0 0 1 0 0 0 0 0 1"/>"#),
            "{xml}"
        );
        let exr = files
            .files
            .iter()
            .find(|f| f.path.ends_with(".exr"))
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("e.exr");
        std::fs::write(&path, &exr.bytes).unwrap();
        let img = crate::support::formats::read_image(&path).unwrap();
        let sky = crate::support::raytrace::environment::SkyParams::default()
            .texels()
            .unwrap();
        assert_eq!((img.width, img.height), (256, 128));
        assert_eq!(img.data[3 * 1000 + 1], 2.0 * sky[1000][1]);
        let pbrt: crate::export::pbrt::Params = serde_json::from_value(serde_json::json!({
            "path": "p/scene.pbrt", "light": {"sky": {}}
        }))
        .unwrap();
        let out = run(&crate::export::pbrt::ExportPbrt, &pbrt, &inputs).unwrap();
        let files = out.value::<mesoflow_runtime::Artifacts>("files");
        let text = String::from_utf8(files.files.last().unwrap().bytes.clone()).unwrap();
        assert!(
            text.contains(
                r#"LightSource "infinite" "string filename" [ "scene_environment.exr" ]"#
            ),
            "{text}"
        );
    }
}
