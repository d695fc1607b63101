//! `scalar.constant` and `scalar.affine`: trivial nodes, so that scheduling overhead can be measured
//! on graphs of any shape, and so that sweeps can be tried on a graph that runs in microseconds.

use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ConstantParams {
    /// The value.
    pub value: f64,
}

pub struct Constant;

impl Node for Constant {
    type Params = ConstantParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "scalar.constant",
            version: 1,
            doc: "A number.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("value", Scalar::TYPE, "the value")],
            disk_cache: false,
        }
    }

    fn run(
        &self,
        _ctx: &NodeContext,
        p: &ConstantParams,
        _inputs: &Inputs,
    ) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("value", Scalar(p.value)))
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct AffineParams {
    /// Multiplier of the input.
    pub scale: f64,
    /// Added after scaling.
    pub offset: f64,
}

impl Default for AffineParams {
    fn default() -> Self {
        AffineParams {
            scale: 1.0,
            offset: 0.0,
        }
    }
}

pub struct Affine;

impl Node for Affine {
    type Params = AffineParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "scalar.affine",
            version: 1,
            doc: "y = scale · x + offset (x = 0 when not connected).",
            device: DevicePreference::Cpu,
            inputs: vec![Port::optional("x", Scalar::TYPE, "input number")],
            outputs: vec![Port::output("y", Scalar::TYPE, "scale · x + offset")],
            disk_cache: false,
        }
    }

    fn run(
        &self,
        _ctx: &NodeContext,
        p: &AffineParams,
        inputs: &Inputs,
    ) -> Result<Outputs, NodeError> {
        let x = inputs.opt::<Scalar>("x")?.map_or(0.0, |s| s.0);
        let y = p.scale * x + p.offset;
        if !y.is_finite() {
            return Err(NodeError::Failed(format!(
                "{} · {x} + {} is not finite",
                p.scale, p.offset
            )));
        }
        Ok(Outputs::new().with("y", Scalar(y)))
    }
}
