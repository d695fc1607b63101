// The ray–triangle test every shader shares (Möller–Trumbore in f32, as raytrace/tracer.rs does
// it in f64): the signed distance along (o, d) to triangle p0 p1 p2, or TRIANGLE_MISS where the
// line misses it or the triangle is degenerate. Joined before each shader that uses it.
const TRIANGLE_MISS: f32 = -3.0e38;

fn ray_triangle(o: vec3<f32>, d: vec3<f32>, p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>) -> f32 {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    let scale = length(e1) * length(e2);
    if (scale == 0.0 || abs(det) <= 1e-12 * scale) {
        return TRIANGLE_MISS;
    }
    let inv = 1.0 / det;
    let s = o - p0;
    let b1 = dot(s, pv) * inv;
    if (b1 < 0.0 || b1 > 1.0) {
        return TRIANGLE_MISS;
    }
    let q = cross(s, e1);
    let b2 = dot(d, q) * inv;
    if (b2 < 0.0 || b1 + b2 > 1.0) {
        return TRIANGLE_MISS;
    }
    return dot(e2, q) * inv;
}
