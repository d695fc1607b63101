//! `image.read`: an image file (PNG, JPEG, HDR, EXR) as a linear `Image`.

use crate::io::formats;
use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Image file, relative to the graph file. 8-bit files are sRGB-decoded to linear.
    pub path: String,
}

pub struct ImageRead;

impl Node for ImageRead {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.read",
            version: 1,
            doc: "Reads PNG, JPEG, HDR or EXR into a linear image (8-bit files are sRGB-decoded).",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("image", Image::TYPE, "linear f32 pixels")],
            disk_cache: true,
        }
    }

    fn files(&self, p: &Params, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.path)])
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("image", formats::read_image(&ctx.input_path(&p.path))?))
    }
}
