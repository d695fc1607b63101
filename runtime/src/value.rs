//! Values flowing between nodes. The runtime sees them only through [`Value`]: a type name (the
//! port type), a size for the memory budget, an encoding for the disk cache, and two optional
//! views: a scalar (reported as a metric) and a dense f32 array (for generic writers like NPY).

use crate::codec::{DecodeError, Decoder, Encoder};
use std::any::Any;
use std::fmt::Debug;
use std::sync::Arc;

/// A dense row-major f32 array: the generic view behind `npy.write`.
pub struct ArrayView<'a> {
    pub shape: Vec<usize>,
    pub data: &'a [f32],
}

pub trait Value: Any + Send + Sync + Debug {
    /// The port type name, e.g. "HeightField".
    fn type_name(&self) -> &'static str;
    /// Approximate bytes held in memory.
    fn byte_size(&self) -> usize;
    /// Appends the disk-cache encoding; the registry's decoder for `type_name` inverts it.
    fn encode(&self, out: &mut Encoder);
    /// Scalars are reported as metrics in the run report.
    fn as_scalar(&self) -> Option<f64> {
        None
    }
    fn as_array(&self) -> Option<ArrayView<'_>> {
        None
    }
    /// A dense row-major f64 array (shape, data), for values whose precision an f32 view would
    /// lose (diffusion profiles span ten decades of radius); `npy.write` prefers it.
    fn as_array_f64(&self) -> Option<(Vec<usize>, Vec<f64>)> {
        None
    }
    /// JSON that must travel with the array for it to be interpreted (the MDF's view directions);
    /// `npy.write` writes it beside the `.npy` as `<name>.json`.
    fn array_sidecar(&self) -> Option<String> {
        None
    }
    fn as_any(&self) -> &dyn Any;
}

pub type ValueRef = Arc<dyn Value>;

/// Decodes one type's encoding.
pub type DecodeFn = fn(&mut Decoder) -> Result<ValueRef, DecodeError>;

/// A number, such as an error metric.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scalar(pub f64);

impl Scalar {
    pub const TYPE: &'static str = "Scalar";
    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        Ok(Arc::new(Scalar(d.f64()?)))
    }
}

impl Value for Scalar {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        8
    }
    fn encode(&self, out: &mut Encoder) {
        out.f64(self.0);
    }
    fn as_scalar(&self) -> Option<f64> {
        Some(self.0)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// A file a node produced (an encoded PNG, an NPY array). Nodes stay pure: they return the bytes,
/// and the runtime writes them under the run's output folder, whether the value was computed or
/// came from a cache.
#[derive(Clone, Debug, PartialEq)]
pub struct Artifact {
    /// Relative paths are relative to the output folder.
    pub path: String,
    pub bytes: Vec<u8>,
}

impl Artifact {
    pub const TYPE: &'static str = "File";
    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        Ok(Arc::new(Artifact {
            path: d.str()?,
            bytes: d.raw()?,
        }))
    }
}

impl Value for Artifact {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.bytes.len() + self.path.len()
    }
    fn encode(&self, out: &mut Encoder) {
        out.str(&self.path).raw(&self.bytes);
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// A set of files a node produced (a folder of images), written like [`Artifact`]s.
#[derive(Clone, Debug, PartialEq)]
pub struct Artifacts {
    pub files: Vec<Artifact>,
}

impl Artifacts {
    pub const TYPE: &'static str = "Files";
    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let n = d.u64()? as usize;
        let mut files = Vec::with_capacity(n.min(1 << 20));
        for _ in 0..n {
            files.push(Artifact {
                path: d.str()?,
                bytes: d.raw()?,
            });
        }
        Ok(Arc::new(Artifacts { files }))
    }
}

impl Value for Artifacts {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.files.iter().map(|a| a.byte_size()).sum()
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.files.len() as u64);
        for a in &self.files {
            a.encode(out);
        }
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
