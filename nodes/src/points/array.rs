//! `points.array`: a point set from an NPY array (n, D), kept in f64.

use crate::support::npy::ArrayParams;
use crate::types::PointSet;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use std::path::{Path, PathBuf};

pub struct PointsArray;

impl Node for PointsArray {
    type Params = ArrayParams;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "points.array",
            version: 1,
            doc: "Point set from an NPY array (n, D), kept in f64.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output(
                "points",
                PointSet::TYPE,
                "n points in D dimensions",
            )],
            disk_cache: false,
        }
    }

    fn files(&self, p: &ArrayParams, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.data)])
    }

    fn run(&self, ctx: &NodeContext, p: &ArrayParams, _: &Inputs) -> Result<Outputs, NodeError> {
        let points = super::read::read(&ctx.input_path("data", &p.data)?)?;
        Ok(Outputs::new().with("points", points))
    }
}
