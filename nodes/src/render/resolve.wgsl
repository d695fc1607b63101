// Resolve of the visibility layers: the MDF shell test and shading, line for line the CPU path
// in shade.rs and material.rs (same interpolation scheme, same rules), in f32.

struct Cam {
    eye: vec4<f32>,
    fwd: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    size: vec4<f32>,
};

struct Params {
    cam: Cam,
    scam: Cam,
    light: vec4<f32>,      // direction towards the light, intensity
    light_pos: vec4<f32>,  // xyz, w = 1 for a point light
    misc: vec4<f32>,       // tiling u, shell, shadow bias, tiling v
    background: vec4<f32>, // rgb, w = 1 for parallax (lookup at the hit's texel)
    mdf: vec4<f32>,        // width, height, depth, present
    rings: vec4<f32>,      // cos θ of the outermost and next light rings, w = 1 to extrapolate
    mat: vec4<u32>,        // kind (0 raw, 1 basis), width, height, ycbcr
    dirs: vec4<u32>,       // btf views, btf lights, mdf views, layers
    offs: vec4<u32>,       // vertices, mode (0 shadow depth, 1 shade), shadows, owners offset
    offs2: vec4<u32>,      // blocks offset in `tables`, light dirs offset, mdf dirs offset, pair_of offset
    rings_at: vec4<u32>,   // ring tables in `dirs` of the views, lights, MDF views (NONE: not rings)
    sides: vec4<u32>,      // the shell's side walls in `mesh`: offset, count (four corners each)
    env: vec4<u32>,        // environment functions per colour (0: none), transfer offset in `envd`
};

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> mesh: array<f32>;      // pos | nrm | uv | tangent
@group(0) @binding(2) var<storage, read> tables: array<u32>;    // indices | pair_of | owners | blocks
@group(0) @binding(3) var<storage, read> material: array<f32>;  // raw BTF, or basis floats
@group(0) @binding(4) var<storage, read> dirs: array<f32>;      // btf views | lights | mdf views
@group(0) @binding(5) var<storage, read> mdf: array<f32>;
@group(0) @binding(6) var<storage, read> shadow: array<f32>;
@group(0) @binding(7) var<storage, read_write> out: array<vec4<f32>>;
@group(0) @binding(8) var layers: texture_2d_array<f32>;
@group(0) @binding(9) var<storage, read> envd: array<f32>;      // lighting | transfer

const NONE: u32 = 0xffffffffu;
// A side wall in `mesh`: four corners, its triangle, the corner slots of its edge.
const SIDE_FLOATS: u32 = 15u;
// shade.rs's SHADOW_SLACK and material.rs's IMPLIED_FLOOR.
const SHADOW_SLACK: f32 = 1.0;
const IMPLIED_FLOOR: f32 = 0.1;

fn inf() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

struct Ray {
    o: vec3<f32>,
    d: vec3<f32>,
};

fn cam_ray(c: Cam, x: u32, y: u32) -> Ray {
    let sx = (2.0 * (f32(x) + 0.5) / c.size.x - 1.0) * c.right.w;
    let sy = 1.0 - 2.0 * (f32(y) + 0.5) / c.size.y;
    var r: Ray;
    if (c.eye.w > 0.5) {
        r.o = c.eye.xyz + c.right.xyz * (sx * c.fwd.w) + c.up.xyz * (sy * c.fwd.w);
        r.d = c.fwd.xyz;
    } else {
        r.o = c.eye.xyz;
        r.d = normalize(c.fwd.xyz + c.right.xyz * (sx * c.fwd.w) + c.up.xyz * (sy * c.fwd.w));
    }
    return r;
}

struct Surface {
    p: vec3<f32>,
    uv: vec2<f32>,
    t: vec3<f32>,
    b: vec3<f32>,
    n: vec3<f32>,
    // The texel aspect (k_u, k_v) (shade.rs's texel_aspect).
    k: vec2<f32>,
    tri: u32,
    // The barycentric weights of the triangle's corners.
    bary: vec3<f32>,
};

fn v3(base: u32, i: u32) -> vec3<f32> {
    return vec3<f32>(mesh[base + 3u * i], mesh[base + 3u * i + 1u], mesh[base + 3u * i + 2u]);
}

