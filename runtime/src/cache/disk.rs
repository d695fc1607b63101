//! Content-addressed disk cache. One file per key, `<dir>/<first two hex>/<key>.mfc`:
//!
//! ```text
//! "MESOFLOW-CACHE\x01\n" | u64 header length | header JSON | payload | blake3(header ‖ payload)
//! ```
//!
//! The header names the key and kind the entry was written for, the compute time, timings and
//! warnings, and each output's port, type and payload length. A read compares the recorded key
//! and kind with the ones asked for, so an entry copied or renamed over another is refused (and
//! recomputed) rather than served. Entries are written to a temporary file in `<dir>/tmp` and renamed into place, so
//! a reader (in this process or another) sees a whole entry or none; the trailing checksum catches
//! truncation and corruption, which the engine reports as a warning and recomputes. Temporary
//! files older than [`ORPHAN_AGE`] were left by a process that died mid-write: every write and
//! `cache stats` reclaim them.

use super::Record;
use crate::codec::Encoder;
use crate::key::Key;
use crate::node::Outputs;
use crate::registry::Registry;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use thiserror::Error;

/// Format 2 records the key and the timings; a format-1 entry reads as a miss and is overwritten.
const MAGIC: &[u8; 16] = b"MESOFLOW-CACHE\x02\n";
const MAGIC_PREFIX: &[u8] = b"MESOFLOW-CACHE";

/// The type of a derived entry's one output: bytes its node encodes and decodes itself.
const BYTES: &str = "bytes";

/// A temporary file older than this is an orphan: no write takes anywhere near as long.
pub const ORPHAN_AGE: std::time::Duration = std::time::Duration::from_secs(3600);

#[derive(Debug, Error)]
pub enum DiskError {
    #[error("cache entry {path}: {message}")]
    Corrupt { path: String, message: String },
    #[error("cache {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}

#[derive(Serialize, Deserialize)]
struct Header {
    key: String,
    kind: String,
    #[serde(flatten)]
    record: Record,
    outputs: Vec<OutputHeader>,
    /// Absent in entries written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    producer: Option<crate::producer::Producer>,
}

#[derive(Serialize, Deserialize)]
struct OutputHeader {
    port: String,
    #[serde(rename = "type")]
    ty: String,
    len: u64,
}

#[derive(Clone, Debug)]
pub struct DiskCache {
    dir: PathBuf,
}

/// Per-kind totals for `mesoflow cache stats`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct KindStats {
    pub entries: u64,
    pub bytes: u64,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct CacheStats {
    pub entries: u64,
    pub bytes: u64,
    pub unreadable: u64,
    /// Temporary files left by interrupted writes that are still younger than [`ORPHAN_AGE`].
    pub temporary: u64,
    /// Orphaned temporary files removed by this call.
    pub reclaimed: u64,
    pub by_kind: BTreeMap<String, KindStats>,
}

/// What [`DiskCache::gc`] removed and kept.
#[derive(Clone, Debug, Default, Serialize)]
pub struct GcStats {
    pub removed: u64,
    pub freed_bytes: u64,
    pub kept: u64,
    pub kept_bytes: u64,
    /// Orphaned temporary files removed as well.
    pub reclaimed: u64,
}

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

impl DiskCache {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        DiskCache { dir: dir.into() }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn entry_path(&self, key: &Key) -> PathBuf {
        let hex = key.hex();
        self.dir.join(&hex[..2]).join(format!("{hex}.mfc"))
    }

    pub fn contains(&self, key: &Key) -> bool {
        self.entry_path(key).is_file()
    }

    /// `Ok(None)` on a miss; `Err(Corrupt)` for an entry that exists but cannot be trusted: bad
    /// checksum, or written for another key or kind than the one asked for.
    pub fn get(
        &self,
        key: &Key,
        kind: &str,
        registry: &Registry,
    ) -> Result<Option<(Outputs, Record)>, DiskError> {
        self.read(key, |bytes| decode_entry(bytes, key, kind, registry))
    }

