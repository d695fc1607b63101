//! `mesh.read`: a Wavefront OBJ file (via tobj), all objects merged, polygons triangulated,
//! one index per vertex. Normals are computed where the file has none, tangents always. A file
//! without texture coordinates is an error unless `generate_uvs` names a projection.

use crate::types::Mesh;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f32::consts::{PI, TAU};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum UvProjection {
    /// Use the file's texture coordinates; a file without them is an error.
    None,
    /// Longitude/latitude around the bounding-box centre, y up (u = 0.5 + atan2(z, x)/2π...).
    Spherical,
    /// x and y over the bounding box, mapped to [0, 1].
    Planar,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// OBJ file, relative to the graph file.
    pub path: String,
    /// Texture coordinates for files without them.
    #[serde(default = "no_projection")]
    pub generate_uvs: UvProjection,
}

fn no_projection() -> UvProjection {
    UvProjection::None
}

pub struct Read;

impl Node for Read {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "mesh.read",
            version: 1,
            doc: "Wavefront OBJ (tobj): merged, triangulated; normals computed if absent, tangents always.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("mesh", Mesh::TYPE, "the triangle mesh")],
            disk_cache: true,
        }
    }

    fn files(&self, p: &Params, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.path)])
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let path = ctx.input_path("path", &p.path)?;
        let mesh = load(&path, p.generate_uvs)?;
        let degenerate = mesh.degenerate_triangles();
        if degenerate > 0 {
            ctx.warn(format!(
                "{degenerate} of {} triangles have zero area; renderers skip them",
                mesh.triangles()
            ));
        }
        Ok(Outputs::new().with("mesh", mesh))
    }
}

pub fn load(path: &Path, generate: UvProjection) -> Result<Mesh, NodeError> {
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let file = std::fs::File::open(path).map_err(|e| NodeError::file(path, e))?;
    if !file.metadata().is_ok_and(|m| m.is_file()) {
        return Err(NodeError::file(path, "not a regular file"));
    }
    // Materials are never read: mesoflow takes the geometry alone, and an `mtllib` line may name
    // any file, `/dev/zero` or a FIFO among them (issue 43).
    let (models, _materials) =
        tobj::load_obj_buf(&mut std::io::BufReader::new(file), &options, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
        .map_err(|e| NodeError::file(path, format!("not a readable OBJ file: {e}")))?;
    let mut mesh = Mesh::default();
    let (mut with_normals, mut with_uvs) = (true, true);
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        let n = m.positions.len() / 3;
        mesh.positions
            .extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        with_normals &= m.normals.len() == 3 * n;
        with_uvs &= m.texcoords.len() == 2 * n;
        if with_normals {
            mesh.normals
                .extend(m.normals.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        }
        if with_uvs {
            mesh.uvs
                .extend(m.texcoords.chunks_exact(2).map(|c| [c[0], c[1]]));
        }
        mesh.indices.extend(m.indices.iter().map(|i| base + i));
    }
    if mesh.indices.is_empty() {
        return Err(NodeError::file(path, "the file has no faces"));
    }
    let values = [("position", &mesh.positions), ("normal", &mesh.normals)];
    for (what, list) in values {
        if let Some(i) = list.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
            return Err(NodeError::file(
                path,
                format!("{what} {i} is {:?}: not finite", list[i]),
            ));
        }
    }
    if !with_normals {
        mesh.compute_normals();
    }
    if !with_uvs {
        mesh.uvs = match generate {
            UvProjection::None => {
                return Err(NodeError::param(
                    "path",
                    format!(
                        "{} has no texture coordinates (vt) on every face; set generate_uvs to \"spherical\" or \"planar\"",
                        path.display()
                    ),
                ))
            }
            projection => project_uvs(&mesh, projection),
        };
    }
    if let Some(i) = mesh
        .indices
        .iter()
        .find(|&&i| i as usize >= mesh.positions.len())
    {
        return Err(NodeError::file(
            path,
            format!("vertex index {i} is out of range"),
        ));
    }
    mesh.compute_tangents();
    mesh.check().map_err(|e| NodeError::file(path, e))?;
    Ok(mesh)
}

fn project_uvs(mesh: &Mesh, projection: UvProjection) -> Vec<[f32; 2]> {
    let (lo, hi) = mesh.bounds();
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    mesh.positions
        .iter()
        .map(|p| match projection {
            UvProjection::Planar => [
                (p[0] - lo[0]) / (hi[0] - lo[0]).max(1e-20),
                (p[1] - lo[1]) / (hi[1] - lo[1]).max(1e-20),
            ],
            _ => {
                let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-20);
                let u = 0.5 - d[2].atan2(d[0]) / TAU;
                let v = 1.0 - (d[1] / r).clamp(-1.0, 1.0).acos() / PI;
                [u, v]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUAD: &str =
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";

    fn write(text: &str) -> tempfile::NamedTempFile {
        let f = tempfile::Builder::new().suffix(".obj").tempfile().unwrap();
        std::fs::write(f.path(), text).unwrap();
        f
    }

    #[test]
    fn a_textured_quad_is_triangulated_with_its_frame() {
        let f = write(QUAD);
        let m = load(f.path(), UvProjection::None).unwrap();
        assert_eq!(m.triangles(), 2);
        assert_eq!(m.normals[0], [0.0, 0.0, 1.0]);
        assert_eq!(m.tangents[2], [1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn missing_uvs_are_an_error_unless_a_projection_is_asked_for() {
        let f = write("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n");
        let e = load(f.path(), UvProjection::None).unwrap_err().to_string();
        assert!(e.contains("generate_uvs") && e.contains("path"), "{e}");
        let m = load(f.path(), UvProjection::Planar).unwrap();
        assert_eq!(m.uvs[1], [1.0, 0.0]);
    }

    #[test]
    fn garbage_and_empty_files_are_errors_naming_the_file() {
        let f = write("this is not an obj\n");
        let e = load(f.path(), UvProjection::None).unwrap_err().to_string();
        assert!(e.contains(".obj"), "{e}");
    }
}
