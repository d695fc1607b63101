//! What the studio shows of a value, per type: a description (sizes, directions, radii, points)
//! as JSON, and images as raw little-endian f32 pixels that the browser tone-maps itself, so
//! exposure and the linear/sRGB toggle need no round trip. Types it does not know (a Python
//! node's) are described by their type name and size.

use mesoflow_nodes::types::{
    BrdfMap, Btf, BtfBasis, DiffusionProfile, Embedding, HeightField, Image, KnnGraph, Mdf, Mesh,
    NormalMap, PointSet, ScatteringMaterial, SssLighting, WARD_PARAMS,
};
use mesoflow_runtime::{Artifact, Artifacts, ValueRef};
use serde_json::{json, Value};

/// The most points or triangles sent to a browser; larger sets are subsampled evenly.
const MAX_POINTS: usize = 20_000;
const MAX_TRIANGLES: usize = 60_000;

/// An image to draw: `channels` interleaved f32 per pixel, row 0 at the top.
pub struct Pixels {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

fn degrees(d: &mesoflow_nodes::types::Direction) -> [f64; 2] {
    [d.theta.to_degrees(), d.phi.to_degrees()]
}

fn pairs_json(pairs: &[mesoflow_nodes::types::DirectionPair]) -> Vec<[f64; 4]> {
    pairs
        .iter()
        .map(|p| {
            let (v, l) = (degrees(&p.view), degrees(&p.light));
            [v[0], v[1], l[0], l[1]]
        })
        .collect()
}

/// Every `step`-th row of an n × dims table, so a browser gets at most [`MAX_POINTS`] rows.
fn rows(data: &[f64], n: usize, dims: usize) -> (Vec<Vec<f64>>, usize) {
    let step = n.div_ceil(MAX_POINTS).max(1);
    let out = (0..n)
        .step_by(step)
        .map(|i| {
            data[i * dims..(i + 1) * dims]
                .iter()
                .map(|x| if x.is_finite() { *x } else { f64::NAN })
                .collect()
        })
        .collect();
    (out, step)
}

/// The description of a value, `{ "view": …, "type": …, "bytes": … }` plus what its view needs.
pub fn describe(v: &ValueRef) -> Value {
    let any = v.as_any();
    let mut d = if let Some(s) = v.as_scalar() {
        json!({ "view": "scalar", "value": s })
    } else if let Some(i) = any.downcast_ref::<Image>() {
        let peak = i
            .data
            .iter()
            .fold(0f32, |m, x| if x.is_finite() { m.max(*x) } else { m });
        json!({ "view": "image", "width": i.width, "height": i.height, "channels": i.channels,
                "peak": peak })
    } else if let Some(h) = any.downcast_ref::<HeightField>() {
        let (lo, hi) = h.min_max();
        json!({ "view": "height", "width": h.width, "height": h.height, "min": lo, "max": hi })
    } else if let Some(n) = any.downcast_ref::<NormalMap>() {
        json!({ "view": "normals", "width": n.width, "height": n.height })
    } else if let Some(b) = any.downcast_ref::<Btf>() {
        json!({ "view": "btf", "width": b.width, "height": b.height, "pairs": pairs_json(&b.pairs) })
    } else if let Some(b) = any.downcast_ref::<BtfBasis>() {
        let ranks: Vec<usize> = b.blocks.iter().map(|x| x.rank()).collect();
        json!({ "view": "btf", "width": b.width, "height": b.height, "pairs": pairs_json(&b.pairs),
                "ranks": ranks })
    } else if let Some(m) = any.downcast_ref::<Mdf>() {
        let views: Vec<[f64; 2]> = m.views.iter().map(degrees).collect();
        json!({ "view": "mdf", "width": m.width, "height": m.height, "views": views,
                "depth": m.depth })
    } else if let Some(p) = any.downcast_ref::<DiffusionProfile>() {
        json!({ "view": "profile", "model": p.model, "radii": p.radii, "rd": p.rd,
                "total": p.total, "mfp": p.mfp })
    } else if let Some(p) = any.downcast_ref::<PointSet>() {
        let (pts, step) = rows(&p.data, p.n, p.dims);
        json!({ "view": "points", "n": p.n, "dims": p.dims, "step": step, "points": pts })
    } else if let Some(e) = any.downcast_ref::<Embedding>() {
        let (pts, step) = rows(&e.data, e.n, e.components);
        json!({ "view": "points", "n": e.n, "dims": e.components, "step": step, "points": pts,
                "eigenvalues": e.eigenvalues })
    } else if let Some(k) = any.downcast_ref::<KnnGraph>() {
        let finite: Vec<f64> = k
            .distances
            .iter()
            .copied()
            .filter(|x| x.is_finite())
            .collect();
        let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
        let max = finite.iter().fold(0f64, |m, x| m.max(*x));
        json!({ "view": "table", "rows": [["points", k.n], ["neighbours each", k.k],
                ["mean distance", mean], ["largest distance", max]] })
    } else if let Some(b) = any.downcast_ref::<BrdfMap>() {
        json!({ "view": "brdfmap", "width": b.width, "height": b.height,
                "params": ["ρd red", "ρd green", "ρd blue", "ρs", "α"] })
    } else if let Some(m) = any.downcast_ref::<Mesh>() {
        mesh(m)
    } else if let Some(s) = any.downcast_ref::<ScatteringMaterial>() {
        json!({ "view": "table", "rows": [["σs′ (mm⁻¹)", s.sigma_s_prime], ["σa (mm⁻¹)", s.sigma_a],
                ["η", s.eta], ["g", s.g]] })
    } else if let Some(l) = any.downcast_ref::<SssLighting>() {
        json!({ "view": "table", "rows": [["irradiance samples", l.len()], ["spacing (mm)", l.spacing_mm],
                ["bounced light", l.bounced.is_some()], ["body grid cells", l.body.as_ref().map(|b| b.dims)]] })
    } else if let Some(a) = any.downcast_ref::<Artifact>() {
        json!({ "view": "files", "files": [{ "path": a.path, "bytes": a.bytes.len() }] })
    } else if let Some(a) = any.downcast_ref::<Artifacts>() {
        let files: Vec<Value> = a
            .files
            .iter()
            .map(|f| json!({ "path": f.path, "bytes": f.bytes.len() }))
            .collect();
        json!({ "view": "files", "files": files })
    } else if let Some(arr) = v.as_array() {
        json!({ "view": "table", "rows": [["shape", arr.shape]] })
    } else {
        json!({ "view": "none" })
    };
    if let Value::Object(m) = &mut d {
        m.insert("type".into(), Value::String(v.type_name().into()));
        m.insert("bytes".into(), Value::from(v.byte_size()));
    }
    d
}

fn mesh(m: &Mesh) -> Value {
    let tris = m.triangles();
    let step = tris.div_ceil(MAX_TRIANGLES).max(1);
    let indices: Vec<u32> = (0..tris)
        .step_by(step)
        .flat_map(|t| m.corners(t).map(|c| c as u32))
        .collect();
    let positions: Vec<f32> = m.positions.iter().flatten().copied().collect();
    let (lo, hi) = m.bounds();
    json!({ "view": "mesh", "triangles": tris, "shown": indices.len() / 3,
            "positions": positions, "indices": indices, "bounds": [lo, hi] })
}

/// The pixels of image `index` of a value: the image itself, a BTF's direction pair, an MDF's
/// view, a BRDF map's parameter. `None`: the value has no such image.
pub fn pixels(v: &ValueRef, index: usize) -> Option<Pixels> {
    let any = v.as_any();
    if let Some(i) = any.downcast_ref::<Image>() {
        return Some(Pixels {
            width: i.width,
            height: i.height,
            channels: i.channels,
            data: i.data.clone(),
        });
    }
    if let Some(h) = any.downcast_ref::<HeightField>() {
        return Some(Pixels {
            width: h.width,
            height: h.height,
            channels: 1,
            data: h.data.clone(),
        });
    }
    if let Some(n) = any.downcast_ref::<NormalMap>() {
        return Some(Pixels {
            width: n.width,
            height: n.height,
            channels: 3,
            data: n.data.clone(),
        });
    }
    if let Some(b) = any.downcast_ref::<Btf>() {
        if index >= b.pairs.len() {
            return None;
        }
        let i = b.preview(index);
        return Some(Pixels {
            width: i.width,
            height: i.height,
            channels: 3,
            data: i.data,
        });
    }
    if let Some(b) = any.downcast_ref::<BtfBasis>() {
        if index >= b.pairs.len() {
            return None;
        }
        let t = b.texels();
        let mut planes = vec![0f32; 3 * t];
        mesoflow_nodes::btf::reconstruct::pair_into(b, &b.column_owners(), index, &mut planes);
        let data = (0..t)
            .flat_map(|i| [planes[i], planes[t + i], planes[2 * t + i]])
            .collect();
        return Some(Pixels {
            width: b.width,
            height: b.height,
            channels: 3,
            data,
        });
    }
    if let Some(m) = any.downcast_ref::<Mdf>() {
        if index >= m.views.len() {
            return None;
        }
        return Some(Pixels {
            width: m.width,
            height: m.height,
            channels: 1,
            data: m.plane(index).to_vec(),
        });
    }
    if let Some(b) = any.downcast_ref::<BrdfMap>() {
        if index >= WARD_PARAMS {
            return None;
        }
        return Some(Pixels {
            width: b.width,
            height: b.height,
            channels: 1,
            data: (0..b.width * b.height)
                .map(|i| b.pixel(i)[index] as f32)
                .collect(),
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_nodes::types::{Direction, DirectionPair};
    use std::sync::Arc;

    #[test]
    fn a_btf_pair_is_its_own_planes_interleaved() {
        // 2 × 1 texels, two pairs; pair 1's planes are R = [1, 2], G = [3, 4], B = [5, 6].
        let pair = |t: f64| DirectionPair {
            view: Direction::degrees(t, 0.0),
            light: Direction::degrees(0.0, 0.0),
        };
        let v: ValueRef = Arc::new(Btf {
            width: 2,
            height: 1,
            pairs: vec![pair(0.0), pair(30.0)],
            data: vec![0., 0., 0., 0., 0., 0., 1., 2., 3., 4., 5., 6.],
        });
        let p = pixels(&v, 1).expect("pair 1 exists");
        assert_eq!((p.width, p.height, p.channels), (2, 1, 3));
        assert_eq!(p.data, vec![1., 3., 5., 2., 4., 6.]);
        assert!(pixels(&v, 2).is_none());
        let d = describe(&v);
        assert_eq!(d["view"], "btf");
        assert!((d["pairs"][1][0].as_f64().unwrap() - 30.0).abs() < 1e-9);
    }

    #[test]
    fn large_point_sets_are_subsampled_not_sent_whole() {
        let n = 3 * MAX_POINTS;
        let v: ValueRef = Arc::new(PointSet {
            n,
            dims: 2,
            data: (0..2 * n).map(|i| i as f64).collect(),
        });
        let d = describe(&v);
        assert_eq!(d["step"], 3);
        assert_eq!(d["points"].as_array().unwrap().len(), MAX_POINTS);
        assert_eq!(d["points"][1][0], 6.0);
    }

    /// One value of every type a node can output, so a new type without a preview fails here.
    fn samples() -> Vec<ValueRef> {
        use mesoflow_nodes::types::ColorSpace;
        use mesoflow_runtime::{Artifact, Artifacts, Scalar};
        let mesh = Mesh {
            positions: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]],
            indices: vec![0, 1, 2],
            ..Default::default()
        };
        vec![
            Arc::new(Scalar(1.0)),
            Arc::new(Artifact {
                path: "a.png".into(),
                bytes: vec![1],
            }),
            Arc::new(Artifacts { files: vec![] }),
            Arc::new(Image {
                width: 1,
                height: 1,
                channels: 3,
                data: vec![0.5; 3],
            }),
            Arc::new(HeightField {
                width: 1,
                height: 1,
                data: vec![0.0],
            }),
            Arc::new(NormalMap {
                width: 1,
                height: 1,
                data: vec![0., 0., 1.],
            }),
            Arc::new(Btf {
                width: 1,
                height: 1,
                pairs: vec![],
                data: vec![],
            }),
            Arc::new(BtfBasis {
                width: 1,
                height: 1,
                pairs: vec![],
                color: ColorSpace::Rgb,
                blocks: vec![],
            }),
            Arc::new(Mdf {
                width: 1,
                height: 1,
                views: vec![],
                depth: 1.0,
                data: vec![],
            }),
            Arc::new(DiffusionProfile {
                model: "dipole".into(),
                radii: vec![0.1, 1.0],
                rd: [vec![1.0, 0.1], vec![1.0, 0.1], vec![1.0, 0.1]],
                total: [0.5; 3],
                mfp: [1.0; 3],
                cdf: [vec![0.5, 1.0], vec![0.5, 1.0], vec![0.5, 1.0]],
            }),
            Arc::new(PointSet {
                n: 1,
                dims: 2,
                data: vec![0., 1.],
            }),
            Arc::new(Embedding {
                n: 1,
                components: 1,
                data: vec![0.],
                eigenvalues: vec![1.],
            }),
            Arc::new(KnnGraph {
                n: 1,
                k: 1,
                neighbors: vec![0],
                distances: vec![0.5],
            }),
            Arc::new(BrdfMap {
                width: 1,
                height: 1,
                data: vec![0.5; WARD_PARAMS],
            }),
            Arc::new(mesh),
            Arc::new(ScatteringMaterial {
                sigma_s_prime: [1.; 3],
                sigma_a: [0.1; 3],
                eta: 1.3,
                g: 0.0,
            }),
            Arc::new(SssLighting {
                params: "{}".into(),
                made_for: String::new(),
                area_each: 1.0,
                spacing_mm: 1.0,
                sources: vec![0.0; 9],
                bounced: None,
                body: None,
                shadow: None,
            }),
        ]
    }

    #[test]
    fn every_type_a_node_can_output_has_a_preview() {
        let samples = samples();
        for v in &samples {
            let d = describe(v);
            assert_ne!(d["view"], "none", "{}", v.type_name());
            assert_eq!(d["type"], v.type_name());
        }
        let registry = mesoflow_nodes::registry::builtin();
        for kind in mesoflow_graph::Catalog::kinds(&registry) {
            let Some(node) = registry.node(kind) else {
                continue;
            };
            for o in &node.signature().outputs {
                assert!(
                    samples.iter().any(|v| v.type_name() == o.ty),
                    "{kind}.{}: type {} has no preview sample",
                    o.name,
                    o.ty
                );
            }
        }
    }
}
