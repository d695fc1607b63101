// What the rasterising passes share (prepended to peel.wgsl and relief.wgsl): the camera block
// and the projection of a world point to clip space, the inverse of Camera::ray.

struct Cam {
    eye: vec4<f32>,    // xyz, w = 1 for orthographic
    fwd: vec4<f32>,    // xyz, w = tan(fov/2) or half height
    right: vec4<f32>,  // xyz, w = aspect
    up: vec4<f32>,
    size: vec4<f32>,   // width, height, near, far
};

fn clip_of(cam: Cam, p: vec3<f32>) -> vec4<f32> {
    let rel = p - cam.eye.xyz;
    let z = dot(rel, cam.fwd.xyz);
    let half = cam.fwd.w;
    let sx = dot(rel, cam.right.xyz) / (half * cam.right.w);
    let sy = dot(rel, cam.up.xyz) / half;
    let near = cam.size.z;
    let far = cam.size.w;
    if (cam.eye.w > 0.5) {
        return vec4<f32>(sx, sy, (z - near) / (far - near), 1.0);
    }
    return vec4<f32>(sx, sy, far * (z - near) / (far - near), z);
}

// The barycentric weights a corner carries, so the rasteriser interpolates them.
fn corner_bary(vi: u32) -> vec3<f32> {
    let corner = vi % 3u;
    return vec3<f32>(select(0.0, 1.0, corner == 0u), select(0.0, 1.0, corner == 1u), select(0.0, 1.0, corner == 2u));
}
