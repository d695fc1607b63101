//! Small helpers for compute passes: upload f32 data, run one WGSL entry point over a 2-D grid,
//! read the result back. GPU nodes share these so each node's file holds only its own logic.

use mesoflow_runtime::{Gpu, NodeError};
use wgpu::util::DeviceExt;

/// One compute dispatch over a 2-D grid: `entry` of the WGSL `shader` with bindings
/// 0 = uniform `params`, 1 = read-only storage `input`, 2 = read-write storage of `output_len` f32.
pub struct Pass2d<'a> {
    pub label: &'a str,
    pub shader: &'a str,
    pub entry: &'a str,
    pub params: &'a [u8],
    pub input: &'a [f32],
    pub output_len: usize,
    /// Grid size; enough 8×8 workgroups are dispatched to cover it.
    pub grid: (u32, u32),
}

/// Runs the pass and returns the output buffer.
pub fn compute_2d(gpu: &Gpu, pass: &Pass2d) -> Result<Vec<f32>, NodeError> {
    compute_2d_sequence(gpu, pass, &[pass.params])
}

/// Runs the pass once per entry of `params` (ignoring `pass.params`), in order, on the same
/// input and output buffers, and returns the output after the last: a shader can split work
/// too long for one dispatch and accumulate into its output.
pub fn compute_2d_sequence(
    gpu: &Gpu,
    pass: &Pass2d,
    params: &[&[u8]],
) -> Result<Vec<f32>, NodeError> {
    let Pass2d {
        label,
        shader,
        entry,
        input,
        output_len,
        grid: (width, height),
        ..
    } = *pass;
    let limit = gpu.device.limits().max_storage_buffer_binding_size;
    let out_bytes = (output_len * 4) as u64;
    let in_bytes = (input.len() * 4) as u64;
    if out_bytes.max(in_bytes) > limit {
        return Err(NodeError::Gpu(format!(
            "{label}: a buffer of {} bytes exceeds this adapter's storage binding limit of {limit} bytes; use --device cpu",
            out_bytes.max(in_bytes)
        )));
    }
    let device = &gpu.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(shader.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    let input_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("input"),
        contents: bytemuck::cast_slice(input),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let output_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("output"),
        size: out_bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: out_bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    for params in params {
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: params,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: input_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: output_buf.as_entire_binding(),
                },
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
    }
    encoder.copy_buffer_to_buffer(&output_buf, 0, &staging, 0, out_bytes);
    gpu.queue.submit([encoder.finish()]);
    let bytes = read_back(gpu, &staging).map_err(|e| NodeError::Gpu(format!("{label}: {e}")))?;
    Ok(bytemuck::cast_slice::<u8, f32>(&bytes).to_vec())
}

/// The bytes of a mappable buffer once the queue has finished with it.
pub fn read_back(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<u8>, String> {
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    gpu.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| format!("wait: {e}"))?;
    rx.recv()
        .map_err(|e| e.to_string())?
        .map_err(|e| e.to_string())?;
    let bytes = slice
        .get_mapped_range()
        .map_err(|e| format!("map: {e}"))?
        .to_vec();
    buffer.unmap();
    Ok(bytes)
}

/// The end of a GPU agreement test: with `MESOFLOW_REQUIRE_GPU=1` (CI, on lavapipe) a test that
/// found no adapter on any backend fails instead of passing vacuously.
#[cfg(test)]
pub fn require_tested(tested: usize) {
    if tested == 0 {
        mesoflow_testkit::skip_unless_required(
            "MESOFLOW_REQUIRE_GPU",
            "no GPU adapter on any backend could run the GPU agreement test",
        );
    }
}

#[cfg(test)]
mod tests {
    /// Every shader, as the nodes hand it to wgpu (shared parts joined in), parses and validates
    /// with naga, the front end wgpu itself uses: on a machine without a GPU adapter the GPU
    /// paths never build their pipelines, and a broken shader would pass every other test there.
    #[test]
    fn every_shader_is_valid_wgsl() {
        let shaders = [
            ("heightfield/normals", crate::heightfield::normals::WGSL),
            ("mdf/mesh_tile", crate::mdf::mesh_tile::WGSL),
            ("mdf/tabulate", crate::mdf::tabulate::WGSL),
            ("render/peel", crate::render::gpu_render::PEEL_WGSL),
            ("render/resolve", crate::render::gpu_render::RESOLVE_WGSL),
            ("render/relief", crate::render::relief_gpu::RELIEF_WGSL),
            ("sss/render/gather", crate::sss::render::gather::WGSL),
        ];
        for (name, source) in shaders {
            let module = naga::front::wgsl::parse_str(source)
                .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::all(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
        }
    }
}
