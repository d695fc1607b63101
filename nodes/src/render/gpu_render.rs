//! The GPU path of `render.mesh` (wgpu): depth-peeling render passes rasterise the visibility
//! layers (`peel.wgsl`), a compute pass resolves them with the shell test and shades
//! (`resolve.wgsl`). Shadows run the same two steps from the light first, into a depth buffer
//! that stays on the GPU. Data layout and rules are those of the CPU path.

use super::material::{Material, Source};
use super::shade::Scene;
use crate::support::geometry::{bounding_sphere, dot, sub};
use crate::support::gpu::read_back;
use crate::support::raytrace::camera::Camera;
use crate::types::{Centring, ColorSpace};
use mesoflow_runtime::{Gpu, NodeError};
use wgpu::util::DeviceExt;

/// The depth-peeling shader: the shared rasteriser, then the peel.
pub(crate) const PEEL_WGSL: &str = concat!(include_str!("raster.wgsl"), include_str!("peel.wgsl"));
/// The resolve shader: the shared ray–triangle test, then the shell test and shading.
pub(crate) const RESOLVE_WGSL: &str = concat!(
    include_str!("../support/raytrace/triangle.wgsl"),
    include_str!("resolve.wgsl")
);

const NONE: u32 = u32::MAX;

fn gpu_err(what: &str) -> impl Fn(String) -> NodeError + '_ {
    move |e| NodeError::Gpu(format!("render.mesh: {what}: {e}"))
}

/// A rasterising pass over the mesh's triangles (vertices pulled from storage buffers by
/// `vs`), culling `cull` faces, nearest fragment by a 32-bit depth test, `fs` writing one
/// Rgba32Float target: the depth-peeling passes and the relief pass.
pub(crate) fn raster_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    label: &str,
    cull: wgpu::Face,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: None,
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: Some(cull),
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: wgpu::TextureFormat::Depth32Float,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::TextureFormat::Rgba32Float.into())],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A render pass into one colour target cleared to `clear` and a depth target cleared to 1
/// (both stored), writing `stamps` where the adapter has timestamp queries.
pub(crate) fn raster_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    view: &wgpu::TextureView,
    depth_view: &wgpu::TextureView,
    clear: [f64; 4],
    stamps: Option<wgpu::RenderPassTimestampWrites>,
) -> wgpu::RenderPass<'e> {
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color {
                    r: clear[0],
                    g: clear[1],
                    b: clear[2],
                    a: clear[3],
                }),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth_view,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: stamps,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// Camera as the shaders' `Cam`: eye (w = ortho), fwd (w = half), right (w = aspect), up,
/// size (width, height, near, far).
pub(crate) fn cam_block(c: &Camera, centre: [f64; 3], radius: f64) -> Vec<f32> {
    let zc = dot(sub(centre, c.eye), c.forward);
    let (near, far) = if c.orthographic {
        (zc - 1.01 * radius, zc + 1.01 * radius)
    } else {
        (
            (zc - 1.01 * radius).max(1e-3 * radius),
            (zc + 1.01 * radius).max(2e-3 * radius),
        )
    };
    let aspect = c.width as f64 / c.height as f64;
    let v = |a: [f64; 3], w: f64| [a[0] as f32, a[1] as f32, a[2] as f32, w as f32];
    [
        v(c.eye, if c.orthographic { 1.0 } else { 0.0 }),
        v(c.forward, c.half),
        v(c.right, aspect),
        v(c.up, 0.0),
        [c.width as f32, c.height as f32, near as f32, far as f32],
    ]
    .concat()
}

/// One frame's stages on the GPU, ms, from timestamp queries: the shadow map (its peel passes
/// and resolve, with shadows on), the view's peel passes (its visibility layers), the shading
/// resolve, and the whole frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuStages {
    pub total_ms: f64,
    pub shadow_ms: Option<f64>,
    pub layers_ms: f64,
    pub shade_ms: f64,
}