    /// A derived entry's bytes ([`DiskCache::put_bytes`]): `Ok(None)` on a miss, `Err(Corrupt)`
    /// as for [`DiskCache::get`].
    pub fn get_bytes(&self, key: &Key, kind: &str) -> Result<Option<Vec<u8>>, DiskError> {
        self.read(key, |bytes| {
            let (header, payload) = open_entry(bytes, key, kind)?;
            match header.outputs.as_slice() {
                [o] if o.ty == BYTES && o.len == payload.len() as u64 => Ok(payload.to_vec()),
                _ => Err("not a derived entry of bytes".into()),
            }
        })
    }

    /// Reads the entry of `key` and decodes it with `decode`; a hit renews its modification
    /// time.
    fn read<T>(
        &self,
        key: &Key,
        decode: impl FnOnce(&[u8]) -> Result<T, String>,
    ) -> Result<Option<T>, DiskError> {
        let path = self.entry_path(key);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(DiskError::Io {
                    path: path.display().to_string(),
                    source,
                })
            }
        };
        if bytes.starts_with(MAGIC_PREFIX) && !bytes.starts_with(MAGIC) {
            return Ok(None); // an older format: recomputed and overwritten
        }
        let entry = decode(&bytes);
        if entry.is_ok() {
            // A hit renews the entry's modification time: `gc` removes the least recently used
            // first. A cache on a read-only filesystem still serves, unrenewed.
            let _ = std::fs::File::options()
                .write(true)
                .open(&path)
                .and_then(|f| f.set_modified(std::time::SystemTime::now()));
        }
        entry.map(Some).map_err(|message| DiskError::Corrupt {
            path: path.display().to_string(),
            message,
        })
    }

    /// Removes an entry (after it was found corrupt).
    pub fn remove(&self, key: &Key) {
        let _ = std::fs::remove_file(self.entry_path(key));
    }

    pub fn put(
        &self,
        key: &Key,
        kind: &str,
        outputs: &Outputs,
        record: &Record,
    ) -> Result<(), DiskError> {
        let mut payload = Encoder::default();
        let mut headers = Vec::new();
        for (port, value) in &outputs.values {
            let start = payload.bytes.len();
            value.encode(&mut payload);
            headers.push(OutputHeader {
                port: port.clone(),
                ty: value.type_name().to_string(),
                len: (payload.bytes.len() - start) as u64,
            });
        }
        self.write(key, kind, record, headers, &payload.bytes)
    }

    /// Stores bytes a node derived from its inputs and encodes itself (a mesh's BVH), not a
    /// value of the graph: an entry like any other (checksummed, counted by `cache stats`
    /// under `kind`, collected by `gc`, removed by `clear`) with one output of type `bytes`.
    pub fn put_bytes(
        &self,
        key: &Key,
        kind: &str,
        bytes: &[u8],
        record: &Record,
    ) -> Result<(), DiskError> {
        let header = OutputHeader {
            port: "data".into(),
            ty: BYTES.into(),
            len: bytes.len() as u64,
        };
        self.write(key, kind, record, vec![header], bytes)
    }

    fn write(
        &self,
        key: &Key,
        kind: &str,
        record: &Record,
        outputs: Vec<OutputHeader>,
        payload: &[u8],
    ) -> Result<(), DiskError> {
        let io = |path: &Path| {
            let path = path.display().to_string();
            move |source| DiskError::Io { path, source }
        };
        let header = serde_json::to_vec(&Header {
            key: key.hex(),
            kind: kind.into(),
            record: record.clone(),
            outputs,
            producer: Some(crate::producer::producer().clone()),
        })
        .map_err(|e| DiskError::Corrupt {
            path: String::new(),
            message: e.to_string(),
        })?;
        let sum = checksum(&[&header, payload]);

        let final_path = self.entry_path(key);
        let tmp_dir = self.dir.join("tmp");
        std::fs::create_dir_all(&tmp_dir).map_err(io(&tmp_dir))?;
        reclaim_orphans(&tmp_dir);
        if let Some(parent) = final_path.parent() {
            std::fs::create_dir_all(parent).map_err(io(parent))?;
        }
        // Hosts sharing the cache over a network filesystem may have the same process ids.
        let tmp = tmp_dir.join(format!(
            "{}.{}.tmp",
            key.hex(),
            crate::producer::unique_suffix(TMP_COUNTER.fetch_add(1, Ordering::Relaxed))
        ));
        let write = || -> std::io::Result<()> {
            let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
            f.write_all(MAGIC)?;
            f.write_all(&(header.len() as u64).to_le_bytes())?;
            f.write_all(&header)?;
            f.write_all(payload)?;
            f.write_all(sum.as_bytes())?;
            f.into_inner().map_err(|e| e.into_error())?.sync_data()?;
            std::fs::rename(&tmp, &final_path)
        };
        write().map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            DiskError::Io {
                path: final_path.display().to_string(),
                source: e,
            }
        })
    }

    /// Removes every entry and leftover temporary file.
    pub fn clear(&self) -> Result<u64, DiskError> {
        let stats = self.stats();
        if self.dir.exists() {
            std::fs::remove_dir_all(&self.dir).map_err(|source| DiskError::Io {
                path: self.dir.display().to_string(),
                source,
            })?;
        }
        Ok(stats.entries)
    }

    /// Removes the entries not used for longer than `older_than`, then the least recently used
    /// (by modification time, which a hit renews; ties by name) until at most `max_bytes`
    /// remain, and orphaned temporary files. A shared cache must not grow without end.
    pub fn gc(&self, max_bytes: Option<u64>, older_than: Option<std::time::Duration>) -> GcStats {
        let mut stats = GcStats {
            reclaimed: reclaim_orphans(&self.dir.join("tmp")),
            ..GcStats::default()
        };
        let now = std::time::SystemTime::now();
        let mut entries: Vec<(std::time::SystemTime, PathBuf, u64)> = Vec::new();
        for shard in std::fs::read_dir(&self.dir).into_iter().flatten().flatten() {
            if shard.file_name() == "tmp" {
                continue;
            }
            for f in std::fs::read_dir(shard.path())
                .into_iter()
                .flatten()
                .flatten()
            {
                let Ok(meta) = f.metadata() else { continue };
                if !meta.is_file() {
                    continue;
                }
                let used = meta.modified().unwrap_or(std::time::UNIX_EPOCH);
                entries.push((used, f.path(), meta.len()));
            }
        }
        entries.sort();
        let mut total: u64 = entries.iter().map(|e| e.2).sum();
        for (used, path, len) in entries {
            let stale =
                older_than.is_some_and(|d| now.duration_since(used).is_ok_and(|age| age > d));
            let over = max_bytes.is_some_and(|m| total > m);
            if (stale || over) && std::fs::remove_file(&path).is_ok() {
                stats.removed += 1;
                stats.freed_bytes += len;
                total -= len;
            } else {
                stats.kept += 1;
                stats.kept_bytes += len;
            }
        }
        stats
    }

    /// Who wrote an entry (`None` for a missing entry or one written before producers were
    /// recorded).
    pub fn producer(&self, key: &Key) -> Option<crate::producer::Producer> {
        read_header(&self.entry_path(key)).and_then(|h| h.producer)
    }

    pub fn stats(&self) -> CacheStats {
        let mut stats = CacheStats::default();
        let Ok(shards) = std::fs::read_dir(&self.dir) else {
            return stats;
        };
        let tmp_dir = self.dir.join("tmp");
        stats.reclaimed = reclaim_orphans(&tmp_dir);
        stats.temporary = std::fs::read_dir(&tmp_dir).map_or(0, |d| d.count() as u64);
        for shard in shards.flatten() {
            if shard.file_name() == "tmp" {
                continue;
            }
            let Ok(files) = std::fs::read_dir(shard.path()) else {
                continue;
            };
            for f in files.flatten() {
                let len = f.metadata().map(|m| m.len()).unwrap_or(0);
                stats.entries += 1;
                stats.bytes += len;
                match read_kind(&f.path()) {
                    Some(kind) => {
                        let k = stats.by_kind.entry(kind).or_default();
                        k.entries += 1;
                        k.bytes += len;
                    }
                    None => stats.unreadable += 1,
                }
            }
        }
        stats
    }
}