fn surface(f: vec4<f32>) -> Surface {
    let n = P.offs.x;
    let tri = u32(f.w);
    let i0 = tables[3u * tri];
    let i1 = tables[3u * tri + 1u];
    let i2 = tables[3u * tri + 2u];
    let w = vec3<f32>(1.0 - f.y - f.z, f.y, f.z);
    var s: Surface;
    s.p = v3(0u, i0) * w.x + v3(0u, i1) * w.y + v3(0u, i2) * w.z;
    let n0 = v3(3u * n, i0) * w.x + v3(3u * n, i1) * w.y + v3(3u * n, i2) * w.z;
    let ub = 6u * n;
    let uv0 = vec2<f32>(mesh[ub + 2u * i0], mesh[ub + 2u * i0 + 1u]);
    let uv1 = vec2<f32>(mesh[ub + 2u * i1], mesh[ub + 2u * i1 + 1u]);
    let uv2 = vec2<f32>(mesh[ub + 2u * i2], mesh[ub + 2u * i2 + 1u]);
    s.uv = (uv0 * w.x + uv1 * w.y + uv2 * w.z) * vec2<f32>(P.misc.x, P.misc.w);
    let tb = 8u * n;
    let t0 = vec3<f32>(mesh[tb + 4u * i0], mesh[tb + 4u * i0 + 1u], mesh[tb + 4u * i0 + 2u]) * w.x
        + vec3<f32>(mesh[tb + 4u * i1], mesh[tb + 4u * i1 + 1u], mesh[tb + 4u * i1 + 2u]) * w.y
        + vec3<f32>(mesh[tb + 4u * i2], mesh[tb + 4u * i2 + 1u], mesh[tb + 4u * i2 + 2u]) * w.z;
    let hand = mesh[tb + 4u * i0 + 3u];
    var nn = vec3<f32>(0.0, 0.0, 1.0);
    if (length(n0) > 1e-30) {
        nn = normalize(n0);
    }
    var tt = t0 - nn * dot(nn, t0);
    if (length(tt) > 1e-30) {
        tt = normalize(tt);
    } else {
        tt = normalize(cross(nn, vec3<f32>(0.0, 1.0, 0.3)));
    }
    s.n = nn;
    s.t = tt;
    s.b = cross(nn, tt) * hand;
    s.tri = tri;
    s.bary = w;
    let kb = 12u * n;
    s.k = vec2<f32>(mesh[kb + 2u * i0], mesh[kb + 2u * i0 + 1u]) * w.x
        + vec2<f32>(mesh[kb + 2u * i1], mesh[kb + 2u * i1 + 1u]) * w.y
        + vec2<f32>(mesh[kb + 2u * i2], mesh[kb + 2u * i2 + 1u]) * w.z;
    return s;
}

// A local direction in the tile's own proportions (shade.rs's Surface::canonical).
fn canonical(s: Surface, w: vec3<f32>) -> vec3<f32> {
    let c = vec3<f32>(w.x * s.k.x, w.y * s.k.y, w.z);
    if (length(c) > 1e-30) {
        return normalize(c);
    }
    return w;
}

// World length along canonical direction per unit of depth (shade.rs's Surface::stretch).
fn stretch(s: Surface, w: vec3<f32>) -> f32 {
    let l = length(vec3<f32>(w.x * s.k.x, w.y * s.k.y, w.z));
    return select(1.0, 1.0 / l, l > 0.0);
}

fn local(s: Surface, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(v, s.t), dot(v, s.b), dot(v, s.n));
}

fn local_up(v: vec3<f32>) -> vec3<f32> {
    if (v.z >= 1e-4) {
        return v;
    }
    let h = max(length(v.xy), 1e-12);
    return vec3<f32>(v.x / h, v.y / h, 1e-4);
}

struct Blend {
    idx: array<u32, 4>,
    w: array<f32, 4>,
    count: u32,
};

const TAU: f32 = 6.283185307179586;

fn wrap_angle(x: f32) -> f32 {
    return x - TAU * floor(x / TAU);
}

// The header of ring r in the ring table at dirs[table..] (rings.rs's encode: ring count, then
// per ring θ, member count, members' (φ, index)).
fn ring_at(table: u32, r: u32) -> u32 {
    var o = table + 1u;
    for (var k = 0u; k < r; k = k + 1u) {
        o = o + 2u + 2u * u32(dirs[o + 1u]);
    }
    return o;
}

fn push(b: ptr<function, Blend>, i: u32, w: f32) {
    (*b).idx[(*b).count] = i;
    (*b).w[(*b).count] = w;
    (*b).count = (*b).count + 1u;
}

// Ring (header at o) at azimuth phi: the two members bracketing it, linear in φ, times scale.
fn on_ring(b: ptr<function, Blend>, o: u32, phi: f32, scale: f32) {
    let c = u32(dirs[o + 1u]);
    if (c == 1u) {
        push(b, u32(dirs[o + 3u]), scale);
        return;
    }
    var j = c;
    for (var k = 0u; k < c; k = k + 1u) {
        if (dirs[o + 2u + 2u * k] > phi) {
            j = k;
            break;
        }
    }
    var ia = j - 1u;
    var ib = j;
    if (j == 0u || j == c) {
        ia = c - 1u;
        ib = 0u;
    }
    let pa = dirs[o + 2u + 2u * ia];
    let pb = dirs[o + 2u + 2u * ib];
    let span = wrap_angle(pb - pa);
    var t = 0.0;
    if (span > 0.0) {
        t = clamp(wrap_angle(phi - pa) / span, 0.0, 1.0);
    }
    push(b, u32(dirs[o + 3u + 2u * ia]), scale * (1.0 - t));
    push(b, u32(dirs[o + 3u + 2u * ib]), scale * t);
}

