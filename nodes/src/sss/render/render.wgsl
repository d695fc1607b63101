// sss.render, the gather on the GPU: for every shading point (the pixels that see the object,
// packed into rows by the host), the sum over all
// irradiance samples farther than `near` of Rd(distance)·(E·ΔA), brute force, with the samples
// streamed through workgroup memory 64 at a time. Rd is looked up exactly as the CPU path does:
// a log-uniform radius table, linear in ln r, the first value inside it, 0 beyond it.

struct Params {
    width: u32, height: u32, points: u32, table: u32,
    shade_offset: u32, point_offset: u32, accumulate: u32, _pad1: u32,
    ln_r0: f32, inv_h: f32, near2: f32, _pad2: f32,
}

@group(0) @binding(0) var<uniform> P: Params;
// Rd table (3 × table, channel-major), then per pixel (x, y, z, valid), then per sample
// (x, y, z, 0, power r, g, b, 0); positions in mm.
@group(0) @binding(1) var<storage, read> input: array<f32>;
@group(0) @binding(2) var<storage, read_write> output: array<f32>;

const TILE: u32 = 64u;
var<workgroup> tile: array<vec4<f32>, 128>;

fn rd(c: u32, r: f32) -> f32 {
    let f = (log(max(r, 1e-30)) - P.ln_r0) * P.inv_h;
    if (f <= 0.0) {
        return input[c * P.table];
    }
    let i = u32(floor(f));
    if (i + 1u >= P.table) {
        return 0.0;
    }
    let t = f - f32(i);
    return input[c * P.table + i] * (1.0 - t) + input[c * P.table + i + 1u] * t;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let inside = id.x < P.width && id.y < P.height;
    let px = min(id.y, P.height - 1u) * P.width + min(id.x, P.width - 1u);
    let s = P.shade_offset + 4u * px;
    let x = vec3<f32>(input[s], input[s + 1u], input[s + 2u]);
    let valid = inside && input[s + 3u] > 0.5;
    var sum = vec3<f32>(0.0);
    // Every invocation takes part in the loads and barriers, valid or not.
    for (var base = 0u; base < P.points; base += TILE) {
        let k = base + li;
        if (k < P.points) {
            let q = P.point_offset + 8u * k;
            tile[2u * li] = vec4<f32>(input[q], input[q + 1u], input[q + 2u], 0.0);
            tile[2u * li + 1u] = vec4<f32>(input[q + 4u], input[q + 5u], input[q + 6u], 0.0);
        }
        workgroupBarrier();
        let count = min(TILE, P.points - base);
        if (valid) {
            for (var j = 0u; j < count; j++) {
                let d = tile[2u * j].xyz - x;
                let d2 = dot(d, d);
                if (d2 >= P.near2) {
                    let r = sqrt(d2);
                    let e = tile[2u * j + 1u].xyz;
                    sum += vec3<f32>(rd(0u, r) * e.x, rd(1u, r) * e.y, rd(2u, r) * e.z);
                }
            }
        }
        workgroupBarrier();
    }
    if (inside) {
        // A later dispatch of the same pixels adds its samples' share to the earlier ones'.
        if (P.accumulate == 1u) {
            sum += vec3<f32>(output[4u * px], output[4u * px + 1u], output[4u * px + 2u]);
        }
        output[4u * px] = sum.x;
        output[4u * px + 1u] = sum.y;
        output[4u * px + 2u] = sum.z;
        output[4u * px + 3u] = 0.0;
    }
}
