// Normal map of a periodic height field by central differences; see normals.rs for the frame.
struct Params {
    width: u32,
    height: u32,
    scale: f32,
    _pad: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> heights: array<f32>;
@group(0) @binding(2) var<storage, read_write> normals: array<f32>;

// Periodic lookup for offsets of at most one tile. Comparisons rather than a signed `%`:
// naga's OpenGL output of `%` on a negative operand gave wrong texels at the tile's edges.
fn wrap(v: i32, n: i32) -> u32 {
    return u32(select(select(v, v - n, v >= n), v + n, v < 0));
}

fn h(x: i32, y: i32) -> f32 {
    let xi = wrap(x, i32(params.width));
    let yi = wrap(y, i32(params.height));
    return heights[yi * params.width + xi];
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.width || id.y >= params.height) {
        return;
    }
    let x = i32(id.x);
    let y = i32(id.y);
    let dx = (h(x + 1, y) - h(x - 1, y)) * 0.5 * params.scale;
    let dy = (h(x, y - 1) - h(x, y + 1)) * 0.5 * params.scale;
    let inv = 1.0 / sqrt(dx * dx + dy * dy + 1.0);
    let i = (id.y * params.width + id.x) * 3u;
    normals[i] = -dx * inv;
    normals[i + 1u] = -dy * inv;
    normals[i + 2u] = inv;
}
