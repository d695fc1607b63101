//! Where a node runs. In `auto` mode a GPU node takes the GPU only when the adapter is worth it:
//! a software adapter (Mesa's llvmpipe through OpenGL, or its Vulkan driver lavapipe) runs our
//! shaders on the CPU, the heavy nodes slower than the CPU path (on 2 cores, BENCHMARKS.md:
//! `render.mesh` 2.1 s a frame on lavapipe against 0.64 s, `render.relief` about even), so the
//! CPU path is taken with a warning naming why. `--device gpu` still runs a software adapter:
//! that is how machines without a GPU test the GPU code. `MESOFLOW_REQUIRE_GPU=1` makes a GPU
//! node that finds no adapter at all fail instead of falling back.

use crate::gpu_memo::Found;
use crate::resources::Resources;
use crate::run::{DeviceMode, RunOptions};
use mesoflow_graph::DevicePreference;

pub(crate) struct Choice {
    /// The GPU lane (the device is taken from the engine when the node runs), or the CPU path.
    pub gpu: bool,
    /// Why a GPU node took its CPU path (a warning for the report).
    pub fallback: Option<String>,
    /// The remembered probe it was chosen from (the disk cache's memo, not a live device): the
    /// scheduler confirms it before computing such a node (see [`crate::gpu_memo`]).
    pub remembered: Option<Found>,
}

impl Choice {
    /// `"gpu"` or `"cpu"`: the path taken, as keys and reports name it.
    pub fn path(&self) -> &'static str {
        if self.gpu {
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

/// Where the probe is remembered: the disk cache, when this run uses it.
pub(crate) fn memo_dir<'a>(
    shared: &'a Resources,
    opts: &RunOptions,
) -> Option<&'a std::path::Path> {
    shared
        .disk
        .as_ref()
        .filter(|_| opts.policy.use_cache)
        .map(|d| d.dir())
}

/// `Err` when a GPU was required (`--device gpu`, `MESOFLOW_REQUIRE_GPU=1`) and none can be had.
pub(crate) fn choose(
    shared: &Resources,
    pref: DevicePreference,
    opts: &RunOptions,
) -> Result<Choice, String> {
    if planned(pref, opts.policy.device) == DevicePreference::Cpu {
        return Ok(Choice {
            gpu: false,
            fallback: None,
            remembered: None,
        });
    }
    let (found, remembered) = shared.gpu.found(memo_dir(shared, opts));
    let choice = |gpu, fallback| Choice {
        gpu,
        fallback,
        remembered: remembered.then(|| found.clone()),
    };
    match found.clone() {
        Found::Software(adapter) if opts.policy.device == DeviceMode::Auto => {
            let why = format!(
                "the only GPU adapter is {adapter}: a software adapter runs this node slower than \
                 the CPU path; ran the CPU path (--device gpu forces it)"
            );
            Ok(choice(false, Some(why)))
        }
        Found::Software(_) | Found::Hardware(_) => Ok(choice(true, None)),
        Found::Missing(e) if opts.policy.device == DeviceMode::Gpu => {
            Err(format!("{e} (--device gpu)"))
        }
        Found::Missing(e) if opts.policy.require_gpu => Err(format!(
            "{e} (MESOFLOW_REQUIRE_GPU=1 forbids the CPU fallback)"
        )),
        Found::Missing(_) => Ok(choice(
            false,
            Some("no GPU adapter; ran the CPU path".into()),
        )),
    }
}

/// Before a GPU node chosen from a remembered probe is computed: does the live probe agree?
/// When it does not, the memo is rewritten and the caller keys the graph again (now from the
/// live device), so no value is computed under a path its key does not name.
pub(crate) fn confirm(shared: &Resources, opts: &RunOptions, remembered: &Found) -> bool {
    let live = shared.gpu.found_live();
    if *remembered == live {
        return true;
    }
    if let Some(dir) = memo_dir(shared, opts) {
        crate::gpu_memo::write(dir, &live);
    }
    false
}