// The blend of q over `count` directions at dirs[base..]: bilinear over their ring table at
// dirs[table..] (rings.rs), or the nearest three where the set has none (table = NONE).
fn lookup(base: u32, count: u32, table: u32, q: vec3<f32>) -> Blend {
    if (table == NONE) {
        return blend(base, count, q, -1.0);
    }
    let theta = acos(clamp(q.z, -1.0, 1.0));
    let phi = wrap_angle(atan2(q.y, q.x));
    let n = u32(dirs[table]);
    var below = 0u;
    var o = table + 1u;
    var oa = o;
    var ob = o;
    for (var r = 0u; r < n; r = r + 1u) {
        if (dirs[o] <= theta) {
            below = r + 1u;
            oa = o;
        } else if (below == r) {
            ob = o;
        }
        o = o + 2u + 2u * u32(dirs[o + 1u]);
    }
    var b: Blend;
    b.count = 0u;
    if (below == 0u) {
        on_ring(&b, table + 1u, phi, 1.0);
    } else if (below == n) {
        on_ring(&b, oa, phi, 1.0);
    } else {
        let s = (theta - dirs[oa]) / (dirs[ob] - dirs[oa]);
        on_ring(&b, oa, phi, 1.0 - s);
        on_ring(&b, ob, phi, s);
    }
    for (var k = 0u; k < b.count; k = k + 1u) {
        let i = b.idx[k];
        let d = vec3<f32>(dirs[base + 3u * i], dirs[base + 3u * i + 1u], dirs[base + 3u * i + 2u]);
        if (acos(clamp(dot(d, q), -1.0, 1.0)) < 1e-4) {
            var one: Blend;
            one.count = 1u;
            one.idx[0] = i;
            one.w[0] = 1.0;
            return one;
        }
    }
    return b;
}

// The three nearest of `count` directions at dirs[base..] to q; exact within 1e-4 rad.
// `ring` ≥ 0 keeps only the directions within 0.01 rad of that polar angle (material.rs's
// blend_ring); a negative `ring` keeps all.
fn blend(base: u32, count: u32, q: vec3<f32>, ring: f32) -> Blend {
    var bi = vec3<u32>(NONE, NONE, NONE);
    var ba = vec3<f32>(1e9, 1e9, 1e9);
    var kept = 0u;
    for (var i = 0u; i < count; i = i + 1u) {
        let d = vec3<f32>(dirs[base + 3u * i], dirs[base + 3u * i + 1u], dirs[base + 3u * i + 2u]);
        if (ring >= 0.0 && abs(acos(clamp(d.z, -1.0, 1.0)) - ring) >= 0.01) {
            continue;
        }
        kept = kept + 1u;
        let a = acos(clamp(dot(d, q), -1.0, 1.0));
        if (a < ba.x) {
            ba = vec3<f32>(a, ba.x, ba.y);
            bi = vec3<u32>(i, bi.x, bi.y);
        } else if (a < ba.y) {
            ba = vec3<f32>(ba.x, a, ba.y);
            bi = vec3<u32>(bi.x, i, bi.y);
        } else if (a < ba.z) {
            ba.z = a;
            bi.z = i;
        }
    }
    var b: Blend;
    b.idx[0] = bi.x;
    b.idx[1] = bi.y;
    b.idx[2] = bi.z;
    b.count = min(kept, 3u);
    if (ba.x < 1e-4) {
        b.count = 1u;
        b.w[0] = 1.0;
        return b;
    }
    var inv = vec3<f32>(1.0 / ba.x, 0.0, 0.0);
    if (b.count > 1u) {
        inv.y = 1.0 / ba.y;
    }
    if (b.count > 2u) {
        inv.z = 1.0 / ba.z;
    }
    let w = inv / (inv.x + inv.y + inv.z);
    b.w[0] = w.x;
    b.w[1] = w.y;
    b.w[2] = w.z;
    return b;
}

fn wrapi(v: i32, n: i32) -> u32 {
    let r = v - n * i32(floor(f32(v) / f32(n)));
    return u32(select(select(r, r - n, r >= n), r + n, r < 0));
}

struct Taps {
    x: vec2<u32>,
    y: vec2<u32>,
    f: vec2<f32>,
};

fn taps(uv: vec2<f32>, w: u32, h: u32) -> Taps {
    let x = uv.x * f32(w) - 0.5;
    let y = (1.0 - uv.y) * f32(h) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    var t: Taps;
    t.f = vec2<f32>(x - x0, y - y0);
    t.x = vec2<u32>(wrapi(i32(x0), i32(w)), wrapi(i32(x0) + 1, i32(w)));
    t.y = vec2<u32>(wrapi(i32(y0), i32(h)), wrapi(i32(y0) + 1, i32(h)));
    return t;
}

fn tap_weight(t: Taps, k: u32) -> f32 {
    let fx = select(1.0 - t.f.x, t.f.x, (k & 1u) == 1u);
    let fy = select(1.0 - t.f.y, t.f.y, k >= 2u);
    return fx * fy;
}

fn ycbcr_to_rgb(c: vec3<f32>) -> vec3<f32> {
    let r = c.x + 1.402 * c.z;
    let b = c.x + 1.772 * c.y;
    return vec3<f32>(r, (c.x - 0.299 * r - 0.114 * b) / 0.587, b);
}

