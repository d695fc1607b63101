//! `image.ramp`: a one-channel linear gradient, for guide images (e.g. where a target should
//! weather most: the bottom of a wall, where water runs).

use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Width in pixels.
    #[schemars(range(min = 1, max = 16384))]
    pub width: u32,
    /// Height in pixels.
    #[schemars(range(min = 1, max = 16384))]
    pub height: u32,
    /// Direction of increase, degrees: 0 = left to right, 90 = top to bottom.
    pub angle: f64,
    /// Value at the start and at the end of the ramp (|v| ≤ 10³⁰: the difference of two larger
    /// values can overflow to infinity).
    #[schemars(range(min = -1e30, max = 1e30))]
    pub from: f64,
    /// Value at the end of the ramp.
    #[schemars(range(min = -1e30, max = 1e30))]
    pub to: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            width: 256,
            height: 256,
            angle: 90.0,
            from: 0.0,
            to: 1.0,
        }
    }
}

pub struct Ramp;

impl Node for Ramp {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "image.ramp",
            version: 1,
            doc: "A one-channel linear gradient from `from` to `to` along `angle` (0° = left to right, 90° = top to bottom).",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("image", Image::TYPE, "the ramp, 1 channel")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let (w, h) = (p.width as usize, p.height as usize);
        let (dx, dy) = (p.angle.to_radians().cos(), p.angle.to_radians().sin());
        // Project pixel centres on the direction; the extreme corners map to `from` and `to`.
        let proj = |x: f64, y: f64| x * dx + y * dy;
        let corners = [
            proj(0.5, 0.5),
            proj(w as f64 - 0.5, 0.5),
            proj(0.5, h as f64 - 0.5),
            proj(w as f64 - 0.5, h as f64 - 0.5),
        ];
        let lo = corners.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let span = (hi - lo).max(1e-12);
        let data = (0..w * h)
            .map(|i| {
                let t = (proj((i % w) as f64 + 0.5, (i / w) as f64 + 0.5) - lo) / span;
                (p.from + (p.to - p.from) * t) as f32
            })
            .collect();
        Ok(Outputs::new().with(
            "image",
            Image {
                width: w,
                height: h,
                channels: 1,
                data,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;

    #[test]
    fn vertical_ramp_runs_top_to_bottom() {
        let p = Params {
            width: 3,
            height: 5,
            from: 0.2,
            to: 0.6,
            ..Params::default()
        };
        let out = mesoflow_testkit::node::run(&Ramp, &p, &Inputs::new()).unwrap();
        let img = out.value::<Image>("image").clone();
        // Rows 0 … 4 at 0.2 + 0.4 · y / 4 (closed form), the same across a row.
        for y in 0..5 {
            for x in 0..3 {
                let want = 0.2 + 0.4 * y as f32 / 4.0;
                assert!((img.data[y * 3 + x] - want).abs() < 1e-6, "({x}, {y})");
            }
        }
    }
}