pub struct GpuRenderer<'a> {
    gpu: &'a Gpu,
    scene: &'a Scene<'a>,
    positions: wgpu::Buffer,
    indices: wgpu::Buffer,
    mesh: wgpu::Buffer,
    tables: wgpu::Buffer,
    material: wgpu::Buffer,
    dirs: wgpu::Buffer,
    mdf: wgpu::Buffer,
    /// Under an environment light: the mesh's lighting, then the BTF's transfer (one float
    /// each, `environment.rs`'s layouts); one float otherwise.
    env: wgpu::Buffer,
    /// The functions per colour (0: no environment) and where the transfer starts in `env`.
    env_info: [u32; 2],
    peel_front: wgpu::RenderPipeline,
    peel_back: wgpu::RenderPipeline,
    resolve: wgpu::ComputePipeline,
    /// Offsets into `tables` and `dirs` (owners, blocks, pair_of; lights, mdf views).
    offsets: [u32; 5],
    /// Where the views', lights' and MDF views' ring tables start in `dirs` (NONE: none).
    ring_offsets: [u32; 3],
    /// Where the side walls start in `mesh`, and how many.
    sides_at: [u32; 2],
    triangles: u32,
    centre: [f64; 3],
    radius: f64,
    /// Four timestamps where the device has them: the shadow map's first pass begins (0), the
    /// view's first peel pass begins (1), its last ends (2), the shading resolve ends (3).
    stamps: Option<wgpu::QuerySet>,
}

