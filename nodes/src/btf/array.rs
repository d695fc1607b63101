//! `btf.array`: a BTF from an NPY array (pairs, 3, H, W) in `npy.write`'s layout, with its
//! direction pairs.

use crate::support::npy::finite_f32;
use crate::types::{Btf, Direction, DirectionPair};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::formats::encode_npy;
    use mesoflow_testkit::node::run_json_in as run;
    use mesoflow_testkit::node::OutputsExt;

    #[test]
    fn a_btf_array_takes_its_direction_pairs_and_refuses_a_mismatch() {
        let dir = tempfile::tempdir().unwrap();
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
}
