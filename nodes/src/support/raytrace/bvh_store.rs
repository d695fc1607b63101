//! A large mesh's BVH kept across processes, in the run's disk cache
//! (`NodeContext::store_derived`): a second process rendering the same surface (a camera move
//! from the command line, the planner's candidates, a cluster's units) reads it instead of
//! building it again (seconds for a displaced surface of millions of triangles).
//!
//! The entry is keyed by the mesh's hash and the executable's build (the BVH builder and the
//! layout of its nodes are the build's), and decoded with every index checked against the node
//! and triangle counts, so an entry that does not fit is rebuilt rather than traversed. The
//! builder is deterministic, so a stored BVH is the one a build would make: the same bits.

use crate::types::Mesh;
use obvhs::aabb::Aabb;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::triangle::Triangle;

/// What the disk cache counts these entries as (`mesoflow cache stats`).
pub const KIND: &str = "raytrace.bvh";

/// The encoding's version, part of the key.
const FORMAT: u32 = 1;

/// The stored BVH's key: its mesh's hash, this encoding and the build that made it (the
/// executable's hash, and the bytes of a small BVH built here: where the executable is
/// another's, as Python's, a builder or layout that changed still changes the key).
pub fn key(mesh_hash: &[u8; 32]) -> [u8; 32] {
    let mut h = blake3::Hasher::new();
    h.update(&FORMAT.to_le_bytes());
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    h.update(mesoflow_runtime::producer::build_id().as_bytes());
    h.update(builder_fingerprint());
    h.update(mesh_hash);
    *h.finalize().as_bytes()
}

/// The encoding of the BVH of a fixed fan of 64 triangles, made once a process.
fn builder_fingerprint() -> &'static [u8] {
    static PRINT: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    PRINT.get_or_init(|| {
        let tris: Vec<Triangle> = (0..64)
            .map(|i| {
                let a = i as f32 * 0.1;
                Triangle {
                    v0: glam::Vec3A::ZERO,
                    v1: glam::Vec3A::new(a.cos(), a.sin(), 0.01 * i as f32),
                    v2: glam::Vec3A::new((a + 0.1).cos(), (a + 0.1).sin(), 0.5),
                }
            })
            .collect();
        encode(&build_triangles(&tris)).unwrap_or_default()
    })
}

/// The BVH of `mesh`'s triangles, as every tracer builds it.
pub fn build(mesh: &Mesh) -> CwBvh {
    let v = |i: usize| {
        let q = mesh.positions[i];
        glam::Vec3A::new(q[0], q[1], q[2])
    };
    let tris: Vec<Triangle> = (0..mesh.triangles())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            Triangle {
                v0: v(a),
                v1: v(b),
                v2: v(c),
            }
        })
        .collect();
    build_triangles(&tris)
}

/// The BVH of `tris` (its parameters are part of what [`key`] fingerprints). obvhs'
/// `very_fast_build` (PLOC at its shortest search, little reinsertion): on the bench torus's
/// 4 M displaced triangles it built in 2.7–2.8 s against `medium_build`'s 3.8–4.2 s and traced
/// 16 samples a pixel in 0.66–0.76 s against 0.85–0.93 s (`fast_build` 3.4 s and 0.76–0.82 s,
/// `fastest_build` 3.4 s and 0.79–0.84 s; three renders each, measured once): the surface's
/// triangles are small and evenly spread, where a longer search buys a tree no faster to trace.
fn build_triangles(tris: &[Triangle]) -> CwBvh {
    obvhs::cwbvh::builder::build_cwbvh_from_tris(
        tris,
        obvhs::BvhBuildParams::very_fast_build(),
        &mut std::time::Duration::default(),
    )
}

/// Whether a node's child slot `meta` is an internal node: 001 in the high bits and its slot
/// index plus 24 in the low five (a leaf's low five bits are its first primitive's offset,
/// under 24, and its high three its count in unary).
fn internal_slot(meta: u8) -> bool {
    meta >> 5 == 1 && meta & 31 >= 24
}

/// The header's words: the flags, then the three counts.
const HEAD: usize = 4 * 8;

/// `bvh` as bytes: the flags (spatial splits, exact boxes), the counts of nodes, primitive
/// indices and exact boxes, the whole box, then the three arrays as they lie in memory
/// (little-endian machines only: `None` elsewhere, and nothing is stored).
pub fn encode(bvh: &CwBvh) -> Option<Vec<u8>> {
    if cfg!(target_endian = "big") {
        return None;
    }
    let exact: &[Aabb] = bvh.exact_node_aabbs.as_deref().unwrap_or(&[]);
    let mut out = Vec::new();
    for word in [
        u64::from(bvh.uses_spatial_splits) | (u64::from(bvh.exact_node_aabbs.is_some()) << 1),
        bvh.nodes.len() as u64,
        bvh.primitive_indices.len() as u64,
        exact.len() as u64,
    ] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(bytemuck::bytes_of(&bvh.total_aabb));
    out.extend_from_slice(bytemuck::cast_slice(&bvh.nodes));
    out.extend_from_slice(bytemuck::cast_slice(&bvh.primitive_indices));
    out.extend_from_slice(bytemuck::cast_slice(exact));
    Some(out)
}

