//! Vector algebra on `[f64; 3]` for the renderers, the planner and the scattering code, and the
//! one mesh measure they share (its bounding sphere).

use crate::types::Mesh;

pub type V3 = [f64; 3];

pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn mul(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn normalize(a: V3) -> Option<V3> {
    let l = dot(a, a).sqrt();
    (l > 1e-300 && l.is_finite()).then(|| mul(a, 1.0 / l))
}
pub fn length(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// Two unit tangents completing the unit vector `z` to an orthonormal frame, without a branch
/// on z's direction (Duff et al. 2017, "Building an orthonormal basis, revisited").
pub fn frame(z: V3) -> (V3, V3) {
    let sign = 1f64.copysign(z[2]);
    let a = -1.0 / (sign + z[2]);
    let b = z[0] * z[1] * a;
    (
        [1.0 + sign * z[0] * z[0] * a, sign * b, -sign * z[0]],
        [b, sign + z[1] * z[1] * a, -z[1]],
    )
}

/// A direction about the unit vector `n` distributed as cos θ / π (Malley's method: a uniform
/// point of the unit disc lifted onto the hemisphere), from two uniforms in [0, 1).
pub fn cosine_direction(n: V3, u1: f64, u2: f64) -> V3 {
    let (t, b) = frame(n);
    let (r, phi) = (u1.sqrt(), 2.0 * std::f64::consts::PI * u2);
    let (x, y, z) = (r * phi.cos(), r * phi.sin(), (1.0 - u1).sqrt());
    [0, 1, 2].map(|k| t[k] * x + b[k] * y + n[k] * z)
}

/// The mesh's bounding sphere (centre, radius): centred on its bounding box, radius at least
/// 10⁻⁹ so that a single point still has a scale.
pub fn bounding_sphere(mesh: &Mesh) -> (V3, f64) {
    let (lo, hi) = mesh.bounds();
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] as f64 + hi[k] as f64));
    let r = mesh
        .positions
        .iter()
        .map(|q| length(sub(q.map(|v| v as f64), c)))
        .fold(0.0, f64::max);
    (c, r.max(1e-9))
}

/// Turns `d` by the polar angle with cosine `cos` and azimuth `phi`.
pub(crate) fn rotate(d: [f64; 3], cos: f64, phi: f64) -> [f64; 3] {
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (t, s) = frame(d);
    let (c, si) = (phi.cos() * sin, phi.sin() * sin);
    [
        c * t[0] + si * s[0] + cos * d[0],
        c * t[1] + si * s[1] + cos * d[1],
        c * t[2] + si * s[2] + cos * d[2],
    ]
}
