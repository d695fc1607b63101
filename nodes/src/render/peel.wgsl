// Depth peeling of a mesh into visibility layers (see layers.rs for the CPU twin). One pass
// draws only front faces or only back faces; a fragment survives if it lies beyond the previous
// layer's sample at its pixel, and the depth test keeps the nearest survivor. The target holds
// (t, b1, b2, triangle) with t the distance along the pixel's ray, -1 where empty.
// The camera block and projection come from raster.wgsl, prepended.

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
    var out: VOut;
    out.clip = clip_of(U.cam, p);
    out.world = p;
    out.bary = corner_bary(vi);
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
