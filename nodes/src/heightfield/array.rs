//! `heightfield.array`: a periodic height field from an NPY array (H, W) in `npy.write`'s layout.

use crate::support::npy::{finite_f32, ArrayParams};
use crate::types::HeightField;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use std::path::{Path, PathBuf};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::formats::encode_npy;
    use mesoflow_testkit::node::run_json_in as run;

    #[test]
    fn a_non_finite_height_is_refused_naming_its_element() {
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
    }
}