impl<'a> GpuRenderer<'a> {
    pub fn new(gpu: &'a Gpu, scene: &'a Scene<'a>) -> Result<Self, NodeError> {
        let device = &gpu.device;
        let m = scene.mesh;
        // Degenerate triangles rasterise to nothing on the GPU; the CPU caster skips them too.
        let positions: Vec<f32> = m.positions.iter().flatten().copied().collect();
        let mut mesh_f: Vec<f32> = positions.clone();
        mesh_f.extend(m.normals.iter().flatten());
        mesh_f.extend(m.uvs.iter().flatten());
        mesh_f.extend(m.tangents.iter().flatten());
        // The texel aspect per vertex (1, 1 where the scene has none).
        if scene.aspect.len() == m.positions.len() {
            mesh_f.extend(scene.aspect.iter().flatten());
        } else {
            mesh_f.extend(std::iter::repeat_n(1.0f32, 2 * m.positions.len()));
        }
        // The shell's side walls at the open boundary (shade.rs), four corners each.
        let sides_at = [mesh_f.len() as u32, scene.sides.len() as u32];
        // Per wall: its four corners, then its triangle and the corner slots of its edge.
        for side in &scene.sides {
            mesh_f.extend(side.q.iter().flatten().map(|v| *v as f32));
            mesh_f.extend([side.tri as f32, side.ends[0] as f32, side.ends[1] as f32]);
        }
        let mat = scene.material;
        let mut tables: Vec<u32> = m.indices.clone();
        let pair_of_off = tables.len() as u32;
        tables.extend(mat.pair_of.iter().map(|p| p.map_or(NONE, |v| v as u32)));
        let owners_off = tables.len() as u32;
        let (material, blocks_off) = material_arrays(mat, &mut tables);
        let mut dirs: Vec<f32> = mat.views.iter().flatten().map(|v| *v as f32).collect();
        let lights_off = dirs.len() as u32;
        dirs.extend(mat.lights.iter().flatten().map(|v| *v as f32));
        let mdf_dirs_off = dirs.len() as u32;
        let mut mdf_data = vec![0f32];
        if let Some(l) = &scene.mdf {
            dirs.extend(l.views.iter().flatten().map(|v| *v as f32));
            mdf_data = l.mdf.data.clone();
        }
        // The ring tables of the bilinear direction lookup (rings.rs), after the directions.
        let mut table = |r: Option<&super::rings::Rings>| match r {
            Some(r) => {
                let at = dirs.len() as u32;
                dirs.extend(r.encode());
                at
            }
            None => NONE,
        };
        let ring_offsets = [
            table(mat.view_table.as_ref()),
            table(mat.light_table.as_ref()),
            table(scene.mdf.as_ref().and_then(|l| l.rings.as_ref())),
        ];
        let (env_data, env_info) = match &scene.env {
            Some(e) => {
                let mut data: Vec<f32> = e.lighting().iter().flatten().copied().collect();
                let at = data.len() as u32;
                data.extend(e.transfer().iter().flatten());
                (data, [e.functions() as u32, at])
            }
            None => (vec![0f32], [0, 0]),
        };
        let limit = device.limits().max_storage_buffer_binding_size;
        for (what, bytes) in [
            (
                "the environment's transfer and lighting",
                env_data.len() * 4,
            ),
            ("the material", material.len() * 4),
            ("the MDF", mdf_data.len() * 4),
            ("the mesh", mesh_f.len() * 4),
            ("the mesh's tables", tables.len() * 4),
        ] {
            if bytes as u64 > limit {
                return Err(NodeError::Gpu(format!(
                    "render.mesh: {what} needs {bytes} bytes, over this adapter's storage binding limit of {limit}; use --device cpu or a PCA basis"
                )));
            }
        }
        let storage = |label: &str, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: if bytes.is_empty() { &[0u8; 4] } else { bytes },
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let peel = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("peel"),
            source: wgpu::ShaderSource::Wgsl(PEEL_WGSL.into()),
        });
        let peel_pipeline = |cull| raster_pipeline(device, &peel, "peel", cull);
        // OpenGL ES adapters may lack float render targets: a validation error, caught and
        // turned into a message rather than a panic in wgpu's default handler.
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let peel_front = peel_pipeline(wgpu::Face::Back);
        let peel_back = peel_pipeline(wgpu::Face::Front);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(NodeError::Gpu(format!(
                "render.mesh: {} cannot render the visibility layers (32-bit float render targets): {e}; use --device cpu",
                gpu.describe()
            )));
        }
        let resolve_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("resolve"),
            source: wgpu::ShaderSource::Wgsl(RESOLVE_WGSL.into()),
        });
        let resolve = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("resolve"),
            layout: None,
            module: &resolve_module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let (centre, radius) = bounding_sphere(m);
        let stamps = device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| {
                device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("frame stages"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 4,
                })
            });
        Ok(GpuRenderer {
            gpu,
            scene,
            positions: storage("positions", bytemuck::cast_slice(&positions)),
            indices: storage("indices", bytemuck::cast_slice(&m.indices)),
            mesh: storage("mesh", bytemuck::cast_slice(&mesh_f)),
            tables: storage("tables", bytemuck::cast_slice(&tables)),
            material: storage("material", bytemuck::cast_slice(&material)),
            dirs: storage("dirs", bytemuck::cast_slice(&dirs)),
            mdf: storage("mdf", bytemuck::cast_slice(&mdf_data)),
            env: storage("environment", bytemuck::cast_slice(&env_data)),
            env_info,
            peel_front,
            peel_back,
            resolve,
            offsets: [
                owners_off,
                blocks_off,
                pair_of_off,
                lights_off,
                mdf_dirs_off,
            ],
            ring_offsets,
            sides_at,
            triangles: m.triangles() as u32,
            centre,
            radius,
            stamps,
        })
    }

    /// Checks an image or shadow-map size against the device.
    pub fn check_size(gpu: &Gpu, what: &str, w: u32, h: u32) -> Result<(), NodeError> {
        let max = gpu.device.limits().max_texture_dimension_2d;
        if w > max || h > max {
            return Err(NodeError::param(
                what,
                format!(
                    "{w}×{h} exceeds this adapter's largest texture, {max} pixels per side ({})",
                    gpu.describe()
                ),
            ));
        }
        Ok(())
    }

    fn texture(
        &self,
        label: &str,
        w: u32,
        h: u32,
        layers: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> wgpu::Texture {
        self.gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: layers,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    }

    /// Encodes the peeling passes for `cam`; returns the layer array (2·count layers). The
    /// first pass writes timestamp `begin` at its start and the last `end` at its end, where
    /// given and the device has timestamps.
    fn encode_layers(
        &self,
        enc: &mut wgpu::CommandEncoder,
        cam: &Camera,
        count: u32,
        begin: Option<u32>,
        end: Option<u32>,
    ) -> wgpu::Texture {
        let device = &self.gpu.device;
        let (w, h) = (cam.width, cam.height);
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC;
        let targets: Vec<wgpu::Texture> = (0..2 * count)
            .map(|_| self.texture("layer", w, h, 1, wgpu::TextureFormat::Rgba32Float, usage))
            .collect();
        let dummy = self.texture(
            "none",
            1,
            1,
            1,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let depth = self.texture(
            "depth",
            w,
            h,
            1,
            wgpu::TextureFormat::Depth32Float,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let depth_view = depth.create_view(&Default::default());
        let cam_f = cam_block(cam, self.centre, self.radius);
        for (i, target) in targets.iter().enumerate() {
            let first = i == 0;
            let mut u = cam_f.clone();
            u.extend([if first { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0]);
            let ubuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("peel params"),
                contents: bytemuck::cast_slice(&u),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            let prev_view = if first {
                dummy.create_view(&Default::default())
            } else {
                targets[i - 1].create_view(&Default::default())
            };
            let pipeline = if i % 2 == 0 {
                &self.peel_front
            } else {
                &self.peel_back
            };
            let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("peel"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: ubuf.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: self.positions.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: self.indices.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&prev_view),
                    },
                ],
            });
            let view = target.create_view(&Default::default());
            let (b, e) = (
                begin.filter(|_| i == 0),
                end.filter(|_| i + 1 == targets.len()),
            );
            let stamp = self
                .stamps
                .as_ref()
                .filter(|_| b.is_some() || e.is_some())
                .map(|query_set| wgpu::RenderPassTimestampWrites {
                    query_set,
                    beginning_of_pass_write_index: b,
                    end_of_pass_write_index: e,
                });
            let mut pass = raster_pass(
                enc,
                "peel",
                &view,
                &depth_view,
                [-1.0, 0.0, 0.0, 0.0],
                stamp,
            );
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.draw(0..3 * self.triangles, 0..1);
        }
        let array = self.texture(
            "layers",
            w,
            h,
            2 * count,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        for (i, t) in targets.iter().enumerate() {
            enc.copy_texture_to_texture(
                t.as_image_copy(),
                wgpu::TexelCopyTextureInfo {
                    texture: &array,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: i as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
        }
        array
    }

    /// Encodes the resolve; returns its output buffer (vec4 per pixel).
    #[allow(clippy::too_many_arguments)]
    fn encode_resolve(
        &self,
        enc: &mut wgpu::CommandEncoder,
        cam: &Camera,
        shadow_cam: Option<&Camera>,
        layers: &wgpu::Texture,
        count: u32,
        shade: bool,
        shadow: Option<(&wgpu::Buffer, f64)>,
    ) -> wgpu::Buffer {
        let device = &self.gpu.device;
        let s = self.scene;
        let mat = s.material;
        let mut u: Vec<f32> = cam_block(cam, self.centre, self.radius);
        u.extend(match shadow_cam {
            Some(c) => cam_block(c, self.centre, self.radius),
            None => vec![0.0; 20],
        });
        let l = &s.light;
        u.extend([l.direction[0], l.direction[1], l.direction[2], l.intensity].map(|v| v as f32));
        let lp = l.position.unwrap_or([0.0; 3]);
        u.extend(
            [
                lp[0],
                lp[1],
                lp[2],
                if l.position.is_some() { 1.0 } else { 0.0 },
            ]
            .map(|v| v as f32),
        );
        u.extend(
            [
                s.tiling[0],
                s.shell,
                shadow.map_or(0.0, |x| x.1),
                s.tiling[1],
            ]
            .map(|v| v as f32),
        );
        let parallax = if s.parallax { 1.0 } else { 0.0 };
        u.extend([s.background[0], s.background[1], s.background[2], parallax].map(|v| v as f32));
        u.extend(match &s.mdf {
            Some(m) => [
                m.mdf.width as f32,
                m.mdf.height as f32,
                m.mdf.depth as f32,
                1.0,
            ],
            None => [1.0, 1.0, 0.0, 0.0],
        });
        u.extend(match mat.light_rings {
            Some((c1, c0)) => [c1 as f32, c0 as f32, 0.0, 1.0],
            None => [1.0, 1.0, 0.0, 0.0],
        });
        let (kind, ycc) = match &mat.source {
            Source::Raw(_) => (0, 0),
            Source::Basis { basis, .. } => (1, (basis.color == ColorSpace::YCbCr) as u32),
        };
        let [owners_off, blocks_off, pair_of_off, lights_off, mdf_dirs_off] = self.offsets;
        let ints: [u32; 28] = [
            kind,
            mat.width as u32,
            mat.height as u32,
            ycc,
            mat.views.len() as u32,
            mat.lights.len() as u32,
            s.mdf.as_ref().map_or(0, |m| m.views.len() as u32),
            count,
            s.mesh.positions.len() as u32,
            shade as u32,
            shadow.is_some() as u32,
            owners_off,
            blocks_off,
            lights_off,
            mdf_dirs_off,
            pair_of_off,
            self.ring_offsets[0],
            self.ring_offsets[1],
            self.ring_offsets[2],
            0,
            self.sides_at[0],
            self.sides_at[1],
            0,
            0,
            self.env_info[0],
            self.env_info[1],
            0,
            0,
        ];
        let mut bytes: Vec<u8> = bytemuck::cast_slice(&u).to_vec();
        bytes.extend_from_slice(bytemuck::cast_slice(&ints));
        let ubuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("resolve params"),
            contents: &bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let pixels = (cam.width * cam.height) as u64;
        let out = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("resolve out"),
            size: pixels * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let none = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("no shadow"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let layers_view = layers.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let entries = [
            ubuf.as_entire_binding(),
            self.mesh.as_entire_binding(),
            self.tables.as_entire_binding(),
            self.material.as_entire_binding(),
            self.dirs.as_entire_binding(),
            self.mdf.as_entire_binding(),
            shadow.map_or(&none, |x| x.0).as_entire_binding(),
            out.as_entire_binding(),
            wgpu::BindingResource::TextureView(&layers_view),
            self.env.as_entire_binding(),
        ];
        let entries: Vec<wgpu::BindGroupEntry> = entries
            .into_iter()
            .enumerate()
            .map(|(i, resource)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource,
            })
            .collect();
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("resolve"),
            layout: &self.resolve.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("resolve"),
            timestamp_writes: self.stamps.as_ref().filter(|_| shade).map(|query_set| {
                wgpu::ComputePassTimestampWrites {
                    query_set,
                    beginning_of_pass_write_index: None,
                    end_of_pass_write_index: Some(3),
                }
            }),
        });
        pass.set_pipeline(&self.resolve);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(cam.width.div_ceil(8), cam.height.div_ceil(8), 1);
        drop(pass);
        out
    }

    /// One frame: (RGBA per pixel, a = 1 where mesostructure was hit; empty when `read` is
    /// false, for timing frames) and its stages' GPU times from timestamp queries, where the
    /// device has them.
    pub fn frame(
        &self,
        cam: &Camera,
        shadow_cam: Option<(&Camera, f64)>,
        count: u32,
        read: bool,
    ) -> Result<(Vec<f32>, Option<GpuStages>), NodeError> {
        let device = &self.gpu.device;
        let mut enc = device.create_command_encoder(&Default::default());
        let shadow_buf = shadow_cam.map(|(sc, bias)| {
            let layers = self.encode_layers(&mut enc, sc, count, Some(0), None);
            (
                self.encode_resolve(&mut enc, sc, None, &layers, count, false, None),
                bias,
            )
        });
        let layers = self.encode_layers(&mut enc, cam, count, Some(1), Some(2));
        let out = self.encode_resolve(
            &mut enc,
            cam,
            shadow_cam.map(|x| x.0),
            &layers,
            count,
            true,
            shadow_buf.as_ref().map(|(b, bias)| (b, *bias)),
        );
        let readback = |size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let image = read.then(|| {
            let staging = readback(out.size());
            enc.copy_buffer_to_buffer(&out, 0, &staging, 0, out.size());
            staging
        });
        let stamps = self.stamps.as_ref().map(|qs| {
            let resolved = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 32,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            // Without shadows timestamp 0 is never written: resolve only what was, to the
            // buffer's start (a resolve's offset must be aligned to 256 bytes).
            let from = if shadow_cam.is_some() { 0 } else { 1 };
            enc.resolve_query_set(qs, from..4, &resolved, 0);
            let staging = readback(32);
            enc.copy_buffer_to_buffer(&resolved, 0, &staging, 0, 32);
            staging
        });
        self.gpu.queue.submit([enc.finish()]);
        let data = match &image {
            Some(b) => bytemuck::cast_slice::<u8, f32>(&self.read_buffer(b)?).to_vec(),
            None => Vec::new(),
        };
        let gpu_ms = match &stamps {
            Some(b) => {
                let bytes = self.read_buffer(b)?;
                let got: &[u64] = bytemuck::cast_slice(&bytes);
                // Timestamps 0..4, the unwritten first one as 0 without shadows.
                let t: Vec<u64> = if shadow_cam.is_some() {
                    got[..4].to_vec()
                } else {
                    [0].into_iter().chain(got[..3].iter().copied()).collect()
                };
                let period = self.gpu.queue.get_timestamp_period() as f64 * 1e-6;
                let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * period;
                let shadow_ms = shadow_cam.map(|_| ms(t[0], t[1]));
                Some(GpuStages {
                    total_ms: shadow_ms.unwrap_or(0.0) + ms(t[1], t[3]),
                    shadow_ms,
                    layers_ms: ms(t[1], t[2]),
                    shade_ms: ms(t[2], t[3]),
                })
            }
            None => {
                device
                    .poll(wgpu::PollType::wait_indefinitely())
                    .map_err(|e| gpu_err("wait")(e.to_string()))?;
                None
            }
        };
        Ok((data, gpu_ms))
    }

    /// Maps a readback buffer after the queue finished and copies its bytes out.
    fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, NodeError> {
        read_back(self.gpu, buffer).map_err(|e| gpu_err("readback")(e))
    }
}

