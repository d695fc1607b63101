// Relief mapping (Policarpo, Oliveira & Comba 2005) in one render pass: the vertex stage places
// the mesh's triangles (as peel.wgsl does), the fragment stage rebuilds the surface at the
// pixel's barycentrics and follows the view ray down through the height field in tangent space
// (linear, then binary search), shades the hit with the Ward maps and searches towards the light
// for self-shadowing. The formulas and their order are relief.rs's; see there for the units.
// The camera block and projection come from raster.wgsl, prepended.

struct Params {
    cam: Cam,
    tile: vec4<f32>,      // width, height (texels), top (texels), depth (texels)
    tiling: vec4<f32>,    // u, v, linear steps, binary steps
    light: vec4<f32>,     // direction (to the light) or position, w = 1 for a point light
    light2: vec4<f32>,    // intensity, shadows (1/0), aspect present (1/0), unused
};

@group(0) @binding(0) var<uniform> U: Params;
// positions (3n) | normals (3n) | uvs (2n) | tangents (4n) | aspect (2n)
@group(0) @binding(1) var<storage, read> mesh: array<f32>;
@group(0) @binding(2) var<storage, read> indices: array<u32>;
// heights (W·H) | grad (2·W·H) | maps (5·W·H)
@group(0) @binding(3) var<storage, read> tex: array<f32>;

struct VOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) bary: vec3<f32>,
    @location(1) @interpolate(flat) tri: u32,
};

fn vcount() -> u32 {
    return arrayLength(&mesh) / 14u;
}

fn pos(v: u32) -> vec3<f32> {
    return vec3<f32>(mesh[3u * v], mesh[3u * v + 1u], mesh[3u * v + 2u]);
}

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> VOut {
    let p = pos(indices[vi]);
    var out: VOut;
    out.clip = clip_of(U.cam, p);
    out.bary = corner_bary(vi);
    out.tri = vi / 3u;
    return out;
}

fn wrap(a: i32, n: i32) -> i32 {
    return ((a % n) + n) % n;
}

fn texel(x: i32, y: i32) -> u32 {
    let w = i32(U.tile.x);
    let h = i32(U.tile.y);
    return u32(wrap(y, h) * w + wrap(x, w));
}

struct Taps {
    idx: array<u32, 4>,
    wgt: array<f32, 4>,
};

