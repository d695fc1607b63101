//! `mesh.primitive`: a plane, sphere, cylinder or torus with texture coordinates, built as a
//! parametric grid (u around, v up) so every shape has a continuous UV map and tangent frames.
//! World space is y-up; the plane lies in z = 0 facing +z.

use crate::types::Mesh;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f32::consts::{PI, TAU};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// A `size`×`size` square in z = 0, normal +z, u along +x, v along +y.
    Plane,
    /// Radius `size`; u = longitude, v from the south pole (v = 0) to the north pole (v = 1).
    Sphere,
    /// Open tube along y, radius `size`, height `minor`; u around, v up.
    Cylinder,
    /// Ring around y with major radius `size` and tube radius `minor`; u around the ring, v
    /// around the tube.
    Torus,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// `plane`, `sphere`, `cylinder` or `torus`.
    pub shape: Shape,
    /// Plane side, or sphere/cylinder radius, or torus major radius (world units).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub size: f64,
    /// Torus tube radius or cylinder height (world units).
    #[schemars(range(min = 0.0))]
    pub minor: f64,
    /// Grid cells [along u, along v].
    pub segments: [u32; 2],
}

impl Default for Params {
    fn default() -> Self {
        Params {
            shape: Shape::Sphere,
            size: 1.0,
            minor: 0.4,
            segments: [64, 32],
        }
    }
}

pub struct Primitive;

impl Node for Primitive {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "mesh.primitive",
            // 2: no zero-area triangles at the sphere's poles.
            version: 2,
            doc: "Plane, sphere, cylinder or torus with texture coordinates and tangent frames.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("mesh", Mesh::TYPE, "the triangle mesh")],
            disk_cache: false,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        validate(p)
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("mesh", build(p)?))
    }
}

/// Position and outward normal at parameter (u, v) ∈ [0, 1]².
fn surface(p: &Params, u: f32, v: f32) -> ([f32; 3], [f32; 3]) {
    let (r, m) = (p.size as f32, p.minor as f32);
    match p.shape {
        Shape::Plane => ([(u - 0.5) * r, (v - 0.5) * r, 0.0], [0.0, 0.0, 1.0]),
        Shape::Sphere => {
            // Longitude grows counter-clockwise seen from +y, so the frame (u, v, n) is right-handed.
            let (phi, theta) = (-TAU * u, PI * (1.0 - v));
            let n = [
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ];
            ([r * n[0], r * n[1], r * n[2]], n)
        }
        Shape::Cylinder => {
            let phi = -TAU * u;
            let n = [phi.cos(), 0.0, phi.sin()];
            ([r * n[0], (v - 0.5) * m, r * n[2]], n)
        }
        Shape::Torus => {
            let (phi, psi) = (-TAU * u, PI - TAU * v);
            let ring = [phi.cos(), 0.0, phi.sin()];
            let n = [ring[0] * -psi.cos(), psi.sin(), ring[2] * -psi.cos()];
            let c = [ring[0] * r, 0.0, ring[2] * r];
            ([c[0] + m * n[0], c[1] + m * n[1], c[2] + m * n[2]], n)
        }
    }
}

/// The parameters' own rules (cells, radii).
fn validate(p: &Params) -> Result<(), NodeError> {
    let [su, sv] = p.segments;
    if su == 0 || sv == 0 || su as u64 * sv as u64 > 1 << 24 {
        return Err(NodeError::param(
            "segments",
            format!("{su}×{sv} cells: each must be at least 1, and 16M cells at most"),
        ));
    }
    if p.shape == Shape::Sphere && sv < 2 {
        return Err(NodeError::param(
            "segments",
            "a sphere needs at least 2 cells from pole to pole",
        ));
    }
    if !(p.size > 0.0 && p.size.is_finite()) {
        return Err(NodeError::param("size", "must be positive and finite"));
    }
    if matches!(p.shape, Shape::Torus | Shape::Cylinder) && !(p.minor > 0.0 && p.minor.is_finite())
    {
        return Err(NodeError::param("minor", "must be positive and finite"));
    }
    if p.shape == Shape::Torus && p.minor >= p.size {
        return Err(NodeError::param(
            "minor",
            format!(
                "a torus tube of radius {} does not fit its ring of radius {}",
                p.minor, p.size
            ),
        ));
    }
    Ok(())
}

