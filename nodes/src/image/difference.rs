//! `image.difference`: the signed difference image − reference as a picture, red where the image
//! is brighter and blue where it is darker (the channels' mean), black where they agree: where a
//! render gains or loses light, which an absolute difference hides.

use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The difference shown at full red or blue; default half the reference's 99th-percentile
    /// channel value.
    #[schemars(range(min = 1e-12))]
    pub scale: Option<f64>,
}

pub struct Difference;

impl Node for Difference {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.difference",
            version: 1,
            doc: "Signed difference image − reference as red (brighter) and blue (darker), scaled; for comparisons against a truth.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("reference", Image::TYPE, "the truth"),
                Port::input("image", Image::TYPE, "the image judged, of the same size"),
            ],
            outputs: vec![Port::output("image", Image::TYPE, "the difference, RGB")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let r = inputs.get::<Image>("reference")?;
        let i = inputs.get::<Image>("image")?;
        super::compare::same_size(r, i)?;
        if r.data.iter().chain(&i.data).any(|v| !v.is_finite()) {
            return Err(NodeError::input("image", "values must be finite"));
        }
        let scale = match p.scale {
            Some(s) => s,
            None => {
                let mut v: Vec<f32> = r.data.clone();
                v.sort_by(f32::total_cmp);
                let q = v
                    .get((v.len() as f64 * 0.99) as usize)
                    .copied()
                    .unwrap_or(0.0);
                0.5 * (q as f64).max(1e-30)
            }
        };
        let c = r.channels.max(1);
        let data = r
            .data
            .chunks_exact(c)
            .zip(i.data.chunks_exact(c))
            .flat_map(|(a, b)| {
                let d = a.iter().zip(b).map(|(a, b)| (b - a) as f64).sum::<f64>() / c as f64;
                let v = (d.abs() / scale).min(1.0) as f32;
                if d > 0.0 {
                    [v, 0.0, 0.0]
                } else {
                    [0.0, 0.0, v]
                }
            })
            .collect();
        Ok(Outputs::new().with(
            "image",
            Image {
                width: r.width,
                height: r.height,
                channels: 3,
                data,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    #[test]
    fn brighter_is_red_darker_is_blue_and_sizes_must_match() {
        let img = |data: Vec<f32>| Image {
            width: 3,
            height: 1,
            channels: 1,
            data,
        };
        let run = |a, b, p: &Params| {
            mesoflow_testkit::node::run(
                &Difference,
                p,
                &Inputs::new()
                    .with("reference", Arc::new(img(a)))
                    .with("image", Arc::new(img(b))),
            )
        };
        let p = Params { scale: Some(0.5) };
        let out = run(vec![1.0, 1.0, 1.0], vec![1.25, 0.0, 1.0], &p).unwrap();
        let d = out.try_value::<Image>("image").unwrap();
        assert_eq!(d.data, vec![0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        let bad = mesoflow_testkit::node::run(
            &Difference,
            &p,
            &Inputs::new()
                .with("reference", Arc::new(img(vec![1.0; 3])))
                .with(
                    "image",
                    Arc::new(Image {
                        width: 1,
                        height: 1,
                        channels: 1,
                        data: vec![1.0],
                    }),
                ),
        )
        .unwrap_err();
        assert!(bad.to_string().contains("image"), "{bad}");
        // `scale`'s lower bound is the schema's: `registry::the_schema_alone_holds_each_range`.
    }
}
