//! `points.synthetic`: built-in point sets with a known 2-D manifold, for trying and checking the
//! manifold nodes without data: the swiss roll and the S-curve (scikit-learn's `make_swiss_roll`
//! and `make_s_curve` shapes, drawn from our own seeded randomness), with optional uniform
//! jitter. The `parameter` output is each point's position along the manifold's long
//! axis, the ground truth an embedding's first component should follow.

use crate::support::rng;
use crate::types::PointSet;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    SwissRoll,
    SCurve,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// `swiss_roll` or `s_curve` (scikit-learn's make_swiss_roll and make_s_curve).
    pub shape: Shape,
    /// Number of points.
    #[schemars(range(min = 2, max = 10000000))]
    pub n: u32,
    /// Uniform jitter of each coordinate, ± noise/2.
    #[schemars(range(min = 0.0))]
    pub noise: f64,
    /// Seed of the points and their noise.
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            shape: Shape::SwissRoll,
            n: 2000,
            noise: 0.0,
            seed: 1,
        }
    }
}

pub struct PointsSynthetic;

impl Node for PointsSynthetic {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "points.synthetic",
            version: 1,
            doc: "Built-in 3-D point sets on a 2-D manifold (swiss roll, S-curve), seeded, with the position along the manifold as ground truth.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::output("points", PointSet::TYPE, "n × 3"),
                Port::output("parameter", PointSet::TYPE, "n × 1: position along the manifold"),
            ],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let (points, t) = generate(p);
        Ok(Outputs::new().with("points", points).with("parameter", t))
    }
}

pub fn generate(p: &Params) -> (PointSet, PointSet) {
    let n = p.n.max(2) as usize;
    let u = |i: usize, s: u64| rng::unit(rng::hash(p.seed, &[i as u64, s]));
    let mut data = Vec::with_capacity(3 * n);
    let mut t = Vec::with_capacity(n);
    for i in 0..n {
        let (a, h) = (u(i, 0), u(i, 1));
        let (x, tt) = match p.shape {
            Shape::SwissRoll => {
                let t = 1.5 * PI * (1.0 + 2.0 * a);
                ([t * t.cos(), 21.0 * h, t * t.sin()], t)
            }
            Shape::SCurve => {
                let t = 3.0 * PI * (a - 0.5);
                ([t.sin(), 2.0 * h, t.signum() * (t.cos() - 1.0)], t)
            }
        };
        for (c, v) in x.iter().enumerate() {
            data.push(v + p.noise * (u(i, 2 + c as u64) - 0.5));
        }
        t.push(tt);
    }
    (
        PointSet { n, dims: 3, data },
        PointSet {
            n,
            dims: 1,
            data: t,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifold::rank::spearman;
    use crate::manifold::{isomap, knn};

    #[test]
    fn isomap_unrolls_the_swiss_roll() {
        // The roll's angle t is the ground truth of its long axis: Isomap's first component
        // must order the points by it (|ρ| > 0.99; the roll is 3.3 turns wide, k = 10).
        let (x, t) = generate(&Params {
            n: 1500,
            ..Default::default()
        });
        let r = isomap::isomap(&x, &knn::knn(&x, 10).unwrap(), &isomap::Params::default()).unwrap();
        let y0: Vec<f64> = (0..x.n).map(|i| r.embedding.data[2 * i]).collect();
        let rho = spearman(&y0, &t.data);
        eprintln!("Spearman ρ(first component, t) = {rho:.4}");
        assert!(rho.abs() > 0.99, "{rho}");
        assert_eq!(r.graph_components, 1);
    }
}
