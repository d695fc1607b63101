//! The surface at a visibility sample: position, texture coordinate, tangent frame and texel
//! aspect, interpolated from the mesh triangle's corners. What `render.mesh`'s shading
//! (`shade.rs`), its environment lighting (`environment.rs`) and `render.relief` all read, kept
//! apart so that none of them imports another for it.

use crate::support::geometry::{add, cross, dot, mul, normalize, sub, V3};
use crate::support::raytrace::layers::Frag;
use crate::types::Mesh;

/// Position, texture coordinate (times `tiling`), tangent frame and texel aspect at a visibility
/// sample of `m`, interpolated from its triangle's corners.
pub fn surface_at(m: &Mesh, tiling: [f64; 2], aspect: &[[f32; 2]], f: &Frag) -> Surface {
    let [i0, i1, i2] = m.corners(f.tri as usize);
    let w = [1.0 - f.b1 - f.b2, f.b1, f.b2];
    let lerp3 = |a: &dyn Fn(usize) -> V3| {
        let (x, y, z) = (a(i0), a(i1), a(i2));
        add(add(mul(x, w[0]), mul(y, w[1])), mul(z, w[2]))
    };
    let p = lerp3(&|i| m.positions[i].map(|v| v as f64));
    let n0 = lerp3(&|i| m.normals[i].map(|v| v as f64));
    let t0 = lerp3(&|i| {
        let t = m.tangents[i];
        [t[0] as f64, t[1] as f64, t[2] as f64]
    });
    let hand = m.tangents[i0][3] as f64;
    let uv = [0, 1].map(|k| {
        (m.uvs[i0][k] as f64 * w[0] + m.uvs[i1][k] as f64 * w[1] + m.uvs[i2][k] as f64 * w[2])
            * tiling[k]
    });
    let (t, b, n) = tangent_frame(n0, t0, hand);
    let k = if aspect.is_empty() {
        [1.0, 1.0]
    } else {
        [0, 1].map(|j| {
            aspect[i0][j] as f64 * w[0] + aspect[i1][j] as f64 * w[1] + aspect[i2][j] as f64 * w[2]
        })
    };
    Surface {
        p,
        uv,
        t,
        b,
        n,
        k,
        tri: f.tri as usize,
        bary: w,
    }
}

/// The shading's tangent frame (t, b, n) from a normal `n0`, a tangent `t0` (orthogonalised
/// against it; any perpendicular where it is parallel) and the tangent's handedness.
pub fn tangent_frame(n0: V3, t0: V3, hand: f64) -> (V3, V3, V3) {
    let n = normalize(n0).unwrap_or([0.0, 0.0, 1.0]);
    let t = normalize(sub(t0, mul(n, dot(n, t0))))
        .unwrap_or_else(|| normalize(cross(n, [0.0, 1.0, 0.3])).unwrap_or([1.0, 0.0, 0.0]));
    (t, mul(cross(n, t), hand), n)
}

/// Position, texture coordinate and tangent frame (t, b, n) at a visibility sample.
pub struct Surface {
    pub p: V3,
    pub uv: [f64; 2],
    pub t: V3,
    pub b: V3,
    pub n: V3,
    /// The texel aspect (k_u, k_v) here (`shade::texel_aspect`).
    pub k: [f64; 2],
    /// The mesh triangle it lies on, and the weights of its corners here.
    pub tri: usize,
    pub bary: [f64; 3],
}

impl Surface {
    /// A local direction in the tile's own proportions: the same line through the stretched
    /// mesostructure as through the one the BTF and MDF measured.
    pub fn canonical(&self, w: V3) -> V3 {
        normalize([w[0] * self.k[0], w[1] * self.k[1], w[2]]).unwrap_or(w)
    }

    /// World length of a unit step along canonical direction (k ⊙ w)/|k ⊙ w|, per unit of
    /// depth: 1/|k ⊙ w| for unit `w`.
    pub fn stretch(&self, w: V3) -> f64 {
        let l = (w[0] * self.k[0]).hypot(w[1] * self.k[1]).hypot(w[2]);
        if l > 0.0 {
            1.0 / l
        } else {
            1.0
        }
    }
}
