//! What the GPU probe found on this machine, remembered in the disk cache (`gpu-probe.json`), so
//! that a run whose GPU nodes are all cached keys them without loading a driver: creating a wgpu
//! instance alone costs 20–90 ms (Vulkan's loader, lavapipe, EGL), which would otherwise be most
//! of a warm run. The memo holds only while its fingerprint does: mesoflow's version, the boot,
//! the environment variables the drivers read, and the driver manifests and device nodes on
//! disk. A run that has a GPU node to compute from a remembered probe confirms it with the live
//! one first and keys again when they differ (the scheduler does), so a stale memo never puts a
//! value under the wrong path's key.

use serde::{Deserialize, Serialize};
use std::path::Path;

/// What a probe found: the path a GPU node can take and the adapter that decides it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Found {
    /// A hardware adapter, described ("NVIDIA H200, Vulkan").
    Hardware(String),
    /// Only a software adapter (lavapipe, llvmpipe), described.
    Software(String),
    /// No adapter; why.
    Missing(String),
}

#[derive(Serialize, Deserialize)]
struct Memo {
    fingerprint: String,
    found: Found,
}

pub const FILE: &str = "gpu-probe.json";

/// Environment variables that change which adapter wgpu finds.
const ENV_PREFIXES: &[&str] = &[
    "WGPU_",
    "VK_",
    "MESA_",
    "LIBGL_",
    "GALLIUM_",
    "LP_",
    "__GLX_",
    "__EGL_",
    "NVIDIA_",
    "CUDA_VISIBLE",
    "DRI_",
];
const ENV_NAMES: &[&str] = &["LD_LIBRARY_PATH", "DISPLAY", "WAYLAND_DISPLAY"];

/// Folders whose entries (name, size, modification time) name the installed drivers and devices.
const DRIVER_DIRS: &[&str] = &[
    "/usr/share/vulkan/icd.d",
    "/usr/local/share/vulkan/icd.d",
    "/etc/vulkan/icd.d",
    "/usr/share/glvnd/egl_vendor.d",
    "/etc/glvnd/egl_vendor.d",
    "/dev/dri",
];

/// A hash of everything the memo's validity rests on.
pub fn fingerprint() -> String {
    let mut h = blake3::Hasher::new();
    h.update(b"mesoflow gpu probe 1\0");
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    let mut vars: Vec<(String, String)> = std::env::vars_os()
        .filter_map(|(k, v)| Some((k.into_string().ok()?, v.to_string_lossy().into_owned())))
        .filter(|(k, _)| {
            ENV_NAMES.contains(&k.as_str()) || ENV_PREFIXES.iter().any(|p| k.starts_with(p))
        })
        .collect();
    vars.sort();
    for (k, v) in vars {
        h.update(format!("env {k}={v}\0").as_bytes());
    }
    for file in [
        "/proc/sys/kernel/random/boot_id",
        "/proc/driver/nvidia/version",
    ] {
        if let Ok(text) = std::fs::read(file) {
            h.update(file.as_bytes());
            h.update(&text);
        }
    }
    let mut dirs: Vec<String> = DRIVER_DIRS.iter().map(|d| d.to_string()).collect();
    if let Some(home) = std::env::var_os("HOME") {
        dirs.push(format!(
            "{}/.local/share/vulkan/icd.d",
            home.to_string_lossy()
        ));
    }
    for dir in dirs {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut seen: Vec<String> = entries
            .flatten()
            .map(|e| {
                let meta = e.metadata().ok();
                let len = meta.as_ref().map_or(0, |m| m.len());
                let modified = meta
                    .and_then(|m| m.modified().ok())
                    .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                    .map_or(0, |d| d.as_nanos());
                format!("{dir}/{} {len} {modified}", e.file_name().to_string_lossy())
            })
            .collect();
        seen.sort();
        for s in seen {
            h.update(s.as_bytes());
            h.update(b"\0");
        }
    }
    // NVIDIA's device nodes live in /dev itself.
    if let Ok(entries) = std::fs::read_dir("/dev") {
        let mut nv: Vec<String> = entries
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("nvidia"))
            .collect();
        nv.sort();
        h.update(nv.join(",").as_bytes());
    }
    h.finalize().to_hex().to_string()
}

/// The remembered probe in `dir`, if one is there and its fingerprint is this machine's now.
pub fn read(dir: &Path) -> Option<Found> {
    let text = std::fs::read(dir.join(FILE)).ok()?;
    let memo: Memo = serde_json::from_slice(&text).ok()?;
    (memo.fingerprint == fingerprint()).then_some(memo.found)
}

/// Remembers `found` in `dir` (best effort: a cache folder that cannot be written only costs the
/// next run a probe). Written to a temporary name and renamed, so a reader sees all or nothing.
pub fn write(dir: &Path, found: &Found) {
    let memo = Memo {
        fingerprint: fingerprint(),
        found: found.clone(),
    };
    let Ok(text) = serde_json::to_vec_pretty(&memo) else {
        return;
    };
    let _ = crate::atomic_file::write_atomic(&dir.join(FILE), text);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_memo_reads_back_while_its_fingerprint_holds_and_not_after() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(read(dir.path()), None);
        let found = Found::Software("llvmpipe, Vulkan, software".into());
        write(dir.path(), &found);
        assert_eq!(read(dir.path()), Some(found.clone()));
        // Another machine's (or another driver's) memo is not believed.
        let other = Memo {
            fingerprint: "0".repeat(64),
            found,
        };
        std::fs::write(dir.path().join(FILE), serde_json::to_vec(&other).unwrap()).unwrap();
        assert_eq!(read(dir.path()), None);
        // Nor a damaged one.
        std::fs::write(dir.path().join(FILE), b"{ not json").unwrap();
        assert_eq!(read(dir.path()), None);
    }

    #[test]
    fn the_fingerprint_is_stable_within_a_process() {
        assert_eq!(fingerprint(), fingerprint());
    }
}
