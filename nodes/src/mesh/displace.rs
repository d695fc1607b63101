//! `mesh.displace`: the true mesostructure as a mesh — the input mesh's surface moved along its
//! normal by a periodic height field laid over it with `tiling`, in exactly the convention
//! `render.mesh` and `mdf.tabulate` use: the mesh is the top of a shell of world thickness
//! `shell`, the height field's top (its highest sample, or its lowest plus `depth`) lies on it
//! and one texel of height is `shell / depth` world units below it, and the tile is looked up
//! with `render.mesh`'s texel convention (bilinear between texel centres, v up the image). What
//! `render.reference` renders as the truth, and what `mesh.write` hands to other renderers.
//!
//! Every triangle is split into n² triangles on a regular barycentric grid, n the same for all
//! triangles (so neighbours share their edge vertices and the surface has no cracks): enough that
//! the longest triangle edge gets `density` vertices per texel it spans. Shared vertices are made
//! once, from the edge's endpoints in a fixed order, so both neighbours see the same bits. Where
//! the input mesh duplicates a vertex at a texture seam (the same position to a millionth of its
//! size, other texture coordinates), both copies are displaced from the same position and normal
//! and the seam's edges are walked in the same direction, so with a whole number of tiles across
//! the seam the two sides meet exactly. Normals are the displaced surface's, averaged over every
//! triangle that meets a position.

use crate::render::material::texel_taps;
use crate::support::geometry::{add, cross, mul, normalize, sub, V3};
use crate::types::{HeightField, Mesh};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

crate::view_params! {
    #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
    #[serde(default, deny_unknown_fields)]
    pub struct Params {
        view { tiling }
        /// Shell thickness in world units (as `render.mesh`'s): the depth the height range maps to.
        #[schemars(range(min = 0.0))]
        pub shell: f64 = 0.05,
        /// Shell thickness in height-field texels, measured from the lowest sample (as
        /// `mdf.tabulate`'s `depth`); default the height range, the tightest shell.
        #[schemars(range(min = 0.0, max = 1e6))]
        pub depth: Option<f64> = None,
        /// Vertices per texel along the longest triangle edge (0.25 to 16).
        #[schemars(range(min = 0.25, max = 16.0))]
        pub density: f64 = 1.0,
        /// Refuse to make more triangles than this.
        #[schemars(range(min = 1, max = 200000000))]
        pub max_triangles: u64 = 20_000_000,
    }
}

pub struct Displace;

impl Node for Displace {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "mesh.displace",
            version: 1,
            doc: "The true mesostructure as a mesh: the mesh moved along its normal by a periodic height field (render.mesh's tiling and shell convention), subdivided to `density` vertices per texel.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the macro surface (the shell's top), with texture coordinates"),
                Port::input("height", HeightField::TYPE, "periodic tile, heights in texels"),
            ],
            outputs: vec![
                Port::output("mesh", Mesh::TYPE, "the displaced surface"),
                Port::output("subdivision", "Scalar", "n: each input triangle became n² triangles"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        if !p.tiling.iter().all(|t| t.is_finite() && *t > 0.0) {
            return Err(NodeError::param("tiling", "must be positive"));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        if mesh.uvs.is_empty() && !mesh.positions.is_empty() {
            return Err(NodeError::input(
                "mesh",
                "needs texture coordinates (mesh.read's `generate_uvs` can make them)",
            ));
        }
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let hf = inputs.get::<HeightField>("height")?;
        if hf.width == 0 || hf.height == 0 || hf.data.iter().any(|h| !h.is_finite()) {
            return Err(NodeError::input(
                "height",
                "expected a non-empty field of finite heights",
            ));
        }
        let (lo, hi) = hf.min_max();
        let (lo, hi) = (lo as f64, hi as f64);
        let depth = match p.depth {
            Some(d) if d + 1e-9 < hi - lo => {
                return Err(NodeError::param(
                    "depth",
                    format!(
                    "{d} texels is less than the height range {:.4}: the shell must hold the tile",
                    hi - lo
                ),
                ))
            }
            Some(d) => d,
            None => hi - lo,
        };
        let n = subdivision(mesh, [hf.width, hf.height], p)?;
        ctx.progress(0, 1);
        let out = displace(mesh, hf, p, n, lo + depth, depth);
        ctx.progress(1, 1);
        Ok(Outputs::new()
            .with("mesh", out)
            .with("subdivision", Scalar(n as f64)))
    }
}

/// The grid size n: the longest edge, in texels, times `density`, rounded up; refused past
/// `max_triangles`.
fn subdivision(mesh: &Mesh, texels: [usize; 2], p: &Params) -> Result<usize, NodeError> {
    let mut longest = 0f64;
    for t in 0..mesh.triangles() {
        let c = mesh.corners(t);
        for (a, b) in [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])] {
            let d = [0, 1].map(|k| {
                (mesh.uvs[a][k] as f64 - mesh.uvs[b][k] as f64) * p.tiling[k] * texels[k] as f64
            });
            longest = longest.max(d[0].hypot(d[1]));
        }
    }
    let n = (longest * p.density).ceil().max(1.0);
    let triangles = mesh.triangles() as f64 * n * n;
    if !(n.is_finite() && triangles <= p.max_triangles as f64) {
        return Err(NodeError::param(
            "density",
            format!(
                "{} triangles ({} input triangles split {n}² ways: the longest edge spans {longest:.1} texels) is more than max_triangles {}: lower `density`, or use a finer input mesh",
                triangles,
                mesh.triangles(),
                p.max_triangles
            ),
        ));
    }
    Ok(n as usize)
}

