//! What runs share and the engine keeps between them: the registry of kinds, the memory and
//! disk caches and the GPU. The scheduler runs a graph with these; the engine owns them.

use crate::cache::{DiskCache, MemoryCache};
use crate::gpu::GpuProvider;
use crate::registry::Registry;
use std::sync::Arc;

pub(crate) struct Resources {
    pub(crate) registry: Arc<Registry>,
    pub(crate) memory: Arc<MemoryCache>,
    pub(crate) disk: Option<DiskCache>,
    pub(crate) gpu: Arc<GpuProvider>,
}
