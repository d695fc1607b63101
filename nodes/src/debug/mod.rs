//! `debug.sleep`: waits, checking for cancellation every 10 ms, then passes its input on. It makes
//! scheduling visible (parallel branches overlap) and lets tests cancel a run mid-node.

use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Milliseconds to wait.
    #[schemars(range(min = 0, max = 3_600_000))]
    pub ms: u64,
    /// Fail after waiting (to test failure handling).
    pub fail: bool,
    /// Ignore cancellation (a node stuck in a loop: to test a second Ctrl-C).
    pub deaf: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            ms: 100,
            fail: false,
            deaf: false,
        }
    }
}

pub struct Sleep;

impl Node for Sleep {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "debug.sleep",
            version: 1,
            doc: "Waits `ms` milliseconds (cancellable), then outputs its input (or 0); for testing the scheduler.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::optional("x", Scalar::TYPE, "passed through")],
            outputs: vec![Port::output("y", Scalar::TYPE, "the input, or 0")],
            disk_cache: true,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let start = Instant::now();
        let total = Duration::from_millis(p.ms);
        while start.elapsed() < total {
            if !p.deaf {
                ctx.check_cancel()?;
            }
            ctx.progress(start.elapsed().as_millis() as u64, p.ms);
            std::thread::sleep(
                Duration::from_millis(10).min(total.saturating_sub(start.elapsed())),
            );
        }
        if p.fail {
            return Err(NodeError::Failed(
                "failed on purpose (`fail` is true)".into(),
            ));
        }
        let x = inputs.opt::<Scalar>("x")?.map_or(0.0, |s| s.0);
        Ok(Outputs::new().with("y", Scalar(x)))
    }
}
