//! `image.row`: up to four images side by side, left to right, on a background, with a gap;
//! for before/after comparisons that people would rather look at than read.

use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Pixels between images.
    #[schemars(range(max = 1024))]
    pub gap: u32,
    /// Linear RGB of the gap and of the space below shorter images.
    pub background: [f64; 3],
}

impl Default for Params {
    fn default() -> Self {
        Params {
            gap: 4,
            background: [1.0, 1.0, 1.0],
        }
    }
}

pub struct Row;

const PORTS: [&str; 4] = ["a", "b", "c", "d"];

impl Node for Row {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.row",
            version: 1,
            doc: "Up to four images side by side (a, b, c, d), RGB, with a gap.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("a", Image::TYPE, "leftmost image"),
                Port::optional("b", Image::TYPE, "second image"),
                Port::optional("c", Image::TYPE, "third image"),
                Port::optional("d", Image::TYPE, "fourth image"),
            ],
            outputs: vec![Port::output("image", Image::TYPE, "the row, RGB")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mut images = Vec::new();
        for port in PORTS {
            if let Some(img) = inputs.opt::<Image>(port)? {
                images.push(img);
            }
        }
        let gap = p.gap as usize;
        let width = images.iter().map(|i| i.width).sum::<usize>() + gap * (images.len() - 1);
        let height = images.iter().map(|i| i.height).max().unwrap_or(0);
        let mut data: Vec<f32> = (0..width * height)
            .flat_map(|_| p.background.map(|v| v as f32))
            .collect();
        let mut x0 = 0;
        for img in images {
            for y in 0..img.height {
                for x in 0..img.width {
                    let src = &img.data[(y * img.width + x) * img.channels..][..img.channels];
                    let rgb = match img.channels {
                        1 => [src[0]; 3],
                        _ => [src[0], src[1], src[2]],
                    };
                    data[(y * width + x0 + x) * 3..][..3].copy_from_slice(&rgb);
                }
            }
            x0 += img.width + gap;
        }
        Ok(Outputs::new().with(
            "image",
            Image {
                width,
                height,
                channels: 3,
                data,
            },
        ))
    }
}
