//! `image.colorize`: a one-channel image mapped to colour between two RGB values — linearly, or
//! split at a threshold into two flat colours (a two-material albedo or a mask from a height or
//! a photograph).

use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Colour (linear RGB) of the value 0, or of values below the threshold.
    pub low: [f64; 3],
    /// Colour of the value 1, or of values at or above the threshold.
    pub high: [f64; 3],
    /// Split at this value into the two flat colours; without it, interpolate (clamped to [0, 1]).
    pub threshold: Option<f64>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            low: [0.0; 3],
            high: [1.0; 3],
            threshold: None,
        }
    }
}

pub struct Colorize;

impl Node for Colorize {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.colorize",
            version: 1,
            doc: "Maps a one-channel image between two RGB colours, linearly or split at a threshold.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("image", Image::TYPE, "values (first channel)")],
            outputs: vec![Port::output("image", Image::TYPE, "RGB")],
            disk_cache: false,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        for (name, c) in [("low", p.low), ("high", p.high)] {
            if c.iter().any(|v| !v.is_finite()) {
                return Err(NodeError::param(name, "must be finite"));
            }
        }
        if p.threshold.is_some_and(|t| !t.is_finite()) {
            return Err(NodeError::param("threshold", "must be finite"));
        }
        Ok(())
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let img = inputs.get::<Image>("image")?;
        let data = img
            .data
            .chunks_exact(img.channels.max(1))
            .flat_map(|px| {
                let v = px[0] as f64;
                let t = match p.threshold {
                    Some(th) => f64::from(u8::from(v >= th)),
                    None => v.clamp(0.0, 1.0),
                };
                [0, 1, 2].map(|c| (p.low[c] + t * (p.high[c] - p.low[c])) as f32)
            })
            .collect();
        Ok(Outputs::new().with(
            "image",
            Image {
                width: img.width,
                height: img.height,
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
    fn values_map_between_the_colours_or_split_at_the_threshold() {
        let img = Image {
            width: 3,
            height: 1,
            channels: 1,
            data: vec![0.0, 0.25, 1.5],
        };
        let run = |p: Params| {
            let out = mesoflow_testkit::node::run(
                &Colorize,
                &p,
                &Inputs::new().with("image", Arc::new(img.clone())),
            )
            .unwrap();
            out.value::<Image>("image").data.clone()
        };
        let p = Params {
            low: [0.0, 0.2, 1.0],
            high: [1.0, 0.2, 0.0],
            threshold: None,
        };
        assert_eq!(
            run(p.clone()),
            vec![0.0, 0.2, 1.0, 0.25, 0.2, 0.75, 1.0, 0.2, 0.0]
        );
        assert_eq!(
            run(Params {
                threshold: Some(0.2),
                ..p
            }),
            vec![0.0, 0.2, 1.0, 1.0, 0.2, 0.0, 1.0, 0.2, 0.0]
        );
    }
}
