//! Writing values as NumPy arrays (`npy.write`); reading them back is each type's `*.array` kind.

pub mod write;
