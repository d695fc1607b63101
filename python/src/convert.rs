//! Values between the engine and Python: a value with an array layout becomes a numpy array that
//! views the engine's own memory (the buffer protocol, read-only, no copy) or, for the f64 layouts
//! that a value computes on request, an array that owns that one copy; scalars become floats;
//! files become `{path: bytes}`. Arrays a Python node returns become typed values again.

use mesoflow_nodes::types::{HeightField, Image, NormalMap, PointSet};
use mesoflow_runtime::{Artifact, Artifacts, Scalar, ValueRef};
use pyo3::buffer::PyBuffer;
use pyo3::exceptions::PyBufferError;
use pyo3::ffi;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::ffi::{c_int, c_void, CString};
use std::sync::Arc;

enum Data {
    /// The value's own f32 array (`Value::as_array`), kept alive by this reference.
    Shared(ValueRef),
    /// An f64 layout the value computed (`Value::as_array_f64`).
    F64(Vec<f64>),
}

/// A read-only n-dimensional array exported through the buffer protocol; `numpy.asarray` wraps
/// it without copying.
#[pyclass(module = "mesoflow._native", frozen)]
pub struct ArrayBuffer {
    data: Data,
    shape: Vec<isize>,
    strides: Vec<isize>,
    #[pyo3(get)]
    type_name: String,
}

impl ArrayBuffer {
    fn new(data: Data, shape: &[usize], type_name: &str) -> ArrayBuffer {
        let item = match data {
            Data::Shared(_) => 4,
            Data::F64(_) => 8,
        };
        let mut strides = vec![item as isize; shape.len()];
        for d in (0..shape.len().saturating_sub(1)).rev() {
            strides[d] = strides[d + 1] * shape[d + 1] as isize;
        }
        ArrayBuffer {
            data,
            shape: shape.iter().map(|&d| d as isize).collect(),
            strides,
            type_name: type_name.into(),
        }
    }

    fn bytes(&self) -> (*const u8, usize, usize) {
        match &self.data {
            Data::Shared(v) => match v.as_array() {
                Some(a) => (a.data.as_ptr().cast(), a.data.len() * 4, 4),
                None => (std::ptr::null(), 0, 4),
            },
            Data::F64(d) => (d.as_ptr().cast(), d.len() * 8, 8),
        }
    }
}

#[pymethods]
impl ArrayBuffer {
    unsafe fn __getbuffer__(
        slf: Bound<'_, Self>,
        view: *mut ffi::Py_buffer,
        flags: c_int,
    ) -> PyResult<()> {
        if view.is_null() {
            return Err(PyBufferError::new_err("no view to fill"));
        }
        if flags & ffi::PyBUF_WRITABLE == ffi::PyBUF_WRITABLE {
            return Err(PyBufferError::new_err(
                "mesoflow values are read-only; copy the array (numpy.array(x)) to change it",
            ));
        }
        let this = slf.get();
        let (ptr, len, item) = this.bytes();
        let format = if item == 4 { "f" } else { "d" };
        // SAFETY: `view` is the non-null Py_buffer that Python asked us to fill; the pointers
        // stored in it (data, shape, strides) live inside `slf`, which the view holds a
        // reference to (`obj`) until `__releasebuffer__`, and `frozen` means they never move.
        unsafe {
            (*view).obj = slf.clone().into_any().into_ptr();
            (*view).buf = ptr as *mut c_void;
            (*view).len = len as isize;
            (*view).readonly = 1;
            (*view).itemsize = item as isize;
            (*view).format = if flags & ffi::PyBUF_FORMAT == ffi::PyBUF_FORMAT {
                CString::new(format)
                    .map(CString::into_raw)
                    .unwrap_or(std::ptr::null_mut())
            } else {
                std::ptr::null_mut()
            };
            (*view).ndim = this.shape.len() as c_int;
            (*view).shape = if flags & ffi::PyBUF_ND == ffi::PyBUF_ND {
                this.shape.as_ptr() as *mut isize
            } else {
                std::ptr::null_mut()
            };
            (*view).strides = if flags & ffi::PyBUF_STRIDES == ffi::PyBUF_STRIDES {
                this.strides.as_ptr() as *mut isize
            } else {
                std::ptr::null_mut()
            };
            (*view).suboffsets = std::ptr::null_mut();
            (*view).internal = std::ptr::null_mut();
        }
        Ok(())
    }

    unsafe fn __releasebuffer__(&self, view: *mut ffi::Py_buffer) {
        // SAFETY: the format string was made by `CString::into_raw` in `__getbuffer__` (or is
        // null), and is released exactly once, here.
        unsafe {
            if !view.is_null() && !(*view).format.is_null() {
                drop(CString::from_raw((*view).format));
            }
        }
    }

    /// The array's shape.
    #[getter]
    fn shape(&self) -> Vec<isize> {
        self.shape.clone()
    }
}

/// A value with no array layout (a mesh, a material, a kNN graph): its type and size.
#[pyclass(module = "mesoflow._native", frozen, get_all)]
pub struct Opaque {
    pub type_name: String,
    pub bytes: usize,
}

#[pymethods]
impl Opaque {
    fn __repr__(&self) -> String {
        format!(
            "<mesoflow {} value, {} bytes; write it with a node (npy.write, mesh.write) to read it>",
            self.type_name, self.bytes
        )
    }
}

fn numpy_of<'py>(py: Python<'py>, buf: ArrayBuffer) -> PyResult<Bound<'py, PyAny>> {
    let np = py.import("numpy")?;
    np.call_method1("asarray", (Bound::new(py, buf)?,))
}