/// Removes temporary files older than [`ORPHAN_AGE`]; returns how many.
fn reclaim_orphans(tmp_dir: &Path) -> u64 {
    let Ok(files) = std::fs::read_dir(tmp_dir) else {
        return 0;
    };
    let mut removed = 0;
    for f in files.flatten() {
        let old = f
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age > ORPHAN_AGE);
        if old && std::fs::remove_file(f.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// blake3 of the concatenated parts; large inputs are hashed on the rayon pool (blake3's tree
/// hash gives the same digest whatever the thread count).
fn checksum(parts: &[&[u8]]) -> blake3::Hash {
    let mut h = blake3::Hasher::new();
    for p in parts {
        if p.len() > 1 << 20 {
            h.update_rayon(p);
        } else {
            h.update(p);
        }
    }
    h.finalize()
}

fn read_kind(path: &Path) -> Option<String> {
    read_header(path).map(|h| h.kind)
}

fn read_header(path: &Path) -> Option<Header> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).ok()?;
    let mut head = [0u8; 24];
    f.read_exact(&mut head).ok()?;
    if &head[..16] != MAGIC {
        return None;
    }
    let len = u64::from_le_bytes(head[16..24].try_into().ok()?);
    let mut header = vec![0u8; usize::try_from(len).ok().filter(|l| *l < 1 << 20)?];
    f.read_exact(&mut header).ok()?;
    serde_json::from_slice::<Header>(&header).ok()
}

