//! `btf.write_ubo2014`: a `BtfBasis` as a Bonn UBO2014 DFMF file (`!DFMF08FCR`, half floats),
//! so mesoflow's compressed BTFs open in btflib and the tools built on it. Every block's
//! components and means become DFMF components of their channel (see `ubo2014::write_dfmf`), so
//! nothing is re-fitted: the file reconstructs the basis up to half-float rounding.

use super::ubo2014;
use crate::types::BtfBasis;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{
    Artifact, Artifacts, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The `.btf` file, relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
}

pub struct WriteUbo2014;

impl Node for WriteUbo2014 {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.write_ubo2014",
            version: 1,
            doc: "Writes a BtfBasis as a Bonn UBO2014 DFMF .btf file (half floats, RGB or YUV), readable by btflib.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("basis", BtfBasis::TYPE, "the factorised BTF (btf.pca's)")],
            outputs: vec![Port::output("files", Artifacts::TYPE, "the .btf file, written under the output folder")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let basis = inputs.get::<BtfBasis>("basis")?;
        let bytes = ubo2014::write_dfmf(basis).map_err(|e| NodeError::input("basis", e))?;
        Ok(Outputs::new().with(
            "files",
            Artifacts {
                files: vec![Artifact {
                    path: p.path.clone(),
                    bytes,
                }],
            },
        ))
    }
}