fn texel(pair: u32, x: u32, y: u32) -> vec3<f32> {
    let w = P.mat.y;
    let h = P.mat.z;
    let t = y * w + x;
    let plane = w * h;
    if (P.mat.x == 0u) {
        let base = pair * 3u * plane + t;
        return vec3<f32>(material[base], material[base + plane], material[base + 2u * plane]);
    }
    var c = vec3<f32>(0.0);
    for (var ch = 0u; ch < 3u; ch = ch + 1u) {
        let o = P.offs.w + 2u * (pair * 3u + ch);
        let blk = tables[o];
        if (blk == NONE) {
            continue;
        }
        let j = tables[o + 1u];
        let r = P.offs2.x + 6u * blk;
        let mean_off = tables[r];
        let maps_off = tables[r + 1u];
        let basis_off = tables[r + 2u];
        let k = tables[r + 3u];
        let n = tables[r + 4u];
        var s = material[mean_off + j];
        if (tables[r + 5u] == 1u) {
            s = material[mean_off + t];
        }
        for (var kk = 0u; kk < k; kk = kk + 1u) {
            s = s + material[maps_off + kk * plane + t] * material[basis_off + kk * n + j];
        }
        c[ch] = s;
    }
    if (P.mat.w == 1u) {
        return ycbcr_to_rgb(c);
    }
    return c;
}

// How much light from local direction l reaches the point `depth` MDF texels below the top at
// uv (material.rs's MdfLookup::reaches): each MDF view blended for l asked along its own line
// through the point.
fn reaches(uv: vec2<f32>, depth: f32, l: vec3<f32>, slack: f32) -> f32 {
    if (l.z <= 1e-4) {
        return 0.0;
    }
    let mw = u32(P.mdf.x);
    let mh = u32(P.mdf.y);
    let bv = lookup(P.offs2.z, P.dirs.z, P.rings_at.z, l);
    var out = 0.0;
    for (var a = 0u; a < bv.count; a = a + 1u) {
        let i = bv.idx[a];
        let vk = vec3<f32>(dirs[P.offs2.z + 3u * i], dirs[P.offs2.z + 3u * i + 1u], dirs[P.offs2.z + 3u * i + 2u]);
        if (vk.z <= 1e-6) {
            continue;
        }
        let reach = depth / vk.z;
        let tp = taps(uv + reach * vk.xy / P.mdf.xy, mw, mh);
        var sum = 0.0;
        var weight = 0.0;
        for (var k = 0u; k < 4u; k = k + 1u) {
            let tw = tap_weight(tp, k);
            let d = mdf[(i * mh + tp.y[k >> 1u]) * mw + tp.x[k & 1u]];
            if (d < 3.0e38 && tw > 0.0) {
                sum = sum + d * tw;
                weight = weight + tw;
            }
        }
        var met = inf();
        if (weight >= 0.5) {
            met = sum / weight;
        }
        let sl = slack * (1.0 + 0.05 * reach);
        out = out + bv.w[a] * clamp(1.0 - (reach - sl - met), 0.0, 1.0);
    }
    return out;
}

// The light's visibility at the view hit (shade.rs's light_visibility); 1 where there is no
// depth (no MDF, or lookups at the hit's own texel).
fn light_visible(uv: vec2<f32>, wo: vec3<f32>, depth: vec2<f32>, l: vec3<f32>) -> f32 {
    if (P.mdf.w < 0.5 || (depth.x <= 0.0 && depth.y <= 0.0)) {
        return 1.0;
    }
    let hit = uv - depth * wo.xy;
    return reaches(hit, depth.x * P.mdf.x * wo.z, l, SHADOW_SLACK);
}

// The visibility a blend of sampled lights implies (material.rs).
fn implied(bl: Blend, uv: vec2<f32>, wo: vec3<f32>, depth: vec2<f32>, shadowed: bool) -> f32 {
    if (!shadowed) {
        return 1.0;
    }
    var v = 0.0;
    for (var k = 0u; k < bl.count; k = k + 1u) {
        let i = P.offs2.y + 3u * bl.idx[k];
        v = v + bl.w[k] * light_visible(uv, wo, depth, vec3<f32>(dirs[i], dirs[i + 1u], dirs[i + 2u]));
    }
    return v;
}

// The sampled lights' value with the query's own visibility for the one they imply, only ever
// darker (material.rs's eval_shadowed).
fn reshadow(e: vec3<f32>, own: f32, implied: f32) -> vec3<f32> {
    return e * min((own + IMPLIED_FLOOR) / (implied + IMPLIED_FLOOR), 1.0);
}