/// An entry's header and its outputs' payload, once its checksum, key and kind are checked.
fn open_entry<'a>(bytes: &'a [u8], key: &Key, kind: &str) -> Result<(Header, &'a [u8]), String> {
    if bytes.len() < MAGIC.len() + 8 + 32 || &bytes[..16] != MAGIC {
        return Err("not a mesoflow cache entry or truncated".into());
    }
    let (body, sum) = bytes.split_at(bytes.len() - 32);
    let content = &body[24..];
    if checksum(&[content]).as_bytes() != sum {
        return Err("checksum mismatch (truncated or corrupted)".into());
    }
    let len = u64::from_le_bytes(body[16..24].try_into().map_err(|_| "bad header length")?);
    let len = usize::try_from(len)
        .ok()
        .filter(|l| *l <= content.len())
        .ok_or("bad header length")?;
    let header: Header = serde_json::from_slice(&content[..len]).map_err(|e| e.to_string())?;
    if header.key != key.hex() {
        return Err(format!(
            "holds the entry of key {} (kind `{}`), not of {}",
            header.key,
            header.kind,
            key.hex()
        ));
    }
    if header.kind != kind {
        return Err(format!(
            "was written by kind `{}`, not `{kind}`",
            header.kind
        ));
    }
    Ok((header, &content[len..]))
}

