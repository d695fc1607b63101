//! Who produced a cache entry: the mesoflow build, the host (and Slurm node) and the CPU's
//! features, recorded in every entry's header so a bad entry in a shared cache can be traced to
//! the machine and build that wrote it. Also the random part of temporary names, which must not
//! collide between hosts writing into one cache over a shared filesystem.

use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Producer {
    /// The release and a hash of the executable that wrote the entry.
    pub build: String,
    pub host: String,
    pub cpu: String,
}

/// blake3 of the running executable (its first 16 hex digits): two processes with the same
/// build id run the same code. "unknown" when the executable cannot be read.
pub fn build_id() -> &'static str {
    static ID: OnceLock<String> = OnceLock::new();
    ID.get_or_init(|| {
        std::env::current_exe()
            .and_then(std::fs::read)
            .map(|bytes| blake3::hash(&bytes).to_hex()[..16].to_string())
            .unwrap_or_else(|_| "unknown".into())
    })
}

/// The host name, with the Slurm node name when a job runs under one (several `slurmd` may
/// share a host).
pub fn host() -> &'static str {
    static HOST: OnceLock<String> = OnceLock::new();
    HOST.get_or_init(|| {
        let name = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .or_else(|| std::env::var("COMPUTERNAME").ok())
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| "unknown-host".into());
        match std::env::var("SLURMD_NODENAME") {
            Ok(node) if !node.is_empty() && node != name => format!("{name}/{node}"),
            _ => name,
        }
    })
}

fn cpu() -> String {
    let mut parts = vec![std::env::consts::ARCH.to_string()];
    #[cfg(target_arch = "x86_64")]
    {
        for (name, on) in [
            ("avx2", std::arch::is_x86_feature_detected!("avx2")),
            ("fma", std::arch::is_x86_feature_detected!("fma")),
            ("avx512f", std::arch::is_x86_feature_detected!("avx512f")),
        ] {
            if on {
                parts.push(name.into());
            }
        }
    }
    parts.join(" ")
}

pub fn producer() -> &'static Producer {
    static P: OnceLock<Producer> = OnceLock::new();
    P.get_or_init(|| Producer {
        build: format!("{} {}", env!("CARGO_PKG_VERSION"), build_id()),
        host: host().to_string(),
        cpu: cpu(),
    })
}

/// A part of a temporary file's name that no other writer uses: the host, the process and 64
/// bits from the clock, the process id and a counter hashed together.
pub fn unique_suffix(counter: u64) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let mut h = blake3::Hasher::new();
    h.update(host().as_bytes());
    h.update(&std::process::id().to_le_bytes());
    h.update(&nanos.to_le_bytes());
    h.update(&counter.to_le_bytes());
    let host: String = host()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .take(32)
        .collect();
    format!(
        "{host}.{}.{}",
        std::process::id(),
        &h.finalize().to_hex()[..16]
    )
}
