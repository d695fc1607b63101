//! `mesh.write`: a mesh as Wavefront OBJ (text) or PLY (binary little-endian), with positions,
//! normals and texture coordinates, so the true mesostructure from `mesh.displace` can be taken
//! to any renderer. The node returns the file's bytes; the runtime writes them under the output
//! folder.

use crate::types::Mesh;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Artifact, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// From the path's extension (.obj or .ply).
    Auto,
    Obj,
    Ply,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Output file, relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
    /// File format.
    #[serde(default = "auto")]
    pub format: Format,
}

fn auto() -> Format {
    Format::Auto
}

pub struct MeshWrite;

impl Node for MeshWrite {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "mesh.write",
            version: 1,
            doc: "Writes a mesh as OBJ (text) or PLY (binary little-endian): positions, normals, texture coordinates, triangles.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("mesh", Mesh::TYPE, "the mesh")],
            outputs: vec![Port::output(
                "file",
                "File",
                "the encoded file, written under the output folder",
            )],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        format_of(p).map(drop)
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let bytes = match format_of(p)? {
            Format::Ply => ply(mesh),
            _ => obj(mesh).into_bytes(),
        };
        Ok(Outputs::new().with(
            "file",
            Artifact {
                path: p.path.clone(),
                bytes,
            },
        ))
    }
}

fn format_of(p: &Params) -> Result<Format, NodeError> {
    let extension = std::path::Path::new(&p.path)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match (p.format, extension.as_deref()) {
        (Format::Auto, Some("obj")) => Ok(Format::Obj),
        (Format::Auto, Some("ply")) => Ok(Format::Ply),
        (Format::Auto, other) => Err(NodeError::param(
            "path",
            format!("cannot tell the format from extension {other:?}; use .obj or .ply, or set `format`"),
        )),
        (f, _) => Ok(f),
    }
}

/// OBJ with one index per vertex for position, texture coordinate and normal (they are
/// per-vertex here), 1-based.
pub fn obj(mesh: &Mesh) -> String {
    let mut s = String::with_capacity(mesh.positions.len() * 80 + mesh.indices.len() * 12);
    let _ = writeln!(s, "# mesoflow mesh.write");
    for q in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", q[0], q[1], q[2]);
    }
    for t in &mesh.uvs {
        let _ = writeln!(s, "vt {} {}", t[0], t[1]);
    }
    for n in &mesh.normals {
        let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
    }
    for f in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [f[0] + 1, f[1] + 1, f[2] + 1];
        let _ = writeln!(s, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}");
    }
    s
}

/// Binary little-endian PLY: per vertex x y z nx ny nz u v (float), per face a uchar count and
/// three int indices.
pub fn ply(mesh: &Mesh) -> Vec<u8> {
    ply_with(mesh, true)
}

/// PLY as [`ply`], with the vertex normals or without them (a renderer then shades with the
/// triangles' own normals).
pub fn ply_with(mesh: &Mesh, normals: bool) -> Vec<u8> {
    let normal_props = if normals {
        "property float nx\nproperty float ny\nproperty float nz\n"
    } else {
        ""
    };
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment mesoflow mesh.write\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n{normal_props}property float u\nproperty float v\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles()
    );
    let mut out = header.into_bytes();
    out.reserve(mesh.positions.len() * 32 + mesh.triangles() * 13);
    for i in 0..mesh.positions.len() {
        let n: &[f32] = if normals { &mesh.normals[i] } else { &[] };
        let values = mesh.positions[i].iter().chain(n).chain(&mesh.uvs[i]);
        for v in values {
            out.extend(v.to_le_bytes());
        }
    }
    for f in mesh.indices.chunks_exact(3) {
        out.push(3);
        for &i in f {
            out.extend((i as i32).to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{self, Shape};

    fn torus() -> Mesh {
        primitive::build(&primitive::Params {
            shape: Shape::Torus,
            size: 1.0,
            minor: 0.3,
            segments: [8, 6],
        })
        .unwrap()
    }

    #[test]
    fn obj_reads_back_through_tobj() {
        // tobj (mesh.read's parser) is the independent reader.
        let m = torus();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.obj");
        std::fs::write(&path, obj(&m)).unwrap();
        let (models, _) = tobj::load_obj(
            &path,
            &tobj::LoadOptions {
                single_index: true,
                triangulate: true,
                ..Default::default()
            },
        )
        .unwrap();
        let back = &models[0].mesh;
        // tobj numbers vertices in the order the faces first use them: compare corner by corner.
        assert_eq!(back.indices.len(), m.indices.len());
        for (k, &i) in m.indices.iter().enumerate() {
            let j = back.indices[k] as usize;
            assert_eq!(back.positions[3 * j..3 * j + 3], m.positions[i as usize]);
            assert_eq!(back.texcoords[2 * j..2 * j + 2], m.uvs[i as usize]);
            assert_eq!(back.normals[3 * j..3 * j + 3], m.normals[i as usize]);
        }
    }

    #[test]
    fn ply_without_normals_leaves_them_out_of_header_and_body() {
        let m = torus();
        let bytes = ply_with(&m, false);
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..at]).unwrap();
        assert!(!header.contains("nx") && header.contains("property float u"));
        assert_eq!(
            bytes.len() - at,
            m.positions.len() * 5 * 4 + m.triangles() * 13
        );
    }

    #[test]
    fn ply_has_its_header_and_the_exact_values() {
        let m = torus();
        let bytes = ply(&m);
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..at]).unwrap();
        assert!(header.contains(&format!("element vertex {}", m.positions.len())));
        assert!(header.contains(&format!("element face {}", m.triangles())));
        assert_eq!(
            bytes.len() - at,
            m.positions.len() * 8 * 4 + m.triangles() * (1 + 3 * 4)
        );
        let f = |o: usize| f32::from_le_bytes(bytes[at + o..at + o + 4].try_into().unwrap());
        // Vertex 1: x y z nx ny nz u v.
        assert_eq!(f(32), m.positions[1][0]);
        assert_eq!(f(32 + 28), m.uvs[1][1]);
        let faces = at + m.positions.len() * 32;
        assert_eq!(bytes[faces], 3);
        let i = |o: usize| i32::from_le_bytes(bytes[faces + o..faces + o + 4].try_into().unwrap());
        assert_eq!([i(1), i(5), i(9)], [0, 1, 2].map(|k| m.indices[k] as i32));
    }

    #[test]
    fn the_format_comes_from_the_extension_or_is_asked_for() {
        let p = |path: &str, format| Params {
            path: path.into(),
            format,
        };
        assert_eq!(format_of(&p("a.PLY", Format::Auto)).unwrap(), Format::Ply);
        assert_eq!(format_of(&p("a.obj", Format::Auto)).unwrap(), Format::Obj);
        assert!(format_of(&p("a.stl", Format::Auto)).is_err());
        assert_eq!(format_of(&p("a.mesh", Format::Ply)).unwrap(), Format::Ply);
    }
}