/// The BVH `encode` wrote, for a mesh of `triangles` triangles; `None` for bytes of another
/// length or any index out of range (a node's children, a leaf's primitives, a primitive's
/// triangle).
pub fn decode(bytes: &[u8], triangles: usize) -> Option<CwBvh> {
    if cfg!(target_endian = "big") || bytes.len() < HEAD {
        return None;
    }
    let word = |i: usize| {
        let w = u64::from_le_bytes(bytes[8 * i..8 * i + 8].try_into().ok()?);
        usize::try_from(w).ok()
    };
    let (flags, nodes, prims, exact) = (word(0)?, word(1)?, word(2)?, word(3)?);
    let box_len = std::mem::size_of::<Aabb>();
    let node_len = std::mem::size_of::<CwBvhNode>();
    let want = HEAD
        .checked_add(box_len)?
        .checked_add(nodes.checked_mul(node_len)?)?
        .checked_add(prims.checked_mul(4)?)?
        .checked_add(exact.checked_mul(box_len)?)?;
    if bytes.len() != want || flags > 3 {
        return None;
    }
    let mut at = HEAD;
    let mut take = |len: usize| {
        let part = &bytes[at..at + len];
        at += len;
        part
    };
    let mut total_aabb = Aabb::default();
    bytemuck::bytes_of_mut(&mut total_aabb).copy_from_slice(take(box_len));
    let mut node_list = vec![CwBvhNode::default(); nodes];
    bytemuck::cast_slice_mut(&mut node_list).copy_from_slice(take(nodes * node_len));
    let mut primitive_indices = vec![0u32; prims];
    bytemuck::cast_slice_mut(&mut primitive_indices).copy_from_slice(take(prims * 4));
    let mut exact_boxes = vec![Aabb::default(); exact];
    bytemuck::cast_slice_mut(&mut exact_boxes).copy_from_slice(take(exact * box_len));
    let fits = node_list.iter().all(|n| {
        let children = n.imask.count_ones() as usize;
        let internal_fits = n.imask == 0 || (n.child_base_idx as usize) + children <= nodes;
        let leaves_fit = n.child_meta.iter().all(|&m| {
            if m == 0 || internal_slot(m) {
                return true;
            }
            let count = (m >> 5).count_ones() as usize;
            n.primitive_base_idx as usize + (m & 31) as usize + count <= prims
        });
        internal_fits && leaves_fit
    });
    let triangles_fit = primitive_indices.iter().all(|&p| (p as usize) < triangles);
    if !(fits && triangles_fit) || nodes == 0 {
        return None;
    }
    Some(CwBvh {
        nodes: node_list,
        primitive_indices,
        total_aabb,
        exact_node_aabbs: (flags & 2 != 0).then_some(exact_boxes),
        uses_spatial_splits: flags & 1 != 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(segments: [u32; 2]) -> crate::types::Mesh {
        crate::mesh::primitive::build(&crate::mesh::primitive::Params {
            shape: crate::mesh::primitive::Shape::Sphere,
            size: 1.0,
            minor: 0.0,
            segments,
        })
        .expect("a sphere")
    }

    fn same(a: &CwBvh, b: &CwBvh) -> bool {
        a.nodes == b.nodes
            && a.primitive_indices == b.primitive_indices
            && a.total_aabb == b.total_aabb
            && a.exact_node_aabbs == b.exact_node_aabbs
            && a.uses_spatial_splits == b.uses_spatial_splits
    }

    #[test]
    fn a_bvh_decodes_to_itself_and_bytes_that_do_not_fit_are_refused() {
        let mesh = sphere([64, 32]);
        let built = build(&mesh);
        let bytes = encode(&built).expect("a little-endian machine");
        let back = decode(&bytes, mesh.triangles()).expect("decodes");
        assert!(same(&built, &back));
        // Cut short, one byte too many, or for a mesh with fewer triangles than it indexes.
        assert!(decode(&bytes[..bytes.len() - 1], mesh.triangles()).is_none());
        assert!(decode(&[bytes.as_slice(), &[0]].concat(), mesh.triangles()).is_none());
        assert!(decode(&bytes, mesh.triangles() / 2).is_none());
        // A node whose children lie past the end.
        let mut bad = built.clone();
        bad.nodes[0].child_base_idx = bad.nodes.len() as u32;
        assert!(decode(&encode(&bad).unwrap(), mesh.triangles()).is_none());
        // A leaf whose primitives lie past the end.
        let mut bad = built.clone();
        let leaf = bad
            .nodes
            .iter()
            .position(|n| n.child_meta.iter().any(|&m| m != 0 && !internal_slot(m)))
            .expect("a node with a leaf");
        bad.nodes[leaf].primitive_base_idx = bad.primitive_indices.len() as u32;
        assert!(decode(&encode(&bad).unwrap(), mesh.triangles()).is_none());
    }
}