// Beyond the outermost light ring: the two outer rings at the light's azimuth, continued as a
// power of cos θ (material.rs); the MDF's shadows carried over as in reshadow.
// `shadowed` false: the BTF alone (material.rs's eval_at_depth), no MDF shadows.
fn btf_eval(uv: vec2<f32>, wo: vec3<f32>, wi: vec3<f32>, depth: vec2<f32>, shadowed: bool) -> vec3<f32> {
    let c1 = P.rings.x;
    let c0 = P.rings.y;
    var own = 1.0;
    if (shadowed) {
        own = light_visible(uv, wo, depth, wi);
    }
    if (P.rings.w < 0.5 || wi.z >= c1 - 1e-9) {
        let bl = lookup(P.offs2.y, P.dirs.y, P.rings_at.y, wi);
        return reshadow(btf_eval_sampled(uv, wo, depth, bl), own, implied(bl, uv, wo, depth, shadowed));
    }
    let h = length(wi.xy);
    var cs = vec2<f32>(1.0, 0.0);
    if (h > 1e-12) {
        cs = wi.xy / h;
    }
    let s1 = sqrt(max(1.0 - c1 * c1, 0.0));
    let s0 = sqrt(max(1.0 - c0 * c0, 0.0));
    var b1: Blend;
    var b0: Blend;
    b1.count = 0u;
    b0.count = 0u;
    let table = P.rings_at.y;
    if (table != NONE) {
        let n = u32(dirs[table]);
        let phi = wrap_angle(atan2(cs.y, cs.x));
        on_ring(&b1, ring_at(table, n - 1u), phi, 1.0);
        on_ring(&b0, ring_at(table, n - 2u), phi, 1.0);
    } else {
        b1 = blend(P.offs2.y, P.dirs.y, vec3<f32>(s1 * cs.x, s1 * cs.y, c1), acos(clamp(c1, -1.0, 1.0)));
        b0 = blend(P.offs2.y, P.dirs.y, vec3<f32>(s0 * cs.x, s0 * cs.y, c0), acos(clamp(c0, -1.0, 1.0)));
    }
    let e1 = reshadow(btf_eval_sampled(uv, wo, depth, b1), own, implied(b1, uv, wo, depth, shadowed));
    let e0 = reshadow(btf_eval_sampled(uv, wo, depth, b0), own, implied(b0, uv, wo, depth, shadowed));
    // A power of cos θ through the two rings (material.rs).
    let c = max(wi.z, 1e-6);
    var out = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k = k + 1u) {
        if (e1[k] > 0.0 && e0[k] > 0.0) {
            let p = max(log(e1[k] / e0[k]) / log(c1 / c0), 0.0);
            out[k] = e1[k] * pow(c / c1, p);
        } else {
            out[k] = e1[k] * c / c1;
        }
    }
    return out;
}

// `depth`: the hit's distance along the view ray in tile units (u, v), 0 for none; each view
// is read where its ray meets the same point (material.rs's parallax-compensated view blend).
fn btf_eval_sampled(uv: vec2<f32>, wo: vec3<f32>, depth: vec2<f32>, bl: Blend) -> vec3<f32> {
    let nv = P.dirs.x;
    let nl = P.dirs.y;
    let bv = lookup(0u, nv, P.rings_at.x, wo);
    var pairs = array<u32, 16>();
    var views = array<u32, 16>();
    var weights = array<f32, 16>();
    var total = 0.0;
    var m = 0u;
    for (var a = 0u; a < bv.count; a = a + 1u) {
        for (var b = 0u; b < bl.count; b = b + 1u) {
            let p = tables[P.offs2.w + bv.idx[a] * nl + bl.idx[b]];
            if (p != NONE) {
                pairs[m] = p;
                views[m] = bv.idx[a];
                weights[m] = bv.w[a] * bl.w[b];
                total = total + weights[m];
                m = m + 1u;
            }
        }
    }
    if (total <= 0.0) {
        return vec3<f32>(0.0);
    }
    var acc = vec3<f32>(0.0);
    for (var i = 0u; i < m; i = i + 1u) {
        var at = uv;
        if (depth.x > 0.0 || depth.y > 0.0) {
            let vi = views[i];
            let vk = vec3<f32>(dirs[3u * vi], dirs[3u * vi + 1u], dirs[3u * vi + 2u]);
            let k = wo.z / max(vk.z, 1e-3);
            at = uv + depth * (vk.xy * k - wo.xy);
        }
        let tp = taps(at, P.mat.y, P.mat.z);
        for (var k = 0u; k < 4u; k = k + 1u) {
            let tw = tap_weight(tp, k);
            if (tw == 0.0) {
                continue;
            }
            acc = acc + texel(pairs[i], tp.x[k & 1u], tp.y[k >> 1u]) * (weights[i] * tw / total);
        }
    }
    return acc;
}

// The MDF's distance in texels at uv along wc (material.rs's MdfLookup::eval); ∞ for a miss.
fn mdf_lookup(uv: vec2<f32>, wc: vec3<f32>) -> f32 {
    let mw = u32(P.mdf.x);
    let mh = u32(P.mdf.y);
    let tp = taps(uv, mw, mh);
    let bv = lookup(P.offs2.z, P.dirs.z, P.rings_at.z, wc);
    var sum = 0.0;
    var weight = 0.0;
    for (var a = 0u; a < bv.count; a = a + 1u) {
        for (var k = 0u; k < 4u; k = k + 1u) {
            let tw = tap_weight(tp, k);
            let d = mdf[(bv.idx[a] * mh + tp.y[k >> 1u]) * mw + tp.x[k & 1u]];
            if (d < 3.0e38 && tw > 0.0) {
                sum = sum + d * bv.w[a] * tw;
                weight = weight + bv.w[a] * tw;
            }
        }
    }
    if (weight < 0.5) {
        return inf();
    }
    return sum / weight;
}

// (world distance, MDF texels) to the mesostructure along the local view `wo` (looked up along
// `wc`, canonical(s, wo) above the horizon), 0 without an MDF.
fn mdf_distance(s: Surface, wo: vec3<f32>, wc: vec3<f32>) -> vec2<f32> {
    if (P.mdf.w < 0.5 || P.mdf.z <= 0.0) {
        return vec2<f32>(0.0, 0.0);
    }
    let d = mdf_lookup(s.uv, wc);
    if (d >= 3.0e38) {
        return vec2<f32>(inf(), inf());
    }
    return vec2<f32>(d * P.misc.y / P.mdf.z * stretch(s, wo), d);
}