/// Where a vertex of the subdivided mesh comes from, so that a vertex shared by two triangles is
/// made once: an input corner, the k-th of n − 1 inner points of the edge from the lower to the
/// higher vertex index, or a triangle's inner grid point.
#[derive(Clone, Copy, Hash, PartialEq, Eq)]
enum Key {
    Corner(u32),
    Edge(u32, u32, u32),
    Inner(u32, u32, u32),
}

fn displace(mesh: &Mesh, hf: &HeightField, p: &Params, n: usize, top: f64, depth: f64) -> Mesh {
    let per_texel = if depth > 0.0 { p.shell / depth } else { 0.0 };
    let height = |uv: [f64; 2]| -> f64 {
        let u = uv[0] * p.tiling[0];
        let v = uv[1] * p.tiling[1];
        texel_taps(u, v, hf.width, hf.height)
            .iter()
            .map(|&(x, y, w)| w * hf.data[y * hf.width + x] as f64)
            .sum()
    };
    let f = |v: [f32; 3]| v.map(|x| x as f64);
    let canon = mesh.position_twins();
    // The point at weights (w0, w1, w2) of corners (a, b, c): position and normal interpolated
    // (from each corner's seam twin, so both sides of a seam agree), then moved along the normal.
    let point = |c: [usize; 3], w: [f64; 3]| -> ([f32; 3], [f32; 2]) {
        let mut pos = [0.0; 3];
        let mut nrm = [0.0; 3];
        let mut uv = [0.0; 2];
        for k in 0..3 {
            pos = add(pos, mul(f(mesh.positions[canon[c[k]]]), w[k]));
            nrm = add(nrm, mul(f(mesh.normals[canon[c[k]]]), w[k]));
            for (u, t) in uv.iter_mut().zip(mesh.uvs[c[k]]) {
                *u += t as f64 * w[k];
            }
        }
        let nrm = normalize(nrm).unwrap_or([0.0, 0.0, 1.0]);
        let moved = add(pos, mul(nrm, (height(uv) - top) * per_texel));
        (moved.map(|x| x as f32), uv.map(|x| x as f32))
    };
    let mut index: HashMap<Key, u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let mut indices = Vec::with_capacity(mesh.triangles() * n * n * 3);
    let nf = n as f64;
    for t in 0..mesh.triangles() {
        let c = mesh.corners(t);
        // Grid point (i, j): weights (1 − i/n − j/n, i/n, j/n) of (c0, c1, c2).
        let mut vertex = |i: usize, j: usize| -> u32 {
            let k = n - i - j;
            let key = match (i, j, k) {
                (0, 0, _) => Key::Corner(c[0] as u32),
                (_, 0, 0) => Key::Corner(c[1] as u32),
                (0, _, 0) => Key::Corner(c[2] as u32),
                // On an edge: the position along it from the lower vertex index.
                (_, 0, _) => edge_key(&canon, c[0], c[1], i, n),
                (0, _, _) => edge_key(&canon, c[0], c[2], j, n),
                (_, _, 0) => edge_key(&canon, c[1], c[2], j, n),
                _ => Key::Inner(t as u32, i as u32, j as u32),
            };
            *index.entry(key).or_insert_with(|| {
                let (ends, w) = match key {
                    Key::Corner(v) => ([v as usize; 3], [1.0, 0.0, 0.0]),
                    Key::Edge(a, b, s) => {
                        let s = s as f64 / nf;
                        ([a as usize, b as usize, b as usize], [1.0 - s, s, 0.0])
                    }
                    Key::Inner(..) => (c, [k as f64 / nf, i as f64 / nf, j as f64 / nf]),
                };
                let (pos, uv) = point(ends, w);
                positions.push(pos);
                uvs.push(uv);
                (positions.len() - 1) as u32
            })
        };
        for j in 0..n {
            for i in 0..n - j {
                let (a, b, c2) = (vertex(i, j), vertex(i + 1, j), vertex(i, j + 1));
                indices.extend([a, b, c2]);
                if i + j + 1 < n {
                    let d = vertex(i + 1, j + 1);
                    indices.extend([b, d, c2]);
                }
            }
        }
    }
    let normals = welded_normals(&positions, &indices);
    let mut out = Mesh {
        tangents: Vec::new(),
        normals,
        positions,
        uvs,
        indices,
    };
    out.compute_tangents();
    out
}

