//! `points.read`: a generic point set from an NPY file of shape (n, D), f32 or f64, C order —
//! so the manifold nodes can be used, and checked, on any data (e.g. the arrays a
//! scikit-learn script writes).

use crate::types::PointSet;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// NPY file of shape (n, D), f32 or f64, relative to the graph file.
    pub path: String,
}

pub struct PointsRead;

impl Node for PointsRead {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "points.read",
            version: 1,
            doc: "Point set from an NPY file of shape (n, D), f32 or f64.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::output("points", PointSet::TYPE, "n points in D dimensions"),
                Port::output("count", "Scalar", "n"),
            ],
            disk_cache: false,
        }
    }

    fn files(&self, p: &Params, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.path)])
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let points = read(&ctx.input_path("path", &p.path)?)?;
        let n = points.n as f64;
        Ok(Outputs::new()
            .with("points", points)
            .with("count", Scalar(n)))
    }
}

pub fn read(path: &Path) -> Result<PointSet, NodeError> {
    let a = crate::support::npy::read(path, 2, "(n, D)")?;
    let (n, dims) = (a.shape[0], a.shape[1]);
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(NodeError::file(
            path,
            format!("point {} coordinate {} is not finite", i / dims, i % dims),
        ));
    }
    Ok(PointSet {
        n,
        dims,
        data: a.data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_f32_and_f64_and_refuses_bad_shapes() {
        let dir = tempfile::tempdir().unwrap();
        let f64_path = dir.path().join("a.npy");
        let bytes =
            crate::support::formats::encode_npy(&[3, 2], &[0.0f64, 1.0, 2.0, 3.0, 4.0, 5.5])
                .unwrap();
        std::fs::write(&f64_path, bytes).unwrap();
        let p = read(&f64_path).unwrap();
        assert_eq!((p.n, p.dims), (3, 2));
        assert_eq!(p.point(2), &[4.0, 5.5]);
        let f32_path = dir.path().join("b.npy");
        let bytes = crate::support::formats::encode_npy(&[2, 1], &[1.5f32, -2.0]).unwrap();
        std::fs::write(&f32_path, bytes).unwrap();
        assert_eq!(read(&f32_path).unwrap().data, vec![1.5, -2.0]);
        let bad = dir.path().join("c.npy");
        let bytes = crate::support::formats::encode_npy(&[2, 1, 1], &[1.0f32, 2.0]).unwrap();
        std::fs::write(&bad, bytes).unwrap();
        assert!(read(&bad).unwrap_err().to_string().contains("2-D"));
        let nan = dir.path().join("d.npy");
        let bytes = crate::support::formats::encode_npy(&[1, 2], &[1.0f64, f64::NAN]).unwrap();
        std::fs::write(&nan, bytes).unwrap();
        assert!(read(&nan).unwrap_err().to_string().contains("not finite"));
    }
}