struct Hit {
    found: bool,
    t: f32,
    t_front: f32,
    s: Surface,
    wo: vec3<f32>,
    depth: vec2<f32>,
};

fn corner(o: u32, k: u32) -> vec3<f32> {
    let i = o + 3u * k;
    return vec3<f32>(mesh[i], mesh[i + 1u], mesh[i + 2u]);
}

// The nearest distance beyond `after` at which (o, d) crosses a side wall (shade.rs's side_exit).
fn side_exit(o: vec3<f32>, d: vec3<f32>, after: f32) -> f32 {
    var best = inf();
    for (var q = 0u; q < P.sides.y; q = q + 1u) {
        let base = P.sides.x + SIDE_FLOATS * q;
        let a = corner(base, 0u);
        let b = corner(base, 1u);
        let c = corner(base, 2u);
        let e = corner(base, 3u);
        let t1 = ray_triangle(o, d, a, b, c);
        if (t1 > after && t1 < best) {
            best = t1;
        }
        let t2 = ray_triangle(o, d, a, c, e);
        if (t2 > after && t2 < best) {
            best = t2;
        }
    }
    return best;
}

// A hit at t entering the top at s, dtex MDF texels along wc (shade.rs's deep_hit).
fn deep_hit(s: Surface, dtex: f32, wc: vec3<f32>, t: f32, t_front: f32) -> Hit {
    var h: Hit;
    h.found = true;
    h.t = t;
    h.t_front = t_front;
    h.s = s;
    h.wo = wc;
    h.depth = vec2<f32>(0.0, 0.0);
    if (P.background.w > 0.5) {
        h.s.uv = s.uv - dtex * wc.xy / P.mdf.xy;
    } else if (P.mdf.w > 0.5 && dtex > 0.0) {
        h.depth = dtex / P.mdf.xy;
    }
    return h;
}

fn wall_inward(base: u32) -> vec3<f32> {
    return cross(corner(base, 1u) - corner(base, 0u), corner(base, 3u) - corner(base, 0u));
}

fn wall_crossing(base: u32, o: vec3<f32>, d: vec3<f32>, after: f32) -> f32 {
    var best = inf();
    let t1 = ray_triangle(o, d, corner(base, 0u), corner(base, 1u), corner(base, 2u));
    if (t1 > after && t1 < best) {
        best = t1;
    }
    let t2 = ray_triangle(o, d, corner(base, 0u), corner(base, 2u), corner(base, 3u));
    if (t2 > after && t2 < best) {
        best = t2;
    }
    return best;
}

// Where a ray entering the shell through a side wall before `before` meets mesostructure
// (shade.rs's side_hit).
fn side_hit(o: vec3<f32>, d: vec3<f32>, before: f32) -> Hit {
    var none: Hit;
    none.found = false;
    if (P.mdf.w < 0.5 || P.mdf.z <= 0.0) {
        return none;
    }
    var tw = inf();
    var wall = NONE;
    for (var q = 0u; q < P.sides.y; q = q + 1u) {
        let base = P.sides.x + SIDE_FLOATS * q;
        if (dot(d, wall_inward(base)) <= 0.0) {
            continue;
        }
        let t = wall_crossing(base, o, d, 0.0);
        if (t < before && t < tw) {
            tw = t;
            wall = base;
        }
    }
    if (wall == NONE) {
        return none;
    }
    let p = o + d * tw;
    let q0 = corner(wall, 0u);
    let edge = corner(wall, 1u) - q0;
    let along = clamp(dot(p - q0, edge) / max(dot(edge, edge), 1e-30), 0.0, 1.0);
    var w = array<f32, 3>(0.0, 0.0, 0.0);
    w[u32(mesh[wall + 13u])] = 1.0 - along;
    w[u32(mesh[wall + 14u])] = along;
    let s = surface(vec4<f32>(tw, w[1], w[2], mesh[wall + 12u]));
    let top = q0 + edge * along;
    let below = max(dot(top - p, s.n), 0.0);
    let wo_world = local_up(local(s, -d));
    let wc = local_up(canonical(s, wo_world));
    let per_texel = P.misc.y / P.mdf.z * stretch(s, wo_world);
    let back = below / wo_world.z / per_texel;
    var entry = s;
    entry.uv = s.uv + back * wc.xy / P.mdf.xy;
    let met = mdf_lookup(entry.uv, wc);
    if (met >= 3.0e38) {
        return none;
    }
    let dtex = max(met, back);
    let t = tw + (dtex - back) * per_texel;
    if (t >= side_exit(o, d, tw * (1.0 + 1e-6) + 1e-9)) {
        return none;
    }
    return deep_hit(entry, dtex, wc, t, tw);
}

