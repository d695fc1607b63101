//! `image.write`: encodes an image as PNG (8/16-bit, sRGB) or EXR (linear f32). The node returns
//! the file's bytes; the runtime writes them under the output folder.

use crate::support::formats;
use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Artifact, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// From the path's extension (.png or .exr).
    Auto,
    Png,
    Exr,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Output file, relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub path: String,
    /// File format.
    #[serde(default = "auto")]
    pub format: Format,
    /// Bits per PNG sample: 8 or 16.
    #[serde(default = "eight")]
    #[schemars(range(min = 8, max = 16))]
    pub bits: u8,
    /// Each pixel written as scale × scale pixels (nearest neighbour), to show small images.
    #[serde(default = "one")]
    #[schemars(range(min = 1, max = 64))]
    pub scale: u32,
    /// Multiplies every value before encoding (a camera's exposure, linear).
    #[serde(default = "unit")]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub exposure: f64,
}

fn auto() -> Format {
    Format::Auto
}
fn eight() -> u8 {
    8
}

fn one() -> u32 {
    1
}
fn unit() -> f64 {
    1.0
}

pub struct ImageWrite;

impl Node for ImageWrite {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.write",
            version: 2,
            doc:
                "Writes an image: PNG (8 or 16 bit, sRGB-encoded for display) or EXR (linear f32).",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("image", Image::TYPE, "linear image")],
            outputs: vec![Port::output(
                "file",
                "File",
                "the encoded file, written under the output folder",
            )],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        format_of(p).map(drop)
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let img = inputs.get::<Image>("image")?;
        let format = format_of(p)?;
        let shown;
        let img = if p.scale == 1 && p.exposure == 1.0 {
            img
        } else {
            shown = enlarge(img, p.scale as usize, p.exposure as f32);
            &shown
        };
        let bytes = match format {
            Format::Exr => formats::encode_exr(img),
            _ => formats::encode_png(img, p.bits),
        }
        .map_err(|e| NodeError::Failed(format!("encoding {}: {e}", p.path)))?;
        Ok(Outputs::new().with(
            "file",
            Artifact {
                path: p.path.clone(),
                bytes,
            },
        ))
    }
}

/// The image times `exposure`, each pixel repeated `scale` × `scale` times.
fn enlarge(img: &Image, scale: usize, exposure: f32) -> Image {
    let (w, c) = (img.width * scale, img.channels);
    let data = (0..img.height * scale)
        .flat_map(|y| (0..w).map(move |x| (y / scale * img.width + x / scale) * c))
        .flat_map(|at| img.data[at..at + c].iter().map(|v| v * exposure))
        .collect();
    Image {
        width: w,
        height: img.height * scale,
        channels: c,
        data,
    }
}

/// The file format `p` asks for (from the extension when `auto`), and its sample size.
fn format_of(p: &Params) -> Result<Format, NodeError> {
    let extension = std::path::Path::new(&p.path)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let format = match (p.format, extension.as_deref()) {
        (Format::Auto, Some("png")) => Format::Png,
        (Format::Auto, Some("exr")) => Format::Exr,
        (Format::Auto, other) => {
            return Err(NodeError::param(
                "path",
                format!("cannot tell the format from extension {other:?}; use .png or .exr, or set `format`"),
            ))
        }
        (f, _) => f,
    };
    if p.bits != 8 && p.bits != 16 {
        return Err(NodeError::param(
            "bits",
            format!("PNG samples are 8 or 16 bits, got {}", p.bits),
        ));
    }
    Ok(format)
}

#[cfg(test)]
mod enlarge_tests {
    use super::*;

    #[test]
    fn enlarging_repeats_pixels_and_exposure_scales_them() {
        let img = Image {
            width: 2,
            height: 1,
            channels: 1,
            data: vec![0.25, 0.5],
        };
        let big = enlarge(&img, 2, 2.0);
        assert_eq!((big.width, big.height), (4, 2));
        assert_eq!(big.data, vec![0.5, 0.5, 1.0, 1.0, 0.5, 0.5, 1.0, 1.0]);
    }
}