fn decode_entry(
    bytes: &[u8],
    key: &Key,
    kind: &str,
    registry: &Registry,
) -> Result<(Outputs, Record), String> {
    let (header, mut rest) = open_entry(bytes, key, kind)?;
    let mut outputs = Outputs::new();
    for o in header.outputs {
        let n = usize::try_from(o.len)
            .ok()
            .filter(|n| *n <= rest.len())
            .ok_or("output longer than entry")?;
        let value = registry
            .decode(&o.ty, &rest[..n])
            .map_err(|e| e.to_string())?;
        outputs.values.insert(o.port, value);
        rest = &rest[n..];
    }
    if !rest.is_empty() {
        return Err("trailing bytes".into());
    }
    Ok((outputs, header.record))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::{Artifact, Scalar};

    fn sample() -> Outputs {
        Outputs::new().with("x", Scalar(2.5)).with(
            "file",
            Artifact {
                path: "a.png".into(),
                bytes: (0..=255).collect(),
            },
        )
    }

    #[test]
    fn derived_bytes_round_trip_are_counted_and_refused_when_damaged_or_of_another_kind() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path());
        let key = Key([9; 32]);
        assert!(cache.get_bytes(&key, "raytrace.bvh").unwrap().is_none());
        let bytes: Vec<u8> = (0..100_000u32).map(|i| (i * 7) as u8).collect();
        let record = Record {
            seconds: 2.0,
            ..Default::default()
        };
        cache
            .put_bytes(&key, "raytrace.bvh", &bytes, &record)
            .unwrap();
        assert_eq!(cache.get_bytes(&key, "raytrace.bvh").unwrap(), Some(bytes));
        let stats = cache.stats();
        assert_eq!(stats.by_kind["raytrace.bvh"].entries, 1);
        assert!(matches!(
            cache.get_bytes(&key, "other.kind"),
            Err(DiskError::Corrupt { .. })
        ));
        // A value's reader refuses it too (its one output is of no registered type).
        assert!(cache.get(&key, "raytrace.bvh", &Registry::new()).is_err());
        let path = cache.entry_path(&key);
        let mut damaged = std::fs::read(&path).unwrap();
        let middle = damaged.len() / 2;
        damaged[middle] ^= 1;
        std::fs::write(&path, damaged).unwrap();
        assert!(matches!(
            cache.get_bytes(&key, "raytrace.bvh"),
            Err(DiskError::Corrupt { .. })
        ));
    }

    #[test]
    fn round_trip_and_every_truncation_is_detected() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path());
        let reg = Registry::new();
        let key = Key([7; 32]);
        assert!(cache.get(&key, "test.kind", &reg).unwrap().is_none());
        let record = Record {
            seconds: 1.25,
            timings: [("gpu_ms".to_string(), 3.5)].into(),
            warnings: vec!["thin: 2.5 mean free paths".into()],
        };
        cache.put(&key, "test.kind", &sample(), &record).unwrap();
        let (out, back) = cache.get(&key, "test.kind", &reg).unwrap().unwrap();
        assert_eq!(back, record);
        let producer = cache.producer(&key).unwrap();
        assert!(
            producer.build.starts_with(env!("CARGO_PKG_VERSION")),
            "{producer:?}"
        );
        assert!(!producer.host.is_empty() && !producer.cpu.is_empty());
        assert_eq!(out.get("x").unwrap().as_scalar(), Some(2.5));
        let full = std::fs::read(cache.entry_path(&key)).unwrap();
        for cut in [0, 10, 30, full.len() / 2, full.len() - 1] {
            std::fs::write(cache.entry_path(&key), &full[..cut]).unwrap();
            assert!(
                matches!(
                    cache.get(&key, "test.kind", &reg),
                    Err(DiskError::Corrupt { .. })
                ),
                "cut {cut}"
            );
        }
        // A flipped payload byte (the last before the 32-byte checksum): the header still reads,
        // so `stats` counts the entry, but the checksum refuses it.
        let mut flipped = full.clone();
        flipped[full.len() - 33] ^= 1;
        std::fs::write(cache.entry_path(&key), &flipped).unwrap();
        assert!(matches!(
            cache.get(&key, "test.kind", &reg),
            Err(DiskError::Corrupt { .. })
        ));
        let stats = cache.stats();
        assert_eq!((stats.entries, stats.unreadable), (1, 0));
        assert!(
            std::fs::read_dir(dir.path().join("tmp"))
                .unwrap()
                .next()
                .is_none(),
            "no temp files left"
        );
        assert_eq!(cache.clear().unwrap(), 1);
        assert_eq!(cache.stats().entries, 0);
    }

    #[test]
    fn an_entry_is_served_only_for_its_own_key_and_kind() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path());
        let reg = Registry::new();
        let (a, b) = (Key([1; 32]), Key([2; 32]));
        cache
            .put(&a, "test.kind", &sample(), &Record::default())
            .unwrap();
        // Another entry copied over this key's file: refused, never served.
        std::fs::create_dir_all(cache.entry_path(&b).parent().unwrap()).unwrap();
        std::fs::copy(cache.entry_path(&a), cache.entry_path(&b)).unwrap();
        let err = cache.get(&b, "test.kind", &reg).unwrap_err().to_string();
        assert!(err.contains("holds the entry of key 0101"), "{err}");
        // The right key asked for by another kind: refused too.
        let err = cache.get(&a, "other.kind", &reg).unwrap_err().to_string();
        assert!(err.contains("written by kind `test.kind`"), "{err}");
        assert!(cache.get(&a, "test.kind", &reg).unwrap().is_some());
    }

    #[test]
    fn gc_removes_stale_entries_then_the_least_recently_used_down_to_the_budget() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path());
        let reg = Registry::new();
        let day = std::time::Duration::from_secs(86_400);
        let now = std::time::SystemTime::now();
        let keys: Vec<Key> = (1..=4).map(|i| Key([i; 32])).collect();
        for (i, k) in keys.iter().enumerate() {
            cache
                .put(k, "test.kind", &sample(), &Record::default())
                .unwrap();
            // Entry i was last used i + 1 days ago, except entry 3, 40 days ago.
            let age = if i == 3 {
                40 * day
            } else {
                (i as u32 + 1) * day
            };
            let f = std::fs::File::options()
                .write(true)
                .open(cache.entry_path(k))
                .unwrap();
            f.set_modified(now - age).unwrap();
        }
        let size = std::fs::metadata(cache.entry_path(&keys[0])).unwrap().len();
        // A hit renews entry 2 (3 days old): it becomes the most recently used.
        assert!(cache.get(&keys[2], "test.kind", &reg).unwrap().is_some());
        let s = cache.gc(None, Some(30 * day));
        assert_eq!((s.removed, s.kept, s.freed_bytes), (1, 3, size));
        assert!(!cache.contains(&keys[3]));
        // Room for two: the least recently used go first (entry 1, 2 days; then entry 0, 1 day).
        let s = cache.gc(Some(2 * size), None);
        assert_eq!((s.removed, s.kept, s.kept_bytes), (1, 2, 2 * size));
        assert!(!cache.contains(&keys[1]) && cache.contains(&keys[0]) && cache.contains(&keys[2]));
        let s = cache.gc(Some(0), None);
        assert_eq!((s.removed, s.kept), (2, 0));
        assert_eq!(cache.stats().entries, 0);
    }

    #[test]
    fn orphaned_temporary_files_are_counted_then_reclaimed_by_age() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path());
        let tmp = dir.path().join("tmp");
        std::fs::create_dir_all(&tmp).unwrap();
        let fresh = tmp.join("fresh.tmp");
        let old = tmp.join("old.tmp");
        std::fs::write(&fresh, b"x").unwrap();
        std::fs::write(&old, b"x").unwrap();
        let long_ago = std::time::SystemTime::now() - ORPHAN_AGE * 2;
        std::fs::File::options()
            .write(true)
            .open(&old)
            .unwrap()
            .set_modified(long_ago)
            .unwrap();
        let stats = cache.stats();
        assert_eq!((stats.reclaimed, stats.temporary), (1, 1));
        assert!(fresh.exists() && !old.exists());
    }
}
