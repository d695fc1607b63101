//! `Mesh`: an indexed triangle mesh with per-vertex normals, texture coordinates and tangent
//! frames, the geometry `render.mesh` maps a BTF onto.
//!
//! Conventions: counter-clockwise triangles seen from outside are front faces; `uv` has v up (OBJ),
//! so texel row 0 (top of a tile) is at v = 1; `tangent` is the unit direction of increasing u
//! projected perpendicular to the normal, and its `w` is the handedness sign, the bitangent being
//! `w · (n × t)` (the direction of increasing v).

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq, Default)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub uvs: Vec<[f32; 2]>,
    pub tangents: Vec<[f32; 4]>,
    pub indices: Vec<u32>,
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn normalize(a: [f32; 3]) -> Option<[f32; 3]> {
    let l = dot(a, a).sqrt();
    (l > 1e-20 && l.is_finite()).then(|| [a[0] / l, a[1] / l, a[2] / l])
}

impl Mesh {
    pub const TYPE: &'static str = "Mesh";

    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }

    /// The corners of triangle `t`.
    pub fn corners(&self, t: usize) -> [usize; 3] {
        [
            self.indices[3 * t] as usize,
            self.indices[3 * t + 1] as usize,
            self.indices[3 * t + 2] as usize,
        ]
    }

    /// Position and vertex normal (interpolated, not normalised) at barycentric weights b1, b2
    /// of corners 1 and 2 of triangle `t`, in f64.
    pub fn interpolate(&self, t: usize, b1: f64, b2: f64) -> ([f64; 3], [f64; 3]) {
        let w = [1.0 - b1 - b2, b1, b2];
        let mut p = [0.0; 3];
        let mut n = [0.0; 3];
        for (j, i) in self.corners(t).into_iter().enumerate() {
            for k in 0..3 {
                p[k] += w[j] * self.positions[i][k] as f64;
                n[k] += w[j] * self.normals[i][k] as f64;
            }
        }
        (p, n)
    }

    /// Triangles whose area is zero (repeated or collinear corners); renderers skip them.
    pub fn degenerate_triangles(&self) -> usize {
        (0..self.triangles())
            .filter(|&t| {
                let [a, b, c] = self.corners(t);
                let (p, q, r) = (self.positions[a], self.positions[b], self.positions[c]);
                normalize(cross(sub(q, p), sub(r, p))).is_none()
            })
            .count()
    }

    /// Axis-aligned bounds (min, max).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Fills `normals` with area-weighted face normals where they are missing.
    pub fn compute_normals(&mut self) {
        let mut acc = vec![[0f32; 3]; self.positions.len()];
        for t in 0..self.triangles() {
            let [a, b, c] = self.corners(t);
            let n = cross(
                sub(self.positions[b], self.positions[a]),
                sub(self.positions[c], self.positions[a]),
            );
            for v in [a, b, c] {
                for k in 0..3 {
                    acc[v][k] += n[k];
                }
            }
        }
        self.normals = acc
            .into_iter()
            .map(|n| normalize(n).unwrap_or([0.0, 0.0, 1.0]))
            .collect();
    }

    /// Triangle `t`'s ∂P/∂u and ∂P/∂v; `None` where its UVs are degenerate.
    pub fn uv_derivatives(&self, t: usize) -> Option<([f32; 3], [f32; 3])> {
        let [a, b, c] = self.corners(t);
        let (e1, e2) = (
            sub(self.positions[b], self.positions[a]),
            sub(self.positions[c], self.positions[a]),
        );
        let (du1, dv1) = (
            self.uvs[b][0] - self.uvs[a][0],
            self.uvs[b][1] - self.uvs[a][1],
        );
        let (du2, dv2) = (
            self.uvs[c][0] - self.uvs[a][0],
            self.uvs[c][1] - self.uvs[a][1],
        );
        let det = du1 * dv2 - du2 * dv1;
        if det.abs() < 1e-20 || !det.is_finite() {
            return None;
        }
        let r = 1.0 / det;
        Some((
            [0, 1, 2].map(|k| (e1[k] * dv2 - e2[k] * dv1) * r),
            [0, 1, 2].map(|k| (e2[k] * du1 - e1[k] * du2) * r),
        ))
    }

    /// Per-vertex tangent frames from the UV parametrisation (Lengyel's method: accumulate each
    /// triangle's ∂P/∂u and ∂P/∂v, orthogonalise against the normal). A vertex whose triangles
    /// all have degenerate UVs gets an arbitrary tangent perpendicular to its normal, so the frame
    /// is always defined.
    pub fn compute_tangents(&mut self) {
        let n = self.positions.len();
        let (mut su, mut sv) = (vec![[0f32; 3]; n], vec![[0f32; 3]; n]);
        for t in 0..self.triangles() {
            let Some((dpdu, dpdv)) = self.uv_derivatives(t) else {
                continue;
            };
            for v in self.corners(t) {
                for k in 0..3 {
                    su[v][k] += dpdu[k];
                    sv[v][k] += dpdv[k];
                }
            }
        }
        self.tangents = (0..n)
            .map(|v| {
                let nrm = self.normals[v];
                let t = sub(su[v], scale(nrm, dot(nrm, su[v])));
                let t = normalize(t).unwrap_or_else(|| any_perpendicular(nrm));
                let w = if dot(cross(nrm, t), sv[v]) < 0.0 {
                    -1.0
                } else {
                    1.0
                };
                [t[0], t[1], t[2], w]
            })
            .collect();
    }

    /// Each vertex's twin: the first vertex within a millionth of the mesh's size of it (itself
    /// where there is none), so copies of a position split at a UV seam count as one. Cells of
    /// that size are searched with their neighbours, so two copies straddling a cell boundary
    /// are still found.
    pub fn position_twins(&self) -> Vec<usize> {
        let (lo, hi) = self.bounds();
        let size = (0..3).map(|k| (hi[k] - lo[k]) as f64).fold(0.0, f64::max);
        let tol = (1e-6 * size).max(f64::MIN_POSITIVE);
        let cell = |q: [f32; 3]| q.map(|x| (x as f64 / tol).floor() as i64);
        let mut first: std::collections::HashMap<[i64; 3], Vec<usize>> =
            std::collections::HashMap::new();
        let mut twin = Vec::with_capacity(self.positions.len());
        for (i, &q) in self.positions.iter().enumerate() {
            let c = cell(q);
            let near = |j: usize| {
                let r = self.positions[j];
                (0..3).all(|k| ((r[k] - q[k]) as f64).abs() <= tol)
            };
            let mut found = None;
            'search: for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let key = [c[0] + dx, c[1] + dy, c[2] + dz];
                        if let Some(j) = first
                            .get(&key)
                            .and_then(|l| l.iter().copied().find(|&j| near(j)))
                        {
                            found = Some(j);
                            break 'search;
                        }
                    }
                }
            }
            match found {
                Some(j) => twin.push(j),
                None => {
                    first.entry(c).or_default().push(i);
                    twin.push(i);
                }
            }
        }
        twin
    }

    /// World length of one unit of texture coordinate along u and along v at each vertex: the
    /// lengths of the triangles' ∂P/∂u and ∂P/∂v, averaged over the vertex's triangles by their
    /// area. [0, 0] at a vertex whose triangles all have degenerate UVs (unknown).
    pub fn uv_scale(&self) -> Vec<[f32; 2]> {
        let n = self.positions.len();
        let mut acc = vec![[0f64; 3]; n];
        for t in 0..self.triangles() {
            let [a, b, c] = self.corners(t);
            let (e1, e2) = (
                sub(self.positions[b], self.positions[a]),
                sub(self.positions[c], self.positions[a]),
            );
            let area = dot(cross(e1, e2), cross(e1, e2)).sqrt();
            let Some((du, dv)) = self.uv_derivatives(t) else {
                continue;
            };
            let len = |v: [f32; 3]| dot(v, v).sqrt() as f64;
            let (dpdu, dpdv) = (len(du), len(dv));
            if area.is_nan() || area <= 0.0 || !(dpdu.is_finite() && dpdv.is_finite()) {
                continue;
            }
            for v in [a, b, c] {
                acc[v][0] += area as f64 * dpdu;
                acc[v][1] += area as f64 * dpdv;
                acc[v][2] += area as f64;
            }
        }
        acc.into_iter()
            .map(|[u, v, w]| {
                if w > 0.0 {
                    [(u / w) as f32, (v / w) as f32]
                } else {
                    [0.0, 0.0]
                }
            })
            .collect()
    }

    /// Structural checks: index range, attribute counts, finite values.
    pub fn check(&self) -> Result<(), String> {
        let n = self.positions.len();
        if !self.indices.len().is_multiple_of(3) {
            return Err(format!(
                "{} indices is not a whole number of triangles",
                self.indices.len()
            ));
        }
        if let Some(i) = self.indices.iter().find(|&&i| i as usize >= n) {
            return Err(format!("index {i} is out of range ({n} vertices)"));
        }
        for (what, len) in [
            ("normals", self.normals.len()),
            ("uvs", self.uvs.len()),
            ("tangents", self.tangents.len()),
        ] {
            if len != n {
                return Err(format!("{len} {what} for {n} vertices"));
            }
        }
        let finite = self.positions.iter().flatten().all(|v| v.is_finite())
            && self.uvs.iter().flatten().all(|v| v.is_finite());
        if !finite {
            return Err("a position or texture coordinate is not finite".into());
        }
        Ok(())
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let positions = d.f32s()?;
        let normals = d.f32s()?;
        let uvs = d.f32s()?;
        let tangents = d.f32s()?;
        let idx = d.raw()?;
        let bad = || DecodeError::new(Self::TYPE, "attribute sizes do not agree");
        if positions.len() % 3 != 0 || idx.len() % 4 != 0 {
            return Err(bad());
        }
        let m = Mesh {
            positions: positions
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            normals: normals
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            uvs: uvs.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
            tangents: tangents
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect(),
            indices: idx
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        };
        m.check().map_err(|e| DecodeError::new(Self::TYPE, e))?;
        Ok(Arc::new(m))
    }
}

fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn any_perpendicular(n: [f32; 3]) -> [f32; 3] {
    let axis = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    normalize(sub(axis, scale(n, dot(n, axis)))).unwrap_or([1.0, 0.0, 0.0])
}

impl Value for Mesh {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.positions.len() * 48 + self.indices.len() * 4
    }
    fn encode(&self, out: &mut Encoder) {
        let flat3: Vec<f32> = self.positions.iter().flatten().copied().collect();
        let nrm: Vec<f32> = self.normals.iter().flatten().copied().collect();
        let uv: Vec<f32> = self.uvs.iter().flatten().copied().collect();
        let tan: Vec<f32> = self.tangents.iter().flatten().copied().collect();
        let idx: Vec<u8> = self.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        out.f32s(&flat3).f32s(&nrm).f32s(&uv).f32s(&tan).raw(&idx);
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quad_gets_the_frame_of_its_parametrisation() {
        // u along +x, v along +y on the z = 0 plane: tangent +x, bitangent +y, normal +z.
        let mut m = Mesh {
            positions: vec![[0., 0., 0.], [2., 0., 0.], [2., 2., 0.], [0., 2., 0.]],
            uvs: vec![[0., 0.], [1., 0.], [1., 1.], [0., 1.]],
            indices: vec![0, 1, 2, 0, 2, 3],
            ..Default::default()
        };
        m.compute_normals();
        m.compute_tangents();
        m.check().unwrap();
        for v in 0..4 {
            assert_eq!(m.normals[v], [0., 0., 1.]);
            assert_eq!(m.tangents[v], [1., 0., 0., 1.]);
        }
        // Mirrored v flips the handedness.
        m.uvs = vec![[0., 1.], [1., 1.], [1., 0.], [0., 0.]];
        m.compute_tangents();
        assert_eq!(m.tangents[0][3], -1.0);
    }

    #[test]
    fn position_twins_join_copies_across_cell_boundaries() {
        // Two copies a hair apart on either side of a multiple of the tolerance, and a distinct
        // point: the copies are twins whichever side of a cell boundary they fall.
        let eps = 1e-7f32;
        let m = Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.5, 0.0],
                [0.5 - eps, 1.0, 0.0],
                [0.5 + eps, 1.0, 0.0],
            ],
            ..Default::default()
        };
        assert_eq!(m.position_twins(), vec![0, 1, 2, 2]);
    }

    #[test]
    fn uv_scale_is_the_world_length_of_a_texture_unit() {
        // A 3 × 1 rectangle mapped to the unit square: u spans 3 units, v spans 1.
        let mut m = Mesh {
            positions: vec![[0., 0., 0.], [3., 0., 0.], [3., 1., 0.], [0., 1., 0.]],
            uvs: vec![[0., 0.], [1., 0.], [1., 1.], [0., 1.]],
            indices: vec![0, 1, 2, 0, 2, 3],
            ..Default::default()
        };
        m.compute_normals();
        for s in m.uv_scale() {
            assert!(
                (s[0] - 3.0).abs() < 1e-6 && (s[1] - 1.0).abs() < 1e-6,
                "{s:?}"
            );
        }
        // Degenerate UVs: unknown.
        m.uvs = vec![[0.5, 0.5]; 4];
        assert!(m.uv_scale().iter().all(|s| *s == [0.0, 0.0]));
    }

    #[test]
    fn degenerate_uvs_and_triangles_still_give_a_frame() {
        let mut m = Mesh {
            positions: vec![[0., 0., 0.], [1., 0., 0.], [2., 0., 0.]],
            uvs: vec![[0., 0.]; 3],
            indices: vec![0, 1, 2],
            ..Default::default()
        };
        m.compute_normals();
        m.compute_tangents();
        assert_eq!(m.degenerate_triangles(), 1);
        assert!(m.tangents.iter().flatten().all(|v| v.is_finite()));
    }
}
