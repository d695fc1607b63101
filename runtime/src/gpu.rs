//! The wgpu device shared by a run (and by every run of one engine), created on first use so a
//! graph without GPU nodes never touches the GPU.

use crate::gpu_memo::{self, Found};
use std::path::Path;
use std::sync::{Arc, OnceLock};

pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl Gpu {
    /// "NVIDIA H100, Vulkan", "llvmpipe (LLVM 15.0.6, 256 bits), Vulkan, software".
    pub fn describe(&self) -> String {
        let software = if self.is_software() { ", software" } else { "" };
        let api = match self.info.backend {
            wgpu::Backend::Vulkan => "Vulkan",
            wgpu::Backend::Metal => "Metal",
            wgpu::Backend::Dx12 => "DirectX 12",
            wgpu::Backend::Gl => "OpenGL",
            wgpu::Backend::BrowserWebGpu => "WebGPU",
            wgpu::Backend::Noop => "no-op",
        };
        format!("{}, {api}{software}", self.info.name)
    }

    /// A rasteriser running on the CPU (lavapipe, llvmpipe, SwiftShader).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// An adapter from the native APIs (Vulkan, Metal, DX12) first; OpenGL only when none exists,
    /// because probing GL drivers is slow and noisy where they are absent. `WGPU_BACKEND` overrides.
    fn adapter() -> Result<wgpu::Adapter, String> {
        let tries = match wgpu::Backends::from_env() {
            Some(b) => vec![b],
            None => vec![wgpu::Backends::PRIMARY, wgpu::Backends::GL],
        };
        let mut last = String::from("no backend tried");
        for backends in tries {
            match Self::request_adapter(backends) {
                Ok(a) => return Ok(a),
                Err(e) => last = e,
            }
        }
        Err(format!("no GPU adapter: {last}"))
    }

    /// The high-performance adapter of an instance limited to `backends`.
    fn request_adapter(backends: wgpu::Backends) -> Result<wgpu::Adapter, String> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.backends = backends;
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        };
        pollster::block_on(wgpu::Instance::new(desc).request_adapter(&options))
            .map_err(|e| e.to_string())
    }

    fn create() -> Result<Gpu, String> {
        Self::from_adapter(Self::adapter()?)
    }

    /// A device on the given backends only, bypassing the engine's choice; for tests that hold
    /// every available backend to the CPU path.
    pub fn with_backends(backends: wgpu::Backends) -> Result<Gpu, String> {
        let adapter =
            Self::request_adapter(backends).map_err(|e| format!("no {backends:?} adapter: {e}"))?;
        Self::from_adapter(adapter)
    }

    fn from_adapter(adapter: wgpu::Adapter) -> Result<Gpu, String> {
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("mesoflow"),
            // Timestamp queries where the adapter has them: nodes report GPU time per frame.
            required_features: adapter.features() & wgpu::Features::TIMESTAMP_QUERY,
            // The adapter's own limits: compute nodes want the largest storage buffers it allows.
            required_limits: adapter.limits(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| format!("adapter {} refused a device: {e}", info.name))?;
        Ok(Gpu {
            device,
            queue,
            info,
        })
    }
}

/// Lazily creates the GPU once; every later call gets the same device or the same error.
#[derive(Default)]
pub struct GpuProvider {
    cell: OnceLock<Result<Arc<Gpu>, String>>,
}

impl GpuProvider {
    pub fn get(&self) -> Result<Arc<Gpu>, String> {
        self.cell
            .get_or_init(|| Gpu::create().map(Arc::new))
            .clone()
    }

    /// What the live probe finds (creating the device on first call).
    pub fn found_live(&self) -> Found {
        match self.get() {
            Ok(g) if g.is_software() => Found::Software(g.describe()),
            Ok(g) => Found::Hardware(g.describe()),
            Err(e) => Found::Missing(e),
        }
    }

    /// What a GPU node can count on, and whether it is remembered rather than probed: the live
    /// device once this engine has one, else the memo in `memo_dir` while it holds (no driver
    /// is loaded), else the live probe, remembered there for the next run.
    pub fn found(&self, memo_dir: Option<&Path>) -> (Found, bool) {
        if self.cell.get().is_some() {
            return (self.found_live(), false);
        }
        if let Some(found) = memo_dir.and_then(gpu_memo::read) {
            return (found, true);
        }
        let found = self.found_live();
        if let Some(dir) = memo_dir {
            gpu_memo::write(dir, &found);
        }
        (found, false)
    }
}
