//! `image.array`: a linear image from an NPY array (H, W, C) in `npy.write`'s layout (the Python
//! package's `g.add("image.array", data=X)`). The file's contents enter the cache key.

use crate::support::npy::{finite_f32, ArrayParams};
use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use std::path::{Path, PathBuf};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::formats::encode_npy;
    use mesoflow_testkit::node::run_json_in as run;
    use mesoflow_testkit::node::OutputsExt;

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
    }

    #[test]
    fn an_image_of_two_channels_is_refused() {
        let dir = tempfile::tempdir().unwrap();
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