fn find_hit(x: u32, y: u32, o: vec3<f32>, d: vec3<f32>) -> Hit {
    let first = textureLoad(layers, vec2<i32>(i32(x), i32(y)), 0, 0);
    var before = inf();
    if (first.x >= 0.0) {
        before = first.x;
    }
    if (P.sides.y > 0u) {
        let sh = side_hit(o, d, before);
        if (sh.found) {
            return sh;
        }
    }
    var h: Hit;
    h.found = false;
    for (var k = 0u; k < P.dirs.w; k = k + 1u) {
        let f = textureLoad(layers, vec2<i32>(i32(x), i32(y)), i32(2u * k), 0);
        if (f.x < 0.0) {
            break;
        }
        let s = surface(f);
        let wo = local_up(local(s, -d));
        let wc = local_up(canonical(s, wo));
        let df = mdf_distance(s, wo, wc);
        var tb = inf();
        let b = textureLoad(layers, vec2<i32>(i32(x), i32(y)), i32(2u * k + 1u), 0);
        if (b.x >= 0.0) {
            let sb = surface(b);
            let outward = local_up(local(sb, d));
            tb = b.x - mdf_distance(sb, outward, local_up(canonical(sb, outward))).x;
        } else {
            // No back face: bounded by the shell's side, where the mesh has one.
            tb = side_exit(o, d, f.x);
        }
        if (df.x < 3.0e38 && f.x + df.x < tb) {
            return deep_hit(s, df.y, wc, f.x + df.x, f.x);
        }
    }
    return h;
}

fn unit_or_up(v: vec3<f32>) -> vec3<f32> {
    if (length(v) > 1e-30) {
        return normalize(v);
    }
    return vec3<f32>(0.0, 0.0, 1.0);
}

// The normal curvature along world tangent direction a on triangle tri (shade.rs's curvature).
fn curvature(tri: u32, a: vec3<f32>) -> f32 {
    let n = P.offs.x;
    let i0 = tables[3u * tri];
    let i1 = tables[3u * tri + 1u];
    let i2 = tables[3u * tri + 2u];
    let e1 = v3(0u, i1) - v3(0u, i0);
    let e2 = v3(0u, i2) - v3(0u, i0);
    let n0 = unit_or_up(v3(3u * n, i0));
    let n1 = unit_or_up(v3(3u * n, i1));
    let n2 = unit_or_up(v3(3u * n, i2));
    let g11 = dot(e1, e1);
    let g12 = dot(e1, e2);
    let g22 = dot(e2, e2);
    let det = g11 * g22 - g12 * g12;
    if (abs(det) <= 1e-12 * g11 * g22) {
        return 0.0;
    }
    let r1 = dot(a, e1);
    let r2 = dot(a, e2);
    let alpha = (g22 * r1 - g12 * r2) / det;
    let beta = (g11 * r2 - g12 * r1) / det;
    return dot((n1 - n0) * alpha + (n2 - n0) * beta, a);
}

// Light past the macro horizon on a convex surface (shade.rs's past_horizon).
fn past_horizon(s: Surface, wo: vec3<f32>, depth: vec2<f32>, to_light: vec3<f32>, wi: vec3<f32>, below_in: f32) -> vec3<f32> {
    let zero = vec3<f32>(0.0);
    if (P.mdf.w < 0.5 || P.mdf.z <= 0.0 || (depth.x <= 0.0 && depth.y <= 0.0) || P.rings.w < 0.5) {
        return zero;
    }
    let c1 = P.rings.x;
    let c0 = P.rings.y;
    let t = to_light - s.n * dot(s.n, to_light);
    if (length(t) < 1e-20) {
        return zero;
    }
    let a = normalize(t);
    let kappa = curvature(s.tri, a);
    if (kappa <= 0.0) {
        return zero;
    }
    let sin_e = wi.z;
    let cos_e = sqrt(max(1.0 - wi.z * wi.z, 0.0));
    let tan_e = sin_e / max(cos_e, 1e-12);
    let below = max(below_in, 0.0);
    if (P.misc.y - below < tan_e * tan_e / (2.0 * kappa)) {
        return zero;
    }
    let exit = (-tan_e + sqrt(tan_e * tan_e + 2.0 * kappa * below)) / kappa;
    let chord = atan(below / max(exit, 1e-30));
    let al = local(s, a);
    let dir = al.xy / max(length(al.xy), 1e-30);
    let hit = s.uv - depth * wo.xy;
    let lit = reaches(hit, depth.x * P.mdf.x * wo.z, canonical(s, vec3<f32>(dir * cos(chord), sin(chord))), 0.0);
    if (lit <= 0.0) {
        return zero;
    }
    let k1 = sqrt(max(1.0 - c1 * c1, 0.0));
    let k0 = sqrt(max(1.0 - c0 * c0, 0.0));
    let e1 = btf_eval(s.uv, wo, canonical(s, vec3<f32>(dir * k1, c1)), depth, false);
    let e0 = btf_eval(s.uv, wo, canonical(s, vec3<f32>(dir * k0, c0)), depth, false);
    let det = c1 * k0 - c0 * k1;
    if (abs(det) < 1e-12) {
        return zero;
    }
    let along = (e1 * k0 - e0 * k1) / det;
    let across = (e0 * c1 - e1 * c0) / det;
    return max(along * sin_e + across * cos_e, zero) * lit;
}

