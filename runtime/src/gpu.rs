//! The wgpu device shared by a run (and by every run of one engine), created on first use so a
//! graph without GPU nodes never touches the GPU.

use std::sync::{Arc, OnceLock};

pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl Gpu {
    /// "NVIDIA H100 (Vulkan)", "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub fn describe(&self) -> String {
        format!("{} ({:?})", self.info.name, self.info.backend)
    }

    fn create() -> Result<Gpu, String> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        }))
        .map_err(|e| format!("no GPU adapter: {e}"))?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("mesoflow"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| format!("adapter {} refused a device: {e}", info.name))?;
        Ok(Gpu { device, queue, info })
    }
}

/// Lazily creates the GPU once; every later call gets the same device or the same error.
#[derive(Default)]
pub struct GpuProvider {
    cell: OnceLock<Result<Arc<Gpu>, String>>,
}

impl GpuProvider {
    pub fn get(&self) -> Result<Arc<Gpu>, String> {
        self.cell.get_or_init(|| Gpu::create().map(Arc::new)).clone()
    }
}
