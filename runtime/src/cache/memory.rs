//! In-process cache of node outputs, bounded in bytes. When full it evicts the entries that are
//! cheapest to get back: least compute time per byte first.

use super::Record;
use crate::key::Key;
use crate::node::Outputs;
use std::collections::HashMap;
use std::sync::Mutex;

struct Entry {
    outputs: Outputs,
    bytes: usize,
    record: Record,
}

pub struct MemoryCache {
    budget: usize,
    inner: Mutex<Inner>,
}

#[derive(Default)]
struct Inner {
    entries: HashMap<Key, Entry>,
    used: usize,
}

impl MemoryCache {
    pub fn new(budget: usize) -> Self {
        MemoryCache {
            budget,
            inner: Mutex::new(Inner::default()),
        }
    }

    pub fn budget(&self) -> usize {
        self.budget
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock cannot leave the map inconsistent (no partial updates),
        // so a poisoned lock is still usable.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn get(&self, key: &Key) -> Option<(Outputs, Record)> {
        self.lock()
            .entries
            .get(key)
            .map(|e| (e.outputs.clone(), e.record.clone()))
    }

    pub fn used(&self) -> usize {
        self.lock().used
    }

    pub fn len(&self) -> usize {
        self.lock().entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Inserts, evicting as needed; an entry larger than the whole budget is not kept.
    pub fn insert(&self, key: Key, outputs: Outputs, record: Record) {
        let bytes = outputs.byte_size().max(1);
        if bytes > self.budget {
            return;
        }
        let mut inner = self.lock();
        if let Some(old) = inner.entries.remove(&key) {
            inner.used -= old.bytes;
        }
        while inner.used + bytes > self.budget {
            let victim = inner
                .entries
                .iter()
                .min_by(|a, b| {
                    let va = a.1.record.seconds / a.1.bytes as f64;
                    let vb = b.1.record.seconds / b.1.bytes as f64;
                    va.total_cmp(&vb).then_with(|| a.0.cmp(b.0))
                })
                .map(|(k, _)| *k);
            match victim.and_then(|k| inner.entries.remove(&k)) {
                Some(e) => inner.used -= e.bytes,
                None => break,
            }
        }
        inner.used += bytes;
        inner.entries.insert(
            key,
            Entry {
                outputs,
                bytes,
                record,
            },
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::Artifact;

    fn secs(seconds: f64) -> Record {
        Record {
            seconds,
            ..Record::default()
        }
    }

    fn out(n: usize) -> Outputs {
        Outputs::new().with(
            "f",
            Artifact {
                path: String::new(),
                bytes: vec![0; n],
            },
        )
    }

    #[test]
    fn evicts_least_seconds_per_byte_first() {
        let c = MemoryCache::new(300);
        c.insert(Key([1; 32]), out(100), secs(10.0)); // 0.1 s/byte: dear to recompute
        c.insert(Key([2; 32]), out(100), secs(0.1)); // 0.001 s/byte: cheap
        c.insert(Key([3; 32]), out(100), secs(1.0)); // 0.01 s/byte
        c.insert(Key([4; 32]), out(100), secs(5.0)); // needs room: the cheapest (2) goes
        assert!(c.get(&Key([2; 32])).is_none());
        for k in [1, 3, 4] {
            assert!(c.get(&Key([k; 32])).is_some(), "{k}");
        }
        assert!(c.used() <= 300);
        c.insert(Key([5; 32]), out(1000), secs(1.0));
        assert!(
            c.get(&Key([5; 32])).is_none(),
            "larger than the budget: not kept"
        );
    }
}
