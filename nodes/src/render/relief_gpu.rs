//! The GPU path of `render.relief` (wgpu): one render pass whose fragment stage does the relief
//! search and shading (`relief.wgsl`), into a float target read back as the image and mask.

use super::gpu_render::{cam_block, raster_pass, raster_pipeline};
use super::relief_scene::Relief;
use crate::support::geometry::bounding_sphere;
use crate::support::gpu::read_back;
use crate::support::raytrace::camera::Camera;
use mesoflow_runtime::{Gpu, NodeError};
use wgpu::util::DeviceExt;

/// The relief shader: the shared rasteriser, then the relief march.
pub(crate) const RELIEF_WGSL: &str =
    concat!(include_str!("raster.wgsl"), include_str!("relief.wgsl"));

fn gpu_err(what: &'static str) -> impl Fn(String) -> NodeError {
    move |e| NodeError::Gpu(format!("render.relief: {what}: {e}"))
}

/// Renders `frames` frames (the last one read back): RGB, mask, and the mean GPU time per frame
/// where the adapter has timestamp queries.
#[allow(clippy::type_complexity)]
pub fn render(
    gpu: &Gpu,
    scene: &Relief,
    cam: &Camera,
    frames: u32,
) -> Result<(Vec<f32>, Vec<f32>, Option<f64>), NodeError> {
    let device = &gpu.device;
    let m = scene.mesh;
    let (w, h) = (cam.width, cam.height);
    let max = device.limits().max_texture_dimension_2d;
    if w > max || h > max {
        return Err(NodeError::param(
            "camera",
            format!(
                "{w}×{h} exceeds this adapter's largest texture, {max} pixels per side ({})",
                gpu.describe()
            ),
        ));
    }
    let mut mesh_f: Vec<f32> = m.positions.iter().flatten().copied().collect();
    mesh_f.extend(m.normals.iter().flatten());
    mesh_f.extend(m.uvs.iter().flatten());
    mesh_f.extend(m.tangents.iter().flatten());
    if scene.aspect.len() == m.positions.len() {
        mesh_f.extend(scene.aspect.iter().flatten());
    } else {
        mesh_f.extend(std::iter::repeat_n(1.0f32, 2 * m.positions.len()));
    }
    let mut tex: Vec<f32> = scene.heights.clone();
    tex.extend(scene.grad.iter().flatten());
    tex.extend(scene.maps.iter().flatten());
    let limit = device.limits().max_storage_buffer_binding_size;
    for (what, bytes) in [("the mesh", mesh_f.len() * 4), ("the tile", tex.len() * 4)] {
        if bytes as u64 > limit {
            return Err(NodeError::Gpu(format!("render.relief: {what} needs {bytes} bytes, over this adapter's storage binding limit of {limit}; use --device cpu")));
        }
    }
    let (centre, radius) = bounding_sphere(m);
    let mut u = cam_block(cam, centre, radius);
    let light = &scene.light;
    let (lv, point) = match light.position {
        Some(q) => (q, 1.0),
        None => (light.direction, 0.0),
    };
    u.extend([
        scene.width as f32,
        scene.height as f32,
        scene.top,
        scene.depth,
    ]);
    u.extend([
        scene.tiling[0] as f32,
        scene.tiling[1] as f32,
        scene.linear_steps as f32,
        scene.binary_steps as f32,
    ]);
    u.extend([lv[0] as f32, lv[1] as f32, lv[2] as f32, point]);
    u.extend([
        light.intensity as f32,
        if scene.shadows { 1.0 } else { 0.0 },
        if scene.aspect.is_empty() { 0.0 } else { 1.0 },
        0.0,
    ]);
    let buffer = |label: &str, bytes: &[u8], usage: wgpu::BufferUsages| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage,
        })
    };
    let ubuf = buffer(
        "relief params",
        bytemuck::cast_slice(&u),
        wgpu::BufferUsages::UNIFORM,
    );
    let mesh_buf = buffer(
        "relief mesh",
        bytemuck::cast_slice(&mesh_f),
        wgpu::BufferUsages::STORAGE,
    );
    let index_buf = buffer(
        "relief indices",
        bytemuck::cast_slice(&m.indices),
        wgpu::BufferUsages::STORAGE,
    );
    let tex_buf = buffer(
        "relief tile",
        bytemuck::cast_slice(&tex),
        wgpu::BufferUsages::STORAGE,
    );
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("relief"),
        source: wgpu::ShaderSource::Wgsl(RELIEF_WGSL.into()),
    });
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let pipeline = raster_pipeline(device, &module, "relief", wgpu::Face::Back);
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(NodeError::Gpu(format!("render.relief: {} cannot build the relief pass (32-bit float render targets): {e}; use --device cpu", gpu.describe())));
    }
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("relief"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: ubuf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: mesh_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: index_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: tex_buf.as_entire_binding(),
            },
        ],
    });
    let texture = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let target = texture(
        "relief image",
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    let depth = texture(
        "relief depth",
        wgpu::TextureFormat::Depth32Float,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    let (view, depth_view) = (
        target.create_view(&Default::default()),
        depth.create_view(&Default::default()),
    );
    let stamps = device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY)
        .then(|| {
            device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("relief time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            })
        });
    let row_bytes = (16 * w).div_ceil(256) * 256;
    let readback = |label: &str, size: u64| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let mut gpu_ms_total = 0.0;
    let mut bytes = Vec::new();
    let bg = scene.background;
    for frame in 0..frames {
        let last = frame + 1 == frames;
        let mut enc = device.create_command_encoder(&Default::default());
        {
            let stamp = stamps
                .as_ref()
                .map(|query_set| wgpu::RenderPassTimestampWrites {
                    query_set,
                    beginning_of_pass_write_index: Some(0),
                    end_of_pass_write_index: Some(1),
                });
            let mut pass = raster_pass(
                &mut enc,
                "relief",
                &view,
                &depth_view,
                [bg[0], bg[1], bg[2], 0.0],
                stamp,
            );
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.draw(0..3 * m.triangles() as u32, 0..1);
        }
        let image = last.then(|| {
            let staging = readback("relief readback", row_bytes as u64 * h as u64);
            enc.copy_texture_to_buffer(
                target.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &staging,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row_bytes),
                        rows_per_image: Some(h),
                    },
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
            staging
        });
        let times = stamps.as_ref().map(|qs| {
            let resolved = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            enc.resolve_query_set(qs, 0..2, &resolved, 0);
            let staging = readback("timestamps readback", 16);
            enc.copy_buffer_to_buffer(&resolved, 0, &staging, 0, 16);
            staging
        });
        gpu.queue.submit([enc.finish()]);
        if let Some(t) = &times {
            let b = read(gpu, t)?;
            let ticks: &[u64] = bytemuck::cast_slice(&b);
            gpu_ms_total += ticks[1].saturating_sub(ticks[0]) as f64
                * gpu.queue.get_timestamp_period() as f64
                * 1e-6;
        } else {
            device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| gpu_err("wait")(e.to_string()))?;
        }
        if let Some(b) = &image {
            bytes = read(gpu, b)?;
        }
    }
    let (mut rgb, mut mask) = (
        Vec::with_capacity(3 * (w * h) as usize),
        Vec::with_capacity((w * h) as usize),
    );
    for y in 0..h as usize {
        let row: &[f32] = bytemuck::cast_slice(
            &bytes[y * row_bytes as usize..y * row_bytes as usize + 16 * w as usize],
        );
        for px in row.chunks_exact(4) {
            rgb.extend_from_slice(&px[..3]);
            mask.push(px[3]);
        }
    }
    Ok((
        rgb,
        mask,
        stamps.is_some().then(|| gpu_ms_total / frames as f64),
    ))
}

fn read(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<u8>, NodeError> {
    read_back(gpu, buffer).map_err(gpu_err("readback"))
}