fn taps(x: f32, y: f32) -> Taps {
    let i = floor(x);
    let j = floor(y);
    let fx = x - i;
    let fy = y - j;
    var t: Taps;
    t.idx = array<u32, 4>(texel(i32(i), i32(j)), texel(i32(i) + 1, i32(j)), texel(i32(i), i32(j) + 1), texel(i32(i) + 1, i32(j) + 1));
    t.wgt = array<f32, 4>((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy);
    return t;
}

fn surface_depth(x: f32, y: f32) -> f32 {
    let t = taps(x, y);
    var h = 0.0;
    for (var k = 0u; k < 4u; k++) {
        h += t.wgt[k] * tex[t.idx[k]];
    }
    return U.tile.z - h;
}

fn lit(x: f32, y: f32, s: f32, l: vec3<f32>) -> bool {
    if (l.z <= 0.0) {
        return false;
    }
    let dx = l.x / l.z;
    let dy = -l.y / l.z;
    let slack = 2.0 * U.tile.w / U.tiling.z / exp2(U.tiling.w);
    let speed = length(vec2<f32>(dx, dy));
    let n = u32(U.tiling.z);
    for (var i = 1u; i <= n; i++) {
        let rise = s * f32(i) / f32(n);
        // relief.rs NORMAL_SUPPORT: occluders within a texel are the normal's own facets.
        if (rise * speed >= 1.0 && surface_depth(x + rise * dx, y + rise * dy) < s - rise - slack) {
            return false;
        }
    }
    return true;
}

fn ward(rho_d: f32, rho_s: f32, alpha: f32, n: vec3<f32>, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let diffuse = rho_d / 3.14159265;
    let ci = dot(n, wi);
    let co = dot(n, wo);
    if (ci <= 0.0 || co <= 0.0) {
        return diffuse;
    }
    let h = normalize(wi + wo);
    let cd = dot(n, h);
    let tan2 = max(1.0 - cd * cd, 0.0) / (cd * cd);
    return diffuse + rho_s * exp(-tan2 / (alpha * alpha)) / (4.0 * 3.14159265 * alpha * alpha * sqrt(ci * co));
}

@fragment
fn fs(in: VOut) -> @location(0) vec4<f32> {
    let nv = vcount();
    let i0 = indices[3u * in.tri];
    let i1 = indices[3u * in.tri + 1u];
    let i2 = indices[3u * in.tri + 2u];
    let w = in.bary;
    let p = pos(i0) * w.x + pos(i1) * w.y + pos(i2) * w.z;
    let nb = 3u * nv;
    var n = vec3<f32>(0.0);
    var t0 = vec3<f32>(0.0);
    var uv = vec2<f32>(0.0);
    var k = vec2<f32>(1.0, 1.0);
    let ids = array<u32, 3>(i0, i1, i2);
    let ws = array<f32, 3>(w.x, w.y, w.z);
    var ka = vec2<f32>(0.0);
    for (var c = 0u; c < 3u; c++) {
        let v = ids[c];
        n += ws[c] * vec3<f32>(mesh[nb + 3u * v], mesh[nb + 3u * v + 1u], mesh[nb + 3u * v + 2u]);
        uv += ws[c] * vec2<f32>(mesh[6u * nv + 2u * v], mesh[6u * nv + 2u * v + 1u]);
        t0 += ws[c] * vec3<f32>(mesh[8u * nv + 4u * v], mesh[8u * nv + 4u * v + 1u], mesh[8u * nv + 4u * v + 2u]);
        ka += ws[c] * vec2<f32>(mesh[12u * nv + 2u * v], mesh[12u * nv + 2u * v + 1u]);
    }
    if (U.light2.z > 0.5) {
        k = ka;
    }
    uv = uv * U.tiling.xy;
    n = normalize(n);
    let t = normalize(t0 - n * dot(n, t0));
    let b = cross(n, t) * mesh[8u * nv + 4u * i0 + 3u];
    // The camera ray through this pixel's centre, as Camera::ray.
    let px = in.clip.xy;
    let aspect = U.cam.size.x / U.cam.size.y;
    let sx = (2.0 * px.x / U.cam.size.x - 1.0) * aspect;
    let sy = 1.0 - 2.0 * px.y / U.cam.size.y;
    var dir = U.cam.fwd.xyz;
    if (U.cam.eye.w < 0.5) {
        dir = normalize(U.cam.fwd.xyz + U.cam.right.xyz * (sx * U.cam.fwd.w) + U.cam.up.xyz * (sy * U.cam.fwd.w));
    }
    var wo = vec3<f32>(dot(-dir, t), dot(-dir, b), dot(-dir, n));
    wo.z = max(wo.z, 1e-3);
    wo = normalize(wo);
    let c = normalize(vec3<f32>(wo.x * k.x, wo.y * k.y, wo.z));
    let x0 = uv.x * U.tile.x - 0.5;
    let y0 = (1.0 - uv.y) * U.tile.y - 0.5;
    let dx = -c.x / c.z;
    let dy = c.y / c.z;
    let d = U.tile.w;
    var lo = 0.0;
    var hi = d;
    let nl = u32(U.tiling.z);
    for (var i = 1u; i <= nl; i++) {
        let s = d * f32(i) / f32(nl);
        if (s >= surface_depth(x0 + s * dx, y0 + s * dy)) {
            hi = s;
            break;
        }
        lo = s;
    }
    let nbin = u32(U.tiling.w);
    for (var j = 0u; j < nbin; j++) {
        let mid = 0.5 * (lo + hi);
        if (mid >= surface_depth(x0 + mid * dx, y0 + mid * dy)) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let hx = x0 + hi * dx;
    let hy = y0 + hi * dy;
    let tp = taps(hx, hy);
    let count = u32(U.tile.x * U.tile.y);
    var g = vec2<f32>(0.0);
    var m = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
    for (var q = 0u; q < 4u; q++) {
        let at = tp.idx[q];
        g += tp.wgt[q] * vec2<f32>(tex[count + 2u * at], tex[count + 2u * at + 1u]);
        for (var e = 0u; e < 5u; e++) {
            m[e] += tp.wgt[q] * tex[3u * count + 5u * at + e];
        }
    }
    let nm = normalize(vec3<f32>(-g.x * k.x, g.y * k.y, 1.0));
    var to_light = U.light.xyz;
    var irradiance = U.light2.x;
    if (U.light.w > 0.5) {
        let dl = U.light.xyz - p;
        irradiance = U.light2.x / max(dot(dl, dl), 1e-30);
        to_light = normalize(dl);
    }
    let wi = vec3<f32>(dot(to_light, t), dot(to_light, b), dot(to_light, n));
    let cos_i = dot(nm, wi);
    var rgb = vec3<f32>(0.0);
    if (cos_i > 0.0 && irradiance > 0.0) {
        let lc = normalize(vec3<f32>(wi.x * k.x, wi.y * k.y, wi.z));
        if (U.light2.y < 0.5 || lit(hx, hy, hi, lc)) {
            for (var ch = 0u; ch < 3u; ch++) {
                rgb[ch] = irradiance * ward(m[ch], m[3], m[4], nm, wi, wo) * cos_i;
            }
        }
    }
    return vec4<f32>(rgb, 1.0);
}
