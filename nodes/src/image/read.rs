//! `image.read`: an image file (PNG, JPEG, HDR, EXR) as a linear `Image`.

use crate::support::formats;
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
        let path = ctx.input_path("path", &p.path)?;
        let image = formats::read_image(&path)?;
        // NaN or infinite pixels (an EXR or HDR can hold them) would poison every sum downstream:
        // refused here, by position, as `heightfield.read` refuses them.
        if let Some(i) = image.data.iter().position(|v| !v.is_finite()) {
            let px = i / image.channels.max(1);
            return Err(NodeError::file(
                &path,
                format!(
                    "pixel ({}, {}) channel {} is not finite",
                    px % image.width.max(1),
                    px / image.width.max(1),
                    i % image.channels.max(1)
                ),
            ));
        }
        Ok(Outputs::new().with("image", image))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_pixels_are_refused_with_their_position() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image {
            width: 2,
            height: 2,
            channels: 3,
            data: vec![
                0.5,
                0.5,
                0.5,
                0.5,
                0.5,
                0.5,
                0.5,
                f32::NAN,
                0.5,
                0.5,
                0.5,
                0.5,
            ],
        };
        std::fs::write(
            dir.path().join("nan.exr"),
            formats::encode_exr(&img).unwrap(),
        )
        .unwrap();
        let ctx = NodeContext::detached(None).with_base(dir.path().to_path_buf());
        let p = Params {
            path: "nan.exr".into(),
        };
        let e = mesoflow_testkit::node::run_in(&ctx, &ImageRead, &p, &Inputs::new())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("pixel (0, 1) channel 1 is not finite"), "{e}");
    }
}
