//! A small little-endian binary codec for values' disk-cache encodings. Lengths are checked on
//! decode so a truncated entry is an error, never a panic.

use thiserror::Error;

#[derive(Debug, Error, PartialEq)]
#[error("cannot decode {what}: {message}")]
pub struct DecodeError {
    pub what: String,
    pub message: String,
}

impl DecodeError {
    pub fn new(what: &str, message: impl Into<String>) -> Self {
        DecodeError {
            what: what.into(),
            message: message.into(),
        }
    }
}

#[derive(Default)]
pub struct Encoder {
    pub bytes: Vec<u8>,
}

impl Encoder {
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.bytes.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.bytes.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.bytes.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64);
        self.bytes.extend_from_slice(s.as_bytes());
        self
    }
    pub fn raw(&mut self, b: &[u8]) -> &mut Self {
        self.u64(b.len() as u64);
        self.bytes.extend_from_slice(b);
        self
    }
    /// Length-prefixed little-endian f64s.
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u64(v.len() as u64);
        self.bytes.reserve(v.len() * 8);
        for x in v {
            self.bytes.extend_from_slice(&x.to_le_bytes());
        }
        self
    }
    /// Length-prefixed little-endian u32s.
    pub fn u32s(&mut self, v: &[u32]) -> &mut Self {
        self.u64(v.len() as u64);
        self.bytes.reserve(v.len() * 4);
        for x in v {
            self.bytes.extend_from_slice(&x.to_le_bytes());
        }
        self
    }
    pub fn f32s(&mut self, v: &[f32]) -> &mut Self {
        self.u64(v.len() as u64);
        if cfg!(target_endian = "little") {
            self.bytes.extend_from_slice(bytemuck::cast_slice(v));
        } else {
            self.bytes.reserve(v.len() * 4);
            for x in v {
                self.bytes.extend_from_slice(&x.to_le_bytes());
            }
        }
        self
    }
}

pub struct Decoder<'a> {
    what: &'static str,
    rest: &'a [u8],
}

impl<'a> Decoder<'a> {
    pub fn new(what: &'static str, bytes: &'a [u8]) -> Self {
        Decoder { what, rest: bytes }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        if self.rest.len() < n {
            return Err(DecodeError::new(
                self.what,
                format!("truncated: needed {n} more bytes, {} left", self.rest.len()),
            ));
        }
        let (head, tail) = self.rest.split_at(n);
        self.rest = tail;
        Ok(head)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn u64(&mut self) -> Result<u64, DecodeError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    fn len(&mut self, elem: usize) -> Result<usize, DecodeError> {
        let n = self.u64()?;
        usize::try_from(n)
            .ok()
            .filter(|n| n.checked_mul(elem).is_some_and(|b| b <= self.rest.len()))
            .ok_or_else(|| {
                DecodeError::new(
                    self.what,
                    format!("length {n} exceeds the {} bytes left", self.rest.len()),
                )
            })
    }
    pub fn str(&mut self) -> Result<String, DecodeError> {
        let n = self.len(1)?;
        String::from_utf8(self.take(n)?.to_vec())
            .map_err(|e| DecodeError::new(self.what, e.to_string()))
    }
    pub fn raw(&mut self) -> Result<Vec<u8>, DecodeError> {
        let n = self.len(1)?;
        Ok(self.take(n)?.to_vec())
    }
    /// [`Encoder::f64s`]'s values, the length checked against the bytes left.
    pub fn f64s(&mut self) -> Result<Vec<f64>, DecodeError> {
        let n = self.len(8)?;
        let bytes = self.take(n * 8)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }
    /// [`Encoder::u32s`]'s values, the length checked against the bytes left.
    pub fn u32s(&mut self) -> Result<Vec<u32>, DecodeError> {
        let n = self.len(4)?;
        let bytes = self.take(n * 4)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }
    pub fn f32s(&mut self) -> Result<Vec<f32>, DecodeError> {
        let n = self.len(4)?;
        let bytes = self.take(n * 4)?;
        let mut out = vec![0f32; n];
        if cfg!(target_endian = "little") {
            // The encoding is little-endian f32, i.e. the in-memory layout: one copy.
            bytemuck::cast_slice_mut::<f32, u8>(&mut out).copy_from_slice(bytes);
        } else {
            for (o, c) in out.iter_mut().zip(bytes.chunks_exact(4)) {
                *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
            }
        }
        Ok(out)
    }
    /// Fails unless every byte was consumed.
    pub fn finish(self) -> Result<(), DecodeError> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(DecodeError::new(
                self.what,
                format!("{} trailing bytes", self.rest.len()),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let mut e = Encoder::default();
        e.u32(7)
            .f64(-1.5)
            .str("héllo")
            .f32s(&[1.0, f32::INFINITY])
            .raw(&[9, 8]);
        let mut d = Decoder::new("t", &e.bytes);
        assert_eq!(d.u32().unwrap(), 7);
        assert_eq!(d.f64().unwrap(), -1.5);
        assert_eq!(d.str().unwrap(), "héllo");
        assert_eq!(d.f32s().unwrap(), vec![1.0, f32::INFINITY]);
        assert_eq!(d.raw().unwrap(), vec![9, 8]);
        d.finish().unwrap();
        for cut in 0..e.bytes.len() {
            let mut d = Decoder::new("t", &e.bytes[..cut]);
            let r = (|| {
                d.u32()?;
                d.f64()?;
                d.str()?;
                d.f32s()?;
                d.raw()
            })();
            assert!(r.is_err(), "cut at {cut} must fail");
        }
    }
}
