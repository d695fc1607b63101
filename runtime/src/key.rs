//! Merkle cache keys (design brief): key(node) = blake3(key-scheme version, kind, kind version,
//! canonical params, input keys, content hashes of files read). Nothing machine-specific enters.

use serde_json::Value;
use std::fmt;

/// Bump when the way keys are computed changes; every old cache entry then misses.
pub const KEY_SCHEME: u32 = 3;

#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Key(pub [u8; 32]);

impl Key {
    pub fn hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }
    pub fn from_hex(s: &str) -> Option<Key> {
        if s.len() != 64 {
            return None;
        }
        let mut k = [0u8; 32];
        for (i, b) in k.iter_mut().enumerate() {
            *b = u8::from_str_radix(s.get(2 * i..2 * i + 2)?, 16).ok()?;
        }
        Some(Key(k))
    }
}

impl fmt::Debug for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Key({})", &self.hex()[..12])
    }
}

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.hex())
    }
}

/// Canonical text of a JSON value: sorted object keys, no whitespace, integers in decimal and
/// every other number by its f64 bit pattern (so 0.1 and the next float up differ, and no float
/// formatting subtleties can make two machines disagree).
pub fn canonical(v: &Value) -> String {
    let mut out = String::new();
    write_canonical(v, &mut out);
    out
}

fn write_canonical(v: &Value, out: &mut String) {
    match v {
        Value::Null => out.push_str("null"),
        Value::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                out.push_str(&format!("i{i}"));
            } else if let Some(u) = n.as_u64() {
                out.push_str(&format!("i{u}"));
            } else {
                out.push_str(&format!(
                    "f{:016x}",
                    n.as_f64().unwrap_or(f64::NAN).to_bits()
                ));
            }
        }
        Value::String(s) => out.push_str(&serde_json::to_string(s).unwrap_or_default()),
        Value::Array(a) => {
            out.push('[');
            for (i, x) in a.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                write_canonical(x, out);
            }
            out.push(']');
        }
        Value::Object(m) => {
            let mut keys: Vec<&String> = m.keys().collect();
            keys.sort();
            out.push('{');
            for (i, k) in keys.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                out.push_str(&serde_json::to_string(k).unwrap_or_default());
                out.push(':');
                write_canonical(&m[k], out);
            }
            out.push('}');
        }
    }
}

/// What a node's key is made of.
pub struct KeyParts<'a> {
    pub kind: &'a str,
    pub version: u32,
    pub params: &'a Value,
    /// (input port, upstream key, upstream output port), sorted by input port.
    pub inputs: Vec<(&'a str, Key, &'a str)>,
    /// Each file's name (its last path component) and the blake3 of its contents, in the order
    /// the node declared them. The name enters because readers take meaning from it (UBO2003
    /// angles are in the file names); the folder does not, so keys stay machine-independent.
    pub files: Vec<(String, [u8; 32])>,
    /// The path a GPU-capable kind takes, `"cpu"` or `"gpu"`: the two compute the same thing to
    /// tested tolerances, not to the bit, so a value of one never stands for the other. `None`
    /// for CPU-only kinds. The adapter's name stays out, so keys match across machines.
    pub device: Option<&'a str>,
}

pub fn compute(parts: &KeyParts) -> Key {
    let mut h = blake3::Hasher::new();
    let mut field = |bytes: &[u8]| {
        h.update(&(bytes.len() as u64).to_le_bytes());
        h.update(bytes);
    };
    field(&KEY_SCHEME.to_le_bytes());
    field(parts.kind.as_bytes());
    field(&parts.version.to_le_bytes());
    field(canonical(parts.params).as_bytes());
    let mut inputs = parts.inputs.clone();
    inputs.sort_by(|a, b| a.0.cmp(b.0));
    field(&(inputs.len() as u64).to_le_bytes());
    for (port, key, from_port) in inputs {
        field(port.as_bytes());
        field(&key.0);
        field(from_port.as_bytes());
    }
    field(&(parts.files.len() as u64).to_le_bytes());
    for (name, hash) in &parts.files {
        field(name.as_bytes());
        field(hash);
    }
    if let Some(device) = parts.device {
        field(device.as_bytes());
    }
    Key(*h.finalize().as_bytes())
}

/// Content hash of a file, streamed so large inputs are not held in memory. Only regular files:
/// a device or a pipe (`/dev/zero`, a FIFO) would never end.
pub fn hash_file(path: &std::path::Path) -> std::io::Result<[u8; 32]> {
    let file = std::fs::File::open(path)?;
    if !file.metadata()?.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a device, pipe or folder cannot be read as input)",
        ));
    }
    let mut h = blake3::Hasher::new();
    h.update_reader(file)?;
    Ok(*h.finalize().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn key(params: Value) -> Key {
        compute(&KeyParts {
            kind: "k",
            version: 1,
            params: &params,
            inputs: vec![],
            files: vec![],
            device: None,
        })
    }

    #[test]
    fn canonical_sorts_keys_and_encodes_float_bits() {
        assert_eq!(
            canonical(&json!({"b": 1, "a": [true, null, "x"]})),
            r#"{"a":[true,null,"x"],"b":i1}"#
        );
        assert_eq!(
            canonical(&json!(0.5)),
            format!("f{:016x}", 0.5f64.to_bits())
        );
    }

    #[test]
    fn last_bit_of_a_float_changes_the_key() {
        let x = 0.1f64;
        let y = f64::from_bits(x.to_bits() + 1);
        assert_ne!(key(json!({ "depth": x })), key(json!({ "depth": y })));
    }

    #[test]
    fn parameter_order_does_not_change_the_key() {
        let a: Value = serde_json::from_str(r#"{"a":1,"b":2.5}"#).unwrap();
        let b: Value = serde_json::from_str(r#"{"b":2.5,"a":1}"#).unwrap();
        assert_eq!(key(a), key(b));
    }

    #[test]
    fn inputs_and_version_enter_the_key() {
        let p = json!({});
        let base = KeyParts {
            kind: "k",
            version: 1,
            params: &p,
            inputs: vec![],
            files: vec![],
            device: None,
        };
        let k0 = compute(&base);
        let k1 = compute(&KeyParts { version: 2, ..base });
        let base = KeyParts {
            kind: "k",
            version: 1,
            params: &p,
            inputs: vec![("x", k0, "out")],
            files: vec![],
            device: None,
        };
        let k2 = compute(&base);
        let k3 = compute(&KeyParts {
            inputs: vec![("x", k0, "other")],
            ..base
        });
        let content = [9u8; 32];
        let named = |name: &str| {
            compute(&KeyParts {
                kind: "k",
                version: 1,
                params: &p,
                inputs: vec![],
                files: vec![(name.into(), content)],
                device: None,
            })
        };
        // The same bytes under another name: another key (names carry meaning for readers).
        let (k4, k5) = (
            named("tl000_pl000_tv000_pv000.png"),
            named("tl015_pl000_tv000_pv000.png"),
        );
        let on = |device| {
            compute(&KeyParts {
                kind: "k",
                version: 1,
                params: &p,
                inputs: vec![],
                files: vec![],
                device: Some(device),
            })
        };
        let (k6, k7) = (on("cpu"), on("gpu"));
        let all = [k0, k1, k2, k3, k4, k5, k6, k7];
        for i in 0..all.len() {
            for j in 0..i {
                assert_ne!(all[i], all[j]);
            }
        }
        assert_eq!(Key::from_hex(&k2.hex()), Some(k2));
    }
}