/// A value as Python sees it (see the module's doc).
pub fn to_python<'py>(py: Python<'py>, v: &ValueRef) -> PyResult<Bound<'py, PyAny>> {
    if let Some(x) = v.as_scalar() {
        return Ok(x.into_pyobject(py)?.into_any());
    }
    if let Some((shape, data)) = v.as_array_f64() {
        return numpy_of(py, ArrayBuffer::new(Data::F64(data), &shape, v.type_name()));
    }
    if let Some(a) = v.as_array() {
        let shape = a.shape.clone();
        return numpy_of(
            py,
            ArrayBuffer::new(Data::Shared(v.clone()), &shape, v.type_name()),
        );
    }
    let files: Option<Vec<&Artifact>> = v
        .as_any()
        .downcast_ref::<Artifact>()
        .map(|a| vec![a])
        .or_else(|| {
            v.as_any()
                .downcast_ref::<Artifacts>()
                .map(|a| a.files.iter().collect())
        });
    if let Some(files) = files {
        let d = PyDict::new(py);
        for f in files {
            d.set_item(&f.path, PyBytes::new(py, &f.bytes))?;
        }
        return Ok(d.into_any());
    }
    Ok(Bound::new(
        py,
        Opaque {
            type_name: v.type_name().into(),
            bytes: v.byte_size(),
        },
    )?
    .into_any())
}

/// The types a Python node may return, with the array shapes each accepts.
pub const RETURNABLE: &[(&str, &str)] = &[
    ("Scalar", "a float"),
    ("Image", "(H, W) or (H, W, C) with C = 1, 3 or 4"),
    ("HeightField", "(H, W)"),
    ("NormalMap", "(H, W, 3)"),
    ("PointSet", "(n, D)"),
];

fn shaped<T: pyo3::buffer::Element + Copy>(
    obj: &Bound<'_, PyAny>,
) -> Result<(Vec<usize>, Vec<T>), String> {
    let py = obj.py();
    let buf = PyBuffer::<T>::get(obj).map_err(|e| e.to_string())?;
    let shape = buf.shape().to_vec();
    // The copy made here against the memory budget (issue 43: what a Python node returned was
    // never held to it).
    let bytes = buf.len_bytes() as u64;
    let budget = mesoflow_nodes::support::memory::budget_bytes(None);
    if bytes > budget {
        return Err(format!(
            "the array of shape {shape:?} is {:.2} GB, over the memory budget of {:.2} GB (MESOFLOW_MEMORY_BUDGET_GB)",
            bytes as f64 / 1e9,
            budget as f64 / 1e9
        ));
    }
    let data = buf.to_vec(py).map_err(|e| e.to_string())?;
    Ok((shape, data))
}

fn finite<T: Copy + Into<f64>>(data: &[T]) -> Result<(), String> {
    match data.iter().position(|&v| !v.into().is_finite()) {
        Some(i) => Err(format!("element {i} (row-major) is not finite")),
        None => Ok(()),
    }
}

/// A Python node's returned object as a value of port type `ty`. Arrays arrive as C-contiguous
/// float32 (float64 for point sets): the Python side converts them.
pub fn from_python(obj: &Bound<'_, PyAny>, ty: &str) -> Result<ValueRef, String> {
    let bad_shape = |shape: &[usize]| {
        let want = RETURNABLE
            .iter()
            .find(|(t, _)| *t == ty)
            .map_or("?", |(_, s)| *s);
        let got: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
        format!(
            "{ty} needs an array of shape {want}; got shape ({})",
            got.join(", ")
        )
    };
    match ty {
        "Scalar" => {
            let x: f64 = obj
                .extract()
                .map_err(|_| format!("a Scalar is a float; got {}", type_name(obj)))?;
            if !x.is_finite() {
                return Err(format!("the Scalar is {x}, not a finite number"));
            }
            Ok(Arc::new(Scalar(x)))
        }
        "Image" | "HeightField" | "NormalMap" => {
            let (shape, data) = shaped::<f32>(obj)?;
            finite(&data)?;
            if data.is_empty() {
                return Err(format!("{ty}: the array is empty (shape {shape:?})"));
            }
            match (ty, shape.as_slice()) {
                ("Image", &[h, w]) => Ok(Arc::new(Image {
                    width: w,
                    height: h,
                    channels: 1,
                    data,
                })),
                ("Image", &[h, w, c]) if matches!(c, 1 | 3 | 4) => Ok(Arc::new(Image {
                    width: w,
                    height: h,
                    channels: c,
                    data,
                })),
                ("HeightField", &[h, w]) => Ok(Arc::new(HeightField {
                    width: w,
                    height: h,
                    data,
                })),
                ("NormalMap", &[h, w, 3]) => Ok(Arc::new(NormalMap {
                    width: w,
                    height: h,
                    data,
                })),
                _ => Err(bad_shape(&shape)),
            }
        }
        "PointSet" => {
            let (shape, data) = shaped::<f64>(obj)?;
            finite(&data)?;
            match shape.as_slice() {
                &[n, dims] if n > 0 && dims > 0 => Ok(Arc::new(PointSet { n, dims, data })),
                _ => Err(bad_shape(&shape)),
            }
        }
        other => Err(format!(
            "a Python node cannot return a {other}; it can return {}",
            RETURNABLE
                .iter()
                .map(|(t, _)| *t)
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "an object".into())
}
