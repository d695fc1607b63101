//! Appearance-manifold values: `PointSet` (n points in D dimensions, f64, row-major), `KnnGraph`
//! (each point's k nearest neighbours and their distances, exact, ties broken by index) and
//! `Embedding` (n points in a few dimensions, with the eigenvalues that produced them).

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

fn read_f64s(d: &mut Decoder, n: usize) -> Result<Vec<f64>, DecodeError> {
    (0..n).map(|_| d.f64()).collect()
}

#[derive(Clone, Debug, PartialEq)]
pub struct PointSet {
    pub n: usize,
    pub dims: usize,
    /// n × dims, row-major.
    pub data: Vec<f64>,
}

impl PointSet {
    pub const TYPE: &'static str = "PointSet";

    pub fn point(&self, i: usize) -> &[f64] {
        &self.data[i * self.dims..(i + 1) * self.dims]
    }

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let n = d.u64()? as usize;
        let dims = d.u64()? as usize;
        let data = read_f64s(d, n * dims)?;
        Ok(Arc::new(PointSet { n, dims, data }))
    }
}

impl Value for PointSet {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 8
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.n as u64).u64(self.dims as u64);
        for x in &self.data {
            out.f64(*x);
        }
    }
    fn as_array_f64(&self) -> Option<(Vec<usize>, Vec<f64>)> {
        Some((vec![self.n, self.dims], self.data.clone()))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct KnnGraph {
    pub n: usize,
    pub k: usize,
    /// n × k neighbour indices, nearest first.
    pub neighbors: Vec<u32>,
    /// n × k Euclidean distances, matching `neighbors`.
    pub distances: Vec<f64>,
}

impl KnnGraph {
    pub const TYPE: &'static str = "KnnGraph";

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let n = d.u64()? as usize;
        let k = d.u64()? as usize;
        let neighbors = (0..n * k)
            .map(|_| d.u64().map(|v| v as u32))
            .collect::<Result<_, _>>()?;
        let distances = read_f64s(d, n * k)?;
        Ok(Arc::new(KnnGraph {
            n,
            k,
            neighbors,
            distances,
        }))
    }
}

impl Value for KnnGraph {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.neighbors.len() * 12
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.n as u64).u64(self.k as u64);
        for v in &self.neighbors {
            out.u64(*v as u64);
        }
        for x in &self.distances {
            out.f64(*x);
        }
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Embedding {
    pub n: usize,
    pub components: usize,
    /// n × components, row-major.
    pub data: Vec<f64>,
    /// The eigenvalues of the centred kernel behind each component, largest first.
    pub eigenvalues: Vec<f64>,
}

impl Embedding {
    pub const TYPE: &'static str = "Embedding";

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let n = d.u64()? as usize;
        let components = d.u64()? as usize;
        let data = read_f64s(d, n * components)?;
        let eigenvalues = read_f64s(d, components)?;
        Ok(Arc::new(Embedding {
            n,
            components,
            data,
            eigenvalues,
        }))
    }
}

impl Value for Embedding {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.data.len() * 8
    }
    fn encode(&self, out: &mut Encoder) {
        out.u64(self.n as u64).u64(self.components as u64);
        for x in self.data.iter().chain(&self.eigenvalues) {
            out.f64(*x);
        }
    }
    /// (n, components) f64: the NPY contract.
    fn as_array_f64(&self) -> Option<(Vec<usize>, Vec<f64>)> {
        Some((vec![self.n, self.components], self.data.clone()))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