/// The key of the point `s` steps (of `n`) from `a` towards `b`, counted from the end whose seam
/// twin comes first (so the two copies of a seam edge are walked the same way).
fn edge_key(canon: &[usize], a: usize, b: usize, s: usize, n: usize) -> Key {
    if (canon[a], a) < (canon[b], b) {
        Key::Edge(a as u32, b as u32, s as u32)
    } else {
        Key::Edge(b as u32, a as u32, (n - s) as u32)
    }
}

/// Area-weighted face normals summed over every triangle meeting a position (so duplicated seam
/// vertices agree).
fn welded_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let bits = |p: [f32; 3]| p.map(f32::to_bits);
    let mut slot: HashMap<[u32; 3], usize> = HashMap::new();
    let of: Vec<usize> = positions
        .iter()
        .map(|&p| {
            let next = slot.len();
            *slot.entry(bits(p)).or_insert(next)
        })
        .collect();
    let mut acc = vec![[0f64; 3]; slot.len()];
    let f = |v: [f32; 3]| -> V3 { v.map(|x| x as f64) };
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| f(positions[i as usize]));
        let nrm = cross(sub(b, a), sub(c, a));
        for &i in t {
            let s = &mut acc[of[i as usize]];
            *s = add(*s, nrm);
        }
    }
    of.iter()
        .map(|&s| {
            normalize(acc[s])
                .unwrap_or([0.0, 0.0, 1.0])
                .map(|x| x as f32)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{self, Shape};
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    fn run(mesh: Mesh, hf: HeightField, p: &Params) -> Result<(Mesh, f64), NodeError> {
        Displace.check(p)?;
        let out = mesoflow_testkit::node::run(
            &Displace,
            p,
            &Inputs::new()
                .with("mesh", Arc::new(mesh))
                .with("height", Arc::new(hf)),
        )?;
        let m = out
            .try_value::<Mesh>("mesh")
            .cloned()
            .ok_or_else(|| NodeError::Failed("no mesh".into()))?;
        let n = out
            .try_value::<Scalar>("subdivision")
            .map_or(f64::NAN, |s| s.0);
        Ok((m, n))
    }

    fn plane(segments: u32) -> Mesh {
        primitive::build(&primitive::Params {
            shape: Shape::Plane,
            size: 2.0,
            minor: 0.0,
            segments: [segments, segments],
        })
        .unwrap()
    }

    #[test]
    fn a_plane_is_moved_down_by_the_height_below_the_top_in_shell_units() {
        // Closed form: the plane z = 0 (the shell's top), one tile per unit of uv over a 2 × 2
        // square, a 4 × 4 field whose samples are 0 except 2 at texel (1, 2); shell 0.1 over the
        // range 2: a texel of height is 0.05 units. At a texel centre the surface is at
        // (h − 2)·0.05: −0.1 on the flat, 0 at the peak.
        let hf = HeightField::from_fn(4, 4, |x, y| if (x, y) == (1, 2) { 2.0 } else { 0.0 });
        let p = Params {
            tiling: [1.0, 1.0],
            shell: 0.1,
            density: 2.0,
            ..Params::default()
        };
        let (m, n) = run(plane(4), hf, &p).unwrap();
        // Each cell's edge spans 1 texel, its diagonal √2: n = ⌈2√2⌉ = 3.
        assert_eq!(n, 3.0);
        assert_eq!(m.triangles(), 4 * 4 * 2 * 9);
        m.check().unwrap();
        // Texel (x, y) has its centre at u = (x + ½)/4, v = 1 − (y + ½)/4 (v up the image); on
        // the 2 × 2 plane, position ((u − ½)·2, (v − ½)·2).
        let at = |x: f64, y: f64| {
            let (u, v) = ((x + 0.5) / 4.0, 1.0 - (y + 0.5) / 4.0);
            [((u - 0.5) * 2.0) as f32, ((v - 0.5) * 2.0) as f32]
        };
        let z_at = |xy: [f32; 2]| {
            m.positions
                .iter()
                .filter(|q| (q[0] - xy[0]).abs() < 1e-5 && (q[1] - xy[1]).abs() < 1e-5)
                .map(|q| q[2])
                .next()
        };
        // Grid points fall on texel centres where (x + ½)/4 is a multiple of 1/12 (n = 3 per
        // 1/4 of uv): texel centres are at 1/8, 3/8, …, which are not; check the corners of the
        // cells instead, which bilinear interpolation puts at the mean of four samples.
        let corner = |x: f64, y: f64| at(x - 0.5, y - 0.5);
        // The corner shared by texels (0..2, 1..3): the peak is one of its four samples.
        let z = z_at(corner(1.0, 2.0)).unwrap();
        assert!((z - (0.5 - 2.0) * 0.05).abs() < 1e-6, "{z}");
        // A corner far from the peak: all four samples 0.
        let z = z_at(corner(3.0, 0.0)).unwrap();
        assert!((z + 0.1).abs() < 1e-6, "{z}");
        // Every vertex lies between the shell's top and its bottom.
        assert!(m
            .positions
            .iter()
            .all(|q| q[2] <= 1e-6 && q[2] >= -0.1 - 1e-6));
    }

    #[test]
    fn a_closed_mesh_stays_closed() {
        // Every edge of the displaced torus is shared by exactly two triangles (welded by
        // position): no cracks between input triangles, nor at the texture seams.
        let torus = primitive::build(&primitive::Params {
            shape: Shape::Torus,
            size: 1.0,
            minor: 0.4,
            segments: [12, 8],
        })
        .unwrap();
        let hf = HeightField::from_fn(8, 8, |x, y| ((x * 7 + y * 3) % 5) as f32);
        let p = Params {
            tiling: [3.0, 2.0],
            shell: 0.05,
            ..Params::default()
        };
        let (m, _) = run(torus, hf, &p).unwrap();
        let key = |i: u32| m.positions[i as usize].map(f32::to_bits);
        let mut edges: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
        for t in m.indices.chunks_exact(3) {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                let (ka, kb) = (key(a), key(b));
                let e = if ka < kb { (ka, kb) } else { (kb, ka) };
                *edges.entry(e).or_default() += 1;
            }
        }
        let open = edges.values().filter(|&&c| c != 2).count();
        assert_eq!(
            open,
            0,
            "{open} of {} edges not shared by two triangles",
            edges.len()
        );
        // Normals point outwards: away from the ring's centre line.
        for (q, nrm) in m.positions.iter().zip(&m.normals) {
            let ring = normalize([q[0] as f64, 0.0, q[2] as f64]).unwrap();
            let out = sub(q.map(|x| x as f64), mul(ring, 1.0));
            assert!(crate::support::geometry::dot(out, nrm.map(|x| x as f64)) > 0.0);
        }
    }

    #[test]
    fn clear_errors() {
        let hf = HeightField::from_fn(4, 4, |x, _| x as f32);
        let too_many = Params {
            max_triangles: 100,
            ..Params::default()
        };
        let e = run(plane(8), hf.clone(), &too_many).unwrap_err();
        assert!(e.to_string().contains("max_triangles"), "{e}");
        let shallow = Params {
            depth: Some(1.0),
            ..Params::default()
        };
        let e = run(plane(2), hf.clone(), &shallow).unwrap_err();
        assert!(e.to_string().contains("depth"), "{e}");
        let mut no_uv = plane(2);
        no_uv.uvs.clear();
        let e = run(no_uv, hf, &Params::default()).unwrap_err();
        assert!(e.to_string().contains("texture coordinates"), "{e}");
    }
}
