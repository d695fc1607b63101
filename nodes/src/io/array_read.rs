//! Typed values from NPY arrays in `npy.write`'s layouts, so an array made elsewhere (numpy, the
//! Python package's `g.add("image.array", data=X)`) enters a graph as the type its consumers need:
//! `image.array` (H, W, C), `heightfield.array` (H, W), `btf.array` (pairs, 3, H, W) with its
//! direction pairs, `points.array` (n, D). The file's contents enter the cache key (as every
//! declared file's do), so the same array gives the same key whatever its file is called.

use crate::types::{Btf, Direction, DirectionPair, HeightField, Image, PointSet};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ArrayParams {
    /// NPY file (f32 or f64, C or Fortran order), relative to the graph file.
    pub data: String,
}

/// The array, every element finite, as f32.
fn finite_f32(path: &Path, rank: usize, what: &str) -> Result<(Vec<usize>, Vec<f32>), NodeError> {
    let a = super::npy_read::read(path, rank, what)?;
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(NodeError::file(
            path,
            format!("element {i} (row-major) is not finite"),
        ));
    }
    Ok((a.shape, a.data.iter().map(|&v| v as f32).collect()))
}

pub struct ImageArray;

impl Node for ImageArray {
    type Params = ArrayParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.array",
            version: 1,
            doc: "Linear image from an NPY array (H, W, C), C = 1, 3 or 4; row 0 is the top.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("image", Image::TYPE, "the image")],
            disk_cache: false,
        }
    }

    fn files(&self, p: &ArrayParams, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.data)])
    }

    fn run(&self, ctx: &NodeContext, p: &ArrayParams, _: &Inputs) -> Result<Outputs, NodeError> {
        let path = ctx.input_path("data", &p.data)?;
        let (shape, data) = finite_f32(&path, 3, "(H, W, C)")?;
        if !matches!(shape[2], 1 | 3 | 4) {
            return Err(NodeError::file(
                &path,
                format!("an image has 1, 3 or 4 channels; got shape {shape:?}"),
            ));
        }
        Ok(Outputs::new().with(
            "image",
            Image {
                width: shape[1],
                height: shape[0],
                channels: shape[2],
                data,
            },
        ))
    }
}

pub struct HeightFieldArray;

impl Node for HeightFieldArray {
    type Params = ArrayParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "heightfield.array",
            version: 1,
            doc: "Periodic height field from an NPY array (H, W), heights in texels.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output(
                "height",
                HeightField::TYPE,
                "the height field",
            )],
            disk_cache: false,
        }
    }

    fn files(&self, p: &ArrayParams, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.data)])
    }

    fn run(&self, ctx: &NodeContext, p: &ArrayParams, _: &Inputs) -> Result<Outputs, NodeError> {
        let (shape, data) = finite_f32(&ctx.input_path("data", &p.data)?, 2, "(H, W)")?;
        Ok(Outputs::new().with(
            "height",
            HeightField {
                width: shape[1],
                height: shape[0],
                data,
            },
        ))
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BtfParams {
    /// NPY file (pairs, 3, H, W): linear RGB planes, as `npy.write` writes a Btf.
    pub data: String,
    /// The direction pair of each plane triple, in order: [θ_view, φ_view, θ_light, φ_light] in
    /// degrees (θ from the normal, 0–90; φ from +x towards +y).
    #[schemars(length(min = 1))]
    pub pairs: Vec<[f64; 4]>,
}

pub struct BtfArray;

impl Node for BtfArray {
    type Params = BtfParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.array",
            version: 1,
            doc: "BTF from an NPY array (pairs, 3, H, W) and its [θv, φv, θl, φl] direction pairs in degrees.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("btf", Btf::TYPE, "the BTF")],
            disk_cache: false,
        }
    }

    fn check(&self, p: &BtfParams) -> Result<(), NodeError> {
        if p.pairs.is_empty() {
            return Err(NodeError::param(
                "pairs",
                "needs at least one direction pair",
            ));
        }
        for (i, q) in p.pairs.iter().enumerate() {
            let ok = q.iter().all(|v| v.is_finite())
                && (0.0..=90.0).contains(&q[0])
                && (0.0..=90.0).contains(&q[2]);
            if !ok {
                return Err(NodeError::param(
                    "pairs",
                    format!("pair {i} {q:?}: θ must be within 0–90° and every angle finite"),
                ));
            }
        }
        Ok(())
    }

    fn files(&self, p: &BtfParams, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.data)])
    }

    fn run(&self, ctx: &NodeContext, p: &BtfParams, _: &Inputs) -> Result<Outputs, NodeError> {
        let path = ctx.input_path("data", &p.data)?;
        let (shape, data) = finite_f32(&path, 4, "(pairs, 3, H, W)")?;
        if shape[1] != 3 || shape[0] != p.pairs.len() {
            return Err(NodeError::file(
                &path,
                format!(
                    "expected shape ({}, 3, H, W) for {} direction pairs; got {shape:?}",
                    p.pairs.len(),
                    p.pairs.len()
                ),
            ));
        }
        let pairs = p
            .pairs
            .iter()
            .map(|q| DirectionPair {
                view: Direction::degrees(q[0], q[1]),
                light: Direction::degrees(q[2], q[3]),
            })
            .collect();
        Ok(Outputs::new().with(
            "btf",
            Btf {
                width: shape[3],
                height: shape[2],
                pairs,
                data,
            },
        ))
    }
}

