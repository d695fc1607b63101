//! `npy.write`: any array-like value as a NumPy `.npy` file (little-endian f32, C order). Layouts:
//! `HeightField` (H, W) in texels; `Image` (H, W, C) linear; `NormalMap` (H, W, 3) unit vectors;
//! `Btf` (pairs, 3, H, W) linear RGB planes, pairs view-major; `Mdf` (views, H, W) texels, +inf for
//! no hit, with a sidecar `<name>.json` listing the view directions in order;
//! `DiffusionProfile` (4, n) **f64**: r in mm, then Rd(r) for R, G, B in mm⁻².
//! Row 0 is the top of the image in every layout.

use crate::types::ARRAY_TYPES;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{
    Artifact, Artifacts, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Output file, relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
}

pub struct NpyWrite;

impl Node for NpyWrite {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "npy.write",
            // 2: the output became a file set, for the MDF's sidecar.
            version: 2,
            doc: "Writes an array-like value as .npy (f32, C order): HeightField (H,W), Image (H,W,C), NormalMap (H,W,3), Btf (pairs,3,H,W), Mdf (views,H,W) + <name>.json; DiffusionProfile (4,n) f64: r mm, Rd R G B mm⁻².",
            device: DevicePreference::Cpu,
            inputs: vec![Port::any_of("value", ARRAY_TYPES, "any array-like value")],
            outputs: vec![Port::output(
                "files",
                Artifacts::TYPE,
                "the .npy file (and its .json sidecar where the type has one), under the output folder",
            )],
            disk_cache: true,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let value = inputs.value("value")?;
        let bytes = match value.as_array_f64() {
            Some((shape, data)) => crate::support::formats::encode_npy(&shape, &data),
            None => {
                let array = value.as_array().ok_or_else(|| {
                    NodeError::input(
                        "value",
                        format!("{} has no array layout", value.type_name()),
                    )
                })?;
                crate::support::formats::encode_npy(&array.shape, array.data)
            }
        }
        .map_err(NodeError::Failed)?;
        let mut files = vec![Artifact {
            path: p.path.clone(),
            bytes,
        }];
        if let Some(json) = value.array_sidecar() {
            let stem = p.path.strip_suffix(".npy").unwrap_or(&p.path);
            files.push(Artifact {
                path: format!("{stem}.json"),
                bytes: json.into_bytes(),
            });
        }
        Ok(Outputs::new().with("files", Artifacts { files }))
    }
}