// Radiance under an environment light (environment.rs's EnvShading::shade): the lighting of
// the hit's triangle corners, barycentric, dotted per function with the BTF's transfer read
// at the texels and views btf_eval_sampled reads.
fn env_shade(h: Hit) -> vec3<f32> {
    let n = P.env.x;
    let bv = lookup(0u, P.dirs.x, P.rings_at.x, h.wo);
    var total = 0.0;
    for (var a = 0u; a < bv.count; a = a + 1u) {
        total = total + bv.w[a];
    }
    if (total <= 0.0) {
        return vec3<f32>(0.0);
    }
    // Where each (view, tap) pair's functions start in `envd`, and its weight.
    var at_f = array<u32, 16>();
    var at_w = array<f32, 16>();
    var m = 0u;
    for (var a = 0u; a < bv.count; a = a + 1u) {
        let vi = bv.idx[a];
        var at = h.s.uv;
        if (h.depth.x > 0.0 || h.depth.y > 0.0) {
            let vk = vec3<f32>(dirs[3u * vi], dirs[3u * vi + 1u], dirs[3u * vi + 2u]);
            let k = h.wo.z / max(vk.z, 1e-3);
            at = h.s.uv + h.depth * (vk.xy * k - h.wo.xy);
        }
        let tp = taps(at, P.mat.y, P.mat.z);
        for (var k = 0u; k < 4u; k = k + 1u) {
            let tw = tap_weight(tp, k);
            if (tw == 0.0) {
                continue;
            }
            let tx = (vi * P.mat.z + tp.y[k >> 1u]) * P.mat.y + tp.x[k & 1u];
            at_f[m] = P.env.y + 3u * n * tx;
            at_w[m] = bv.w[a] * tw / total;
            m = m + 1u;
        }
    }
    let tri = h.s.tri;
    let c0 = 3u * n * tables[3u * tri];
    let c1 = 3u * n * tables[3u * tri + 1u];
    let c2 = 3u * n * tables[3u * tri + 2u];
    var out = vec3<f32>(0.0);
    for (var f = 0u; f < n; f = f + 1u) {
        let l = vec3<f32>(envd[c0 + 3u * f], envd[c0 + 3u * f + 1u], envd[c0 + 3u * f + 2u]) * h.s.bary.x
            + vec3<f32>(envd[c1 + 3u * f], envd[c1 + 3u * f + 1u], envd[c1 + 3u * f + 2u]) * h.s.bary.y
            + vec3<f32>(envd[c2 + 3u * f], envd[c2 + 3u * f + 1u], envd[c2 + 3u * f + 2u]) * h.s.bary.z;
        var t = vec3<f32>(0.0);
        for (var i = 0u; i < m; i = i + 1u) {
            let b = at_f[i] + 3u * f;
            t = t + vec3<f32>(envd[b], envd[b + 1u], envd[b + 2u]) * at_w[i];
        }
        out = out + t * l;
    }
    return max(out, vec3<f32>(0.0));
}

fn lit(p: vec3<f32>, cos_light: f32) -> bool {
    let c = P.scam;
    let rel = p - c.eye.xyz;
    let z = dot(rel, c.fwd.xyz);
    var sx = dot(rel, c.right.xyz) / c.fwd.w;
    var sy = dot(rel, c.up.xyz) / c.fwd.w;
    var t = z;
    if (c.eye.w < 0.5) {
        if (z <= 0.0) {
            return true;
        }
        sx = sx / z;
        sy = sy / z;
        t = length(rel);
    }
    let px = (sx / c.right.w + 1.0) * 0.5 * c.size.x;
    let py = (1.0 - sy) * 0.5 * c.size.y;
    if (px < 0.0 || px >= c.size.x || py < 0.0 || py >= c.size.y) {
        return true;
    }
    // The shadow pass wrote one vec4 per texel, depth in x.
    let depth = shadow[4u * (u32(py) * u32(c.size.x) + u32(px))];
    return t <= depth + P.misc.z / max(cos_light, 0.1);
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) g: vec3<u32>) {
    let w = u32(P.cam.size.x);
    let h = u32(P.cam.size.y);
    if (g.x >= w || g.y >= h) {
        return;
    }
    let ray = cam_ray(P.cam, g.x, g.y);
    let hit = find_hit(g.x, g.y, ray.o, ray.d);
    let px = g.y * w + g.x;
    if (P.offs.y == 0u) {
        out[px] = vec4<f32>(select(inf(), hit.t, hit.found), 0.0, 0.0, 0.0);
        return;
    }
    if (!hit.found) {
        out[px] = vec4<f32>(P.background.xyz, 0.0);
        return;
    }
    if (P.env.x > 0u) {
        out[px] = vec4<f32>(env_shade(hit), 1.0);
        return;
    }
    // Shadows and point lights are evaluated at the receiver's reference surface (see shade.rs).
    let p = ray.o + ray.d * hit.t_front;
    var to_light = P.light.xyz;
    var falloff = 1.0;
    if (P.light_pos.w > 0.5) {
        let v = P.light_pos.xyz - p;
        falloff = 1.0 / max(dot(v, v), 1e-12);
        to_light = normalize(v);
    }
    let wi = local(hit.s, to_light);
    if (wi.z <= 0.0) {
        // Below the macro horizon: what the curved mesostructure still catches.
        let below = (hit.t - hit.t_front) * dot(-ray.d, hit.s.n);
        let e = past_horizon(hit.s, hit.wo, hit.depth, to_light, wi, below);
        out[px] = vec4<f32>(e * (P.light.w * falloff), 1.0);
        return;
    }
    if (P.offs.z == 1u && !lit(p, wi.z)) {
        out[px] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        return;
    }
    let c = btf_eval(hit.s.uv, hit.wo, canonical(hit.s, wi), hit.depth, true) * (P.light.w * falloff);
    out[px] = vec4<f32>(c, 1.0);
}
