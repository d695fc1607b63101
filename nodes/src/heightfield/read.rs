//! `heightfield.read`: a height field from a 16-bit (or 8-bit) grey PNG, an EXR (first channel) or
//! a 2-D NPY array. Samples are multiplied by `depth`, the height in texels of a sample value 1.0
//! (PNG samples are first normalised to [0, 1]).

use crate::support::formats;
use crate::types::HeightField;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// File to read (.png, .exr or .npy), relative to the graph file.
    pub path: String,
    /// Height in texels of a sample value 1.0.
    #[serde(default = "one")]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub depth: f64,
}

fn one() -> f64 {
    1.0
}

pub struct Read;

impl Node for Read {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "heightfield.read",
            version: 1,
            doc: "Height field from a grey PNG (8/16-bit), EXR (first channel) or 2-D NPY, times `depth`.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("height", HeightField::TYPE, "heights in texels")],
            disk_cache: true,
        }
    }

    fn files(&self, p: &Params, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.path)])
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let path = ctx.input_path("path", &p.path)?;
        let grid = formats::read_grey(&path)?;
        let data: Vec<f32> = grid
            .data
            .iter()
            .map(|v| (*v as f64 * p.depth) as f32)
            .collect();
        if let Some(bad) = data.iter().position(|v| !v.is_finite()) {
            return Err(NodeError::file(
                &path,
                format!("sample {bad} is not finite"),
            ));
        }
        Ok(Outputs::new().with(
            "height",
            HeightField {
                width: grid.width,
                height: grid.height,
                data,
            },
        ))
    }
}