/// The material as one f32 array (raw planes, or every block's mean | maps | basis) and, for a
/// basis, the owner records (block, column) per global column and the block records
/// (mean, maps, basis offsets, rank, columns, centring) appended to `tables`. Returns the
/// array and the block records' offset in `tables`.
fn material_arrays(mat: &Material, tables: &mut Vec<u32>) -> (Vec<f32>, u32) {
    match &mat.source {
        Source::Raw(b) => {
            let off = tables.len() as u32;
            (b.data.clone(), off)
        }
        Source::Basis { basis, owners } => {
            tables.extend(owners.iter().flat_map(|o| match o {
                Some((bi, j)) => [*bi as u32, *j as u32],
                None => [NONE, 0],
            }));
            let blocks_off = tables.len() as u32;
            let mut data = Vec::new();
            for blk in &basis.blocks {
                let mean = data.len() as u32;
                data.extend(&blk.mean);
                let maps = data.len() as u32;
                data.extend(&blk.maps);
                let bas = data.len() as u32;
                data.extend(&blk.basis);
                tables.extend([
                    mean,
                    maps,
                    bas,
                    blk.rank() as u32,
                    blk.cols() as u32,
                    (blk.centring == Centring::Texels) as u32,
                ]);
            }
            (data, blocks_off)
        }
    }
}
