// Depth peeling of a mesh into visibility layers (see layers.rs for the CPU twin). One pass
// draws only front faces or only back faces; a fragment survives if it lies beyond the previous
// layer's sample at its pixel, and the depth test keeps the nearest survivor. The target holds
// (t, b1, b2, triangle) with t the distance along the pixel's ray, -1 where empty.

struct Cam {
    eye: vec4<f32>,    // xyz, w = 1 for orthographic
    fwd: vec4<f32>,    // xyz, w = tan(fov/2) or half height
    right: vec4<f32>,  // xyz, w = aspect
    up: vec4<f32>,
    size: vec4<f32>,   // width, height, near, far
};

struct Peel {
    cam: Cam,
    flags: vec4<f32>,  // x = 1 for the first pass (nothing to peel against)
};

@group(0) @binding(0) var<uniform> U: Peel;
@group(0) @binding(1) var<storage, read> positions: array<f32>;
@group(0) @binding(2) var<storage, read> indices: array<u32>;
@group(0) @binding(3) var previous: texture_2d<f32>;

struct VOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) bary: vec3<f32>,
    @location(2) @interpolate(flat) tri: u32,
};

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> VOut {
    let v = indices[vi];
    let p = vec3<f32>(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
    let rel = p - U.cam.eye.xyz;
    let z = dot(rel, U.cam.fwd.xyz);
    let half = U.cam.fwd.w;
    let sx = dot(rel, U.cam.right.xyz) / (half * U.cam.right.w);
    let sy = dot(rel, U.cam.up.xyz) / half;
    let near = U.cam.size.z;
    let far = U.cam.size.w;
    var out: VOut;
    if (U.cam.eye.w > 0.5) {
        out.clip = vec4<f32>(sx, sy, (z - near) / (far - near), 1.0);
    } else {
        out.clip = vec4<f32>(sx, sy, far * (z - near) / (far - near), z);
    }
    out.world = p;
    let corner = vi % 3u;
    out.bary = vec3<f32>(select(0.0, 1.0, corner == 0u), select(0.0, 1.0, corner == 1u), select(0.0, 1.0, corner == 2u));
    out.tri = vi / 3u;
    return out;
}

@fragment
fn fs(in: VOut) -> @location(0) vec4<f32> {
    let rel = in.world - U.cam.eye.xyz;
    var t = length(rel);
    if (U.cam.eye.w > 0.5) {
        t = dot(rel, U.cam.fwd.xyz);
    }
    if (U.flags.x < 0.5) {
        let prev = textureLoad(previous, vec2<i32>(in.clip.xy), 0).x;
        if (prev < 0.0 || !(t > prev + 1e-5 * max(abs(prev), 1.0))) {
            discard;
        }
    }
    return vec4<f32>(t, in.bary.y, in.bary.z, f32(in.tri));
}
