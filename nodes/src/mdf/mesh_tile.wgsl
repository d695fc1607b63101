// mdf.tabulate of a mesh tile: one invocation per (texel, view), the periodic tile walk and
// Möller–Trumbore test (raytrace/triangle.wgsl) of mesh_tile.rs in f32 (see there for the geometry).

struct Params {
    ntris: u32, width: u32, height: u32, views: u32,
    top: f32, lo: f32, lift: f32, texel: f32,
};

@group(0) @binding(0) var<uniform> P: Params;
// Per triangle 13 floats (3 corners, then x min, x max, y min, y max); then per view 4 floats
// (ray direction, cos θ).
@group(0) @binding(1) var<storage, read> input: array<f32>;
@group(0) @binding(2) var<storage, read_write> output: array<f32>;

fn corner(t: u32, k: u32) -> vec3<f32> {
    let b = 13u * t + 3u * k;
    return vec3<f32>(input[b], input[b + 1u], input[b + 2u]);
}

fn boundary(c: i32, s: i32, o: f32, d: f32) -> f32 {
    if (d == 0.0) {
        return 3.0e38;
    }
    return (f32(select(c, c + 1, s > 0)) - o) / d;
}

fn walk(o: vec3<f32>, d: vec3<f32>) -> f32 {
    if (d.z >= 0.0) {
        return -1.0;
    }
    let t_end = (P.lo - o.z) / d.z + 1e-6;
    var i = i32(floor(o.x));
    var j = i32(floor(o.y));
    let si = select(-1, 1, d.x > 0.0);
    let sj = select(-1, 1, d.y > 0.0);
    var t = 0.0;
    for (var n = 0u; n < 1000000u && t <= t_end; n = n + 1u) {
        let bu = boundary(i, si, o.x, d.x);
        let bv = boundary(j, sj, o.y, d.y);
        let exit = min(bu, bv);
        let local = vec3<f32>(o.x - f32(i), o.y - f32(j), o.z);
        let ta = t;
        let tb = min(exit, t_end);
        let xa = local.x + d.x * ta;
        let xb = local.x + d.x * tb;
        let ya = local.y + d.y * ta;
        let yb = local.y + d.y * tb;
        var best = 3.0e38;
        for (var k = 0u; k < P.ntris; k = k + 1u) {
            let b = 13u * k + 9u;
            if (max(xa, xb) < input[b] - 1e-6 || min(xa, xb) > input[b + 1u] + 1e-6
                || max(ya, yb) < input[b + 2u] - 1e-6 || min(ya, yb) > input[b + 3u] + 1e-6) {
                continue;
            }
            let s = ray_triangle(local, d, corner(k, 0u), corner(k, 1u), corner(k, 2u));
            if (s > 0.0 && s >= ta - 1e-6 && s <= tb + 1e-6) {
                best = min(best, s);
            }
        }
        if (best < 3.0e38) {
            return best;
        }
        t = exit;
        if (bu < bv) {
            i = i + si;
        } else {
            j = j + sj;
        }
    }
    return -1.0;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x >= P.width || g.y >= P.height * P.views) {
        return;
    }
    let view = g.y / P.height;
    let y = g.y % P.height;
    let vb = 13u * P.ntris + 4u * view;
    let d = vec3<f32>(input[vb], input[vb + 1u], input[vb + 2u]);
    let o = vec3<f32>((f32(g.x) + 0.5) / f32(P.width), 1.0 - (f32(y) + 0.5) / f32(P.height), P.top + P.lift);
    let t = walk(o, d);
    var out = bitcast<f32>(0x7f800000u);
    if (t >= 0.0) {
        out = max(t - P.lift / input[vb + 3u], 0.0) / P.texel;
    }
    output[(view * P.height + y) * P.width + g.x] = out;
}
