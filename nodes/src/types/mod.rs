//! The domain value types that flow between nodes, each with its disk-cache encoding.

mod brdf_map;
mod btf;
mod btf_basis;
mod heightfield;
mod image;
mod manifold;
mod mdf;
mod mesh;
mod scattering;
mod sss_lighting;
pub use image::{linear_to_srgb, srgb_to_linear};
mod normal_map;

pub use brdf_map::{BrdfMap, WARD_PARAMS};
pub use btf::{Btf, Direction, DirectionPair};
pub use btf_basis::{BasisBlock, BtfBasis, Centring, ColorSpace};
pub use heightfield::HeightField;
pub use image::Image;
pub use manifold::{Embedding, KnnGraph, PointSet};
pub use mdf::Mdf;
pub use mesh::Mesh;
pub use normal_map::NormalMap;
pub use scattering::{DiffusionProfile, ScatteringMaterial};
pub use sss_lighting::{BodyChannel, BodyGrid, LightBounced, SssLighting};

/// Every array-like type, i.e. what `npy.write` accepts.
pub const ARRAY_TYPES: &[&str] = &[
    HeightField::TYPE,
    Image::TYPE,
    NormalMap::TYPE,
    Btf::TYPE,
    Mdf::TYPE,
    DiffusionProfile::TYPE,
    PointSet::TYPE,
    Embedding::TYPE,
    BrdfMap::TYPE,
];

/// Registers the decoders of every type in this module.
pub fn register(r: &mut mesoflow_runtime::Registry) {
    r.register_type(Btf::TYPE, Btf::decode);
    r.register_type(BtfBasis::TYPE, BtfBasis::decode);
    r.register_type(HeightField::TYPE, HeightField::decode);
    r.register_type(Image::TYPE, Image::decode);
    r.register_type(NormalMap::TYPE, NormalMap::decode);
    r.register_type(Mdf::TYPE, Mdf::decode);
    r.register_type(Mesh::TYPE, Mesh::decode);
    r.register_type(ScatteringMaterial::TYPE, ScatteringMaterial::decode);
    r.register_type(DiffusionProfile::TYPE, DiffusionProfile::decode);
    r.register_type(SssLighting::TYPE, SssLighting::decode);
    r.register_type(PointSet::TYPE, PointSet::decode);
    r.register_type(KnnGraph::TYPE, KnnGraph::decode);
    r.register_type(Embedding::TYPE, Embedding::decode);
    r.register_type(BrdfMap::TYPE, BrdfMap::decode);
}