pub struct PointsArray;

impl Node for PointsArray {
    type Params = ArrayParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "points.array",
            version: 1,
            doc: "Point set from an NPY array (n, D), kept in f64.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output(
                "points",
                PointSet::TYPE,
                "n points in D dimensions",
            )],
            disk_cache: false,
        }
    }

    fn files(&self, p: &ArrayParams, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.data)])
    }

    fn run(&self, ctx: &NodeContext, p: &ArrayParams, _: &Inputs) -> Result<Outputs, NodeError> {
        let points = crate::manifold::points_read::read(&ctx.input_path("data", &p.data)?)?;
        Ok(Outputs::new().with("points", points))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::formats::encode_npy;
    use mesoflow_testkit::node::OutputsExt;

    fn run<N: Node>(node: &N, params: serde_json::Value, dir: &Path) -> Result<Outputs, NodeError> {
        let p: N::Params = serde_json::from_value(params).unwrap();
        node.check(&p)?;
        let ctx = NodeContext::detached(None).with_base(dir.to_path_buf());
        node.run(&ctx, &p, &Inputs::new())
    }

    #[test]
    fn arrays_become_typed_values_in_npy_write_layouts() {
        let dir = tempfile::tempdir().unwrap();
        // (H, W, C) = (2, 3, 1): pixel (x, y) is x + 10 y, row 0 at the top.
        let img: Vec<f64> = (0..2)
            .flat_map(|y| (0..3).map(move |x| (x + 10 * y) as f64))
            .collect();
        std::fs::write(
            dir.path().join("i.npy"),
            encode_npy(&[2, 3, 1], &img).unwrap(),
        )
        .unwrap();
        let out = run(
            &ImageArray,
            serde_json::json!({"data": "i.npy"}),
            dir.path(),
        )
        .unwrap();
        let v = out.value::<Image>("image");
        assert_eq!((v.width, v.height, v.channels), (3, 2, 1));
        assert_eq!(v.data[3 + 2], 12.0);

        let btf = vec![0.5f32; 2 * 3 * 2 * 2];
        std::fs::write(
            dir.path().join("b.npy"),
            encode_npy(&[2, 3, 2, 2], &btf).unwrap(),
        )
        .unwrap();
        let pairs = serde_json::json!([[0, 0, 45, 90], [30, 0, 0, 0]]);
        let out = run(
            &BtfArray,
            serde_json::json!({"data": "b.npy", "pairs": pairs}),
            dir.path(),
        )
        .unwrap();
        let b = out.value::<Btf>("btf");
        assert_eq!((b.width, b.height, b.pairs.len()), (2, 2, 2));
        assert!((b.pairs[0].light.phi - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // Three pairs declared for two planes: refused, naming both.
        let three = serde_json::json!([[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]);
        let e = run(
            &BtfArray,
            serde_json::json!({"data": "b.npy", "pairs": three}),
            dir.path(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("(3, 3, H, W)"), "{e}");
        let e = run(
            &BtfArray,
            serde_json::json!({"data": "b.npy", "pairs": [[95, 0, 0, 0]]}),
            dir.path(),
        )
        .unwrap_err();
        assert!(matches!(e, NodeError::Param { .. }));
    }

    #[test]
    fn non_finite_and_wrong_channels_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("h.npy"),
            encode_npy(&[1, 2], &[1.0f32, f32::NAN]).unwrap(),
        )
        .unwrap();
        let e = run(
            &HeightFieldArray,
            serde_json::json!({"data": "h.npy"}),
            dir.path(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("element 1") && e.contains("not finite"), "{e}");
        std::fs::write(
            dir.path().join("i.npy"),
            encode_npy(&[1, 1, 2], &[1.0f32, 2.0]).unwrap(),
        )
        .unwrap();
        let e = run(
            &ImageArray,
            serde_json::json!({"data": "i.npy"}),
            dir.path(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("1, 3 or 4 channels"), "{e}");
    }
}
