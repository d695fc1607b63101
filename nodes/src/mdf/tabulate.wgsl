// mdf.tabulate: one invocation per (texel, view). The same exact traversal as
// heightfield/raycast.rs (Amanatides–Woo over the cells, the bilinear patch's height along the
// ray is a quadratic in t), in f32, with cell boundaries computed from the cell index rather
// than accumulated so long rays do not drift.

struct Params {
    hw: u32, hh: u32, ow: u32, oh: u32,
    views: u32, _pad0: u32, _pad1: u32, _pad2: u32,
    sx: f32, sy: f32, top: f32, scale: f32,
    lo: f32, hi: f32, _pad3: f32, _pad4: f32,
}

@group(0) @binding(0) var<uniform> P: Params;
// Heights (hw·hh), then per view: ray direction in grid coordinates and the horizontal limit.
@group(0) @binding(1) var<storage, read> input: array<f32>;
@group(0) @binding(2) var<storage, read_write> output: array<f32>;

// Periodic index without a signed `%`, whose result naga's OpenGL output leaves undefined for
// negative operands (rays walk to any negative cell); the float quotient is exact enough that
// one correction step covers its rounding.
fn wrap(v: i32, n: i32) -> i32 {
    let r = v - n * i32(floor(f32(v) / f32(n)));
    return select(select(r, r - n, r >= n), r + n, r < 0);
}

fn sample(i: i32, j: i32) -> f32 {
    let x = wrap(i, i32(P.hw));
    let y = wrap(j, i32(P.hh));
    return input[u32(y * i32(P.hw) + x)];
}

fn next_boundary(c: i32, step: i32, o: f32, d: f32) -> f32 {
    if (d == 0.0) {
        return 3.0e38;
    }
    var b = f32(c);
    if (step > 0) {
        b = f32(c + 1);
    }
    return (b - o) / d;
}

// First crossing in cell (i, j) for t in [ta, tb], or -1.
fn in_cell(i: i32, j: i32, o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32) -> f32 {
    if (tb < ta) {
        return -1.0;
    }
    let h00 = sample(i, j);
    let h10 = sample(i + 1, j);
    let h01 = sample(i, j + 1);
    let h11 = sample(i + 1, j + 1);
    let c0 = h00;
    let c1 = h10 - h00;
    let c2 = h01 - h00;
    let c3 = h11 - h10 - h01 + h00;
    let ax = o.x + d.x * ta - f32(i);
    let ay = o.y + d.y * ta - f32(j);
    let az = o.z + d.z * ta;
    let k0 = az - (c0 + c1 * ax + c2 * ay + c3 * ax * ay);
    let k1 = d.z - (c1 * d.x + c2 * d.y + c3 * (ax * d.y + d.x * ay));
    let k2 = -c3 * d.x * d.y;
    let len = tb - ta;
    if (k0 <= 0.0) {
        if (k1 < 0.0 || (k1 == 0.0 && k2 < 0.0)) {
            return ta;
        }
        return -1.0;
    }
    var best = 3.0e38;
    if (abs(k2) < 1e-6 * max(abs(k1) + abs(k0), 1e-30)) {
        if (k1 < 0.0) {
            let s = -k0 / k1;
            if (s >= 0.0 && s <= len) {
                best = s;
            }
        }
    } else {
        let disc = k1 * k1 - 4.0 * k2 * k0;
        if (disc >= 0.0) {
            var sg = 1.0;
            if (k1 < 0.0) {
                sg = -1.0;
            }
            let q = -0.5 * (k1 + sg * sqrt(disc));
            let r0 = q / k2;
            if (r0 >= 0.0 && r0 <= len) {
                best = min(best, r0);
            }
            if (q != 0.0) {
                let r1 = k0 / q;
                if (r1 >= 0.0 && r1 <= len) {
                    best = min(best, r1);
                }
            }
        }
    }
    if (best < 3.0e38) {
        return ta + best;
    }
    if (k0 + len * (k1 + len * k2) < 0.0) {
        return tb;
    }
    return -1.0;
}

fn trace(o: vec3<f32>, d: vec3<f32>, max_h: f32) -> f32 {
    let inf = bitcast<f32>(0x7f800000u);
    var t = 0.0;
    if (o.z > P.hi) {
        t = (P.hi - o.z) / d.z;
    }
    let horizontal = length(d.xy);
    var t_end = 3.0e38;
    if (horizontal > 0.0) {
        t_end = t + max_h / horizontal;
    }
    let p = o + d * t;
    var i = i32(floor(p.x));
    var j = i32(floor(p.y));
    var si = -1;
    if (d.x > 0.0) {
        si = 1;
    }
    var sj = -1;
    if (d.y > 0.0) {
        sj = 1;
    }
    // A guard against a driver hang; the horizontal limit ends every real walk long before.
    for (var n = 0u; n < 4000000u; n = n + 1u) {
        let tu = next_boundary(i, si, o.x, d.x);
        let tv = next_boundary(j, sj, o.y, d.y);
        let t_exit = min(tu, tv);
        let hit = in_cell(i, j, o, d, t, min(t_exit, t_end));
        if (hit >= 0.0) {
            return hit;
        }
        let z_exit = o.z + d.z * t_exit;
        if (t_exit >= t_end || z_exit < P.lo - 1.0) {
            return inf;
        }
        t = t_exit;
        if (tu < tv) {
            i = i + si;
        } else {
            j = j + sj;
        }
    }
    return inf;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x >= P.ow || g.y >= P.oh * P.views) {
        return;
    }
    let view = g.y / P.oh;
    let y = g.y % P.oh;
    let vb = P.hw * P.hh + 4u * view;
    let d = vec3<f32>(input[vb], input[vb + 1u], input[vb + 2u]);
    let o = vec3<f32>((f32(g.x) + 0.5) * P.sx - 0.5, (f32(y) + 0.5) * P.sy - 0.5, P.top);
    output[(view * P.oh + y) * P.ow + g.x] = trace(o, d, input[vb + 3u]) * P.scale;
}
