//! Reading and writing files: images (PNG, JPEG, HDR, EXR) and NPY arrays.

pub mod array_read;
pub mod formats;
pub mod image_read;
pub mod image_write;
pub mod npy_read;
pub mod npy_write;
