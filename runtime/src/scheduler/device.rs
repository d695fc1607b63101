//! Where a node runs. In `auto` mode a GPU node takes the GPU only when the adapter is worth it:
//! a software adapter (Mesa's llvmpipe through OpenGL, or its Vulkan driver lavapipe) runs our
//! shaders on the CPU, slower than the CPU path (`graphs/btf_edit.json` on 2 cores: `render.mesh`
//! 120 s on lavapipe against 1.1 s on the CPU path, `render.relief` 2.6 s against 0.19 s), so the
//! CPU path is taken with a warning naming why. `--device gpu` still runs a software adapter:
//! that is how machines without a GPU test the GPU code. `MESOFLOW_REQUIRE_GPU=1` makes a GPU
//! node that finds no adapter at all fail instead of falling back.

use crate::engine::{DeviceMode, Engine, RunOptions};
use crate::gpu::Gpu;
use mesoflow_graph::DevicePreference;
use std::sync::Arc;

pub(crate) struct Choice {
    /// `Some` to run on the GPU lane, `None` for the CPU path.
    pub gpu: Option<Arc<Gpu>>,
    /// Why a GPU node took its CPU path (a warning for the report).
    pub fallback: Option<String>,
}

impl Choice {
    /// `"gpu"` or `"cpu"`: the path taken, as keys and reports name it.
    pub fn path(&self) -> &'static str {
        if self.gpu.is_some() {
            "gpu"
        } else {
            "cpu"
        }
    }
}

fn planned(pref: DevicePreference, mode: DeviceMode) -> DevicePreference {
    if mode == DeviceMode::Cpu {
        DevicePreference::Cpu
    } else {
        pref
    }
}

/// `Err` when a GPU was required (`--device gpu`, `MESOFLOW_REQUIRE_GPU=1`) and none can be had.
pub(crate) fn choose(
    engine: &Engine,
    pref: DevicePreference,
    opts: &RunOptions,
) -> Result<Choice, String> {
    let cpu = |fallback| Choice {
        gpu: None,
        fallback,
    };
    if planned(pref, opts.device) == DevicePreference::Cpu {
        return Ok(cpu(None));
    }
    match engine.gpu.get() {
        Ok(gpu) if opts.device == DeviceMode::Auto && gpu.is_software() => {
            let why = format!(
                "the only GPU adapter is {}: a software adapter runs this node slower than the CPU \
                 path; ran the CPU path (--device gpu forces it)",
                gpu.describe()
            );
            Ok(cpu(Some(why)))
        }
        Ok(gpu) => Ok(Choice {
            gpu: Some(gpu),
            fallback: None,
        }),
        Err(e) if opts.device == DeviceMode::Gpu => Err(format!("{e} (--device gpu)")),
        Err(e) if opts.require_gpu => Err(format!(
            "{e} (MESOFLOW_REQUIRE_GPU=1 forbids the CPU fallback)"
        )),
        Err(_) => Ok(cpu(Some("no GPU adapter; ran the CPU path".into()))),
    }
}