pub fn build(p: &Params) -> Result<Mesh, NodeError> {
    validate(p)?;
    let [su, sv] = p.segments;
    let mut mesh = Mesh::default();
    for j in 0..=sv {
        for i in 0..=su {
            let (u, v) = (i as f32 / su as f32, j as f32 / sv as f32);
            let (pos, n) = surface(p, u, v);
            mesh.positions.push(pos);
            mesh.normals.push(n);
            mesh.uvs.push([u, v]);
        }
    }
    let at = |i: u32, j: u32| j * (su + 1) + i;
    for j in 0..sv {
        for i in 0..su {
            // (u, v, n) is right-handed on every shape, so this order is counter-clockwise seen
            // from outside.
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            // The sphere's first and last rows meet at a pole: one triangle of each cell there
            // has two corners on the pole, i.e. no area, and is left out.
            let pole_south = p.shape == Shape::Sphere && j == 0;
            let pole_north = p.shape == Shape::Sphere && j == sv - 1;
            if !pole_south {
                mesh.indices.extend_from_slice(&[a, b, c]);
            }
            if !pole_north {
                mesh.indices.extend_from_slice(&[a, c, d]);
            }
        }
    }
    mesh.compute_tangents();
    Ok(mesh)
}

/// A closed box [−h, h] per axis with outward winding: the tests' slab and cube.
#[cfg(test)]
pub(crate) fn closed_box(half: [f32; 3]) -> Mesh {
    let c = |i: usize| [0, 1, 2].map(|k| if i >> k & 1 == 0 { -half[k] } else { half[k] });
    let mut m = Mesh {
        positions: (0..8).map(c).collect(),
        uvs: vec![[0.0, 0.0]; 8],
        tangents: vec![[1.0, 0.0, 0.0, 1.0]; 8],
        // Faces −x, +x, −y, +y, −z, +z, each as two triangles wound outwards.
        indices: vec![
            0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5, 0, 1, 5, 0, 5, 4, 2, 6, 7, 2, 7, 3, 0, 2, 3, 0, 3,
            1, 4, 5, 7, 4, 7, 6,
        ],
        ..Default::default()
    };
    m.compute_normals();
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }

    #[test]
    fn every_shape_winds_counter_clockwise_seen_from_outside() {
        for shape in [Shape::Plane, Shape::Sphere, Shape::Cylinder, Shape::Torus] {
            let m = build(&Params {
                shape,
                segments: [12, 8],
                ..Default::default()
            })
            .unwrap();
            m.check().unwrap();
            let mut checked = 0;
            for t in 0..m.triangles() {
                let [a, b, c] = m.corners(t);
                let (p, q, r) = (m.positions[a], m.positions[b], m.positions[c]);
                let e1 = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
                let e2 = [r[0] - p[0], r[1] - p[1], r[2] - p[2]];
                let f = cross(e1, e2);
                let area = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
                assert!(area > 1e-6, "{shape:?} triangle {t} has no area");
                let n = m.normals[a];
                assert!(
                    f[0] * n[0] + f[1] * n[1] + f[2] * n[2] > 0.0,
                    "{shape:?} triangle {t}"
                );
                checked += 1;
            }
            assert!(checked > 0);
        }
    }

    #[test]
    fn sphere_vertices_lie_on_the_sphere_with_radial_normals() {
        let m = build(&Params {
            size: 2.0,
            ..Default::default()
        })
        .unwrap();
        for (p, n) in m.positions.iter().zip(&m.normals) {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - 2.0).abs() < 1e-5);
            for k in 0..3 {
                assert!((p[k] / 2.0 - n[k]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn bad_parameters_name_themselves() {
        let e = build(&Params {
            shape: Shape::Torus,
            size: 1.0,
            minor: 1.5,
            segments: [8, 8],
        })
        .unwrap_err();
        assert!(e.to_string().contains("minor"), "{e}");
        let e = build(&Params {
            segments: [0, 8],
            ..Default::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("segments"), "{e}");
    }
}
