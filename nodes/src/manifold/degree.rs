//! `manifold.degree`: the weathering degree of every point (thesis eq. 6.69–6.71),
//! ω(x) = δ(x, X0) / (δ(x, X0) + δ(x, X1)), δ the geodesic distance over the kNN graph to the
//! nearest point of the least-weathered set X0 and of the most-weathered set X1 — one
//! multi-source Dijkstra per set. Points are pixels, row-major, so the result is an image.
//!
//! The sets come as pixel lists (`x0`, `x1`: [[x, y], …]) and/or masks (`x0_mask`, `x1_mask`:
//! any image of the sample's size, a pixel is marked where its first channel is > ½). A
//! disconnected graph is joined as `manifold.isomap` joins it, with a warning; a point that
//! still cannot reach a set would get no degree, which joining rules out.

use super::graph::Graph;
use crate::types::{Image, KnnGraph, PointSet};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Least weathered pixels, [x, y].
    pub x0: Vec<[u32; 2]>,
    /// Most weathered pixels, [x, y].
    pub x1: Vec<[u32; 2]>,
    /// Image width; 0 = the masks' width.
    pub width: u32,
}

pub struct Degree;

impl Node for Degree {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "manifold.degree",
            version: 1,
            doc: "Weathering degree ω = δ(x, X0) / (δ(x, X0) + δ(x, X1)) by geodesic distances over the kNN graph to the marked least- and most-weathered sets.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("points", PointSet::TYPE, "appearance vectors, one per pixel"),
                Port::input("graph", KnnGraph::TYPE, "their kNN graph"),
                Port::optional("x0_mask", Image::TYPE, "least weathered pixels (> ½)"),
                Port::optional("x1_mask", Image::TYPE, "most weathered pixels (> ½)"),
                Port::optional("truth", Image::TYPE, "a true degree map, for the spearman metric"),
            ],
            outputs: vec![
                Port::output("degree", Image::TYPE, "ω per pixel, 1 channel"),
                Port::output("graph_components", "Scalar", "connected components before joining"),
                Port::optional_output("spearman", "Scalar", "rank correlation with `truth` (absent without it)"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let points = inputs.get::<PointSet>("points")?;
        let graph = inputs.get::<KnnGraph>("graph")?;
        if graph.n != points.n {
            return Err(NodeError::input(
                "graph",
                format!("{} vertices for {} points", graph.n, points.n),
            ));
        }
        let masks = [
            inputs.opt::<Image>("x0_mask")?,
            inputs.opt::<Image>("x1_mask")?,
        ];
        let width = match (p.width, masks.iter().flatten().next()) {
            (0, Some(m)) => m.width,
            (0, None) => {
                return Err(NodeError::param(
                    "width",
                    "needed when no mask is connected (the points are pixels, row-major)",
                ))
            }
            (w, _) => w as usize,
        };
        if points.n % width != 0 {
            return Err(NodeError::param(
                "width",
                format!("{} points do not fill rows of {width}", points.n),
            ));
        }
        let height = points.n / width;
        let mut sets = Vec::new();
        for (s, (list, mask)) in [(&p.x0, masks[0]), (&p.x1, masks[1])]
            .into_iter()
            .enumerate()
        {
            let (param, port) = (["x0", "x1"][s], ["x0_mask", "x1_mask"][s]);
            let mut set = Vec::new();
            for &[x, y] in list {
                if x as usize >= width || y as usize >= height {
                    return Err(NodeError::param(
                        param,
                        format!("pixel [{x}, {y}] is outside the {width} × {height} sample"),
                    ));
                }
                set.push(y as usize * width + x as usize);
            }
            if let Some(m) = mask {
                if m.width != width || m.height != height {
                    return Err(NodeError::input(
                        port,
                        format!(
                            "{} × {} mask for a {width} × {height} sample",
                            m.width, m.height
                        ),
                    ));
                }
                set.extend((0..points.n).filter(|i| m.data[i * m.channels] > 0.5));
            }
            set.sort_unstable();
            set.dedup();
            if set.is_empty() {
                return Err(NodeError::param(
                    param,
                    format!("no pixel is marked in {param} (nor in {port})"),
                ));
            }
            sets.push(set);
        }
        if let Some(i) = sets[0].iter().find(|i| sets[1].binary_search(i).is_ok()) {
            return Err(NodeError::param(
                "x1",
                format!(
                    "pixel [{}, {}] is marked both least and most weathered",
                    i % width,
                    i / width
                ),
            ));
        }
        let (omega, components) = degree(points, graph, &sets[0], &sets[1]);
        if components > 1 {
            ctx.warn(format!(
                "the kNN graph (k = {}) has {components} connected components; joined each pair by its closest points — raise k for a connected graph",
                graph.k
            ));
        }
        let spearman = match inputs.opt::<Image>("truth")? {
            None => None,
            Some(t) if t.width == width && t.height == height => {
                let truth: Vec<f64> = (0..points.n)
                    .map(|i| t.data[i * t.channels] as f64)
                    .collect();
                Some(super::rank::spearman(&omega, &truth))
            }
            Some(t) => {
                return Err(NodeError::input(
                    "truth",
                    format!(
                        "{} × {} image for a {width} × {height} sample",
                        t.width, t.height
                    ),
                ))
            }
        };
        let out = Outputs::new();
        let out = match spearman {
            Some(rho) => out.with("spearman", Scalar(rho)),
            None => out,
        };
        Ok(out
            .with(
                "degree",
                Image {
                    width,
                    height,
                    channels: 1,
                    data: omega.iter().map(|v| *v as f32).collect(),
                },
            )
            .with("graph_components", Scalar(components as f64)))
    }
}

/// ω per point and the number of graph components before joining. The sets must be non-empty
/// and disjoint, so δ0 + δ1 > 0 wherever the graph's edges have positive length; where two
/// marked points coincide in appearance (zero-length edges) the ratio is taken as ½.
pub fn degree(points: &PointSet, knn: &KnnGraph, x0: &[usize], x1: &[usize]) -> (Vec<f64>, usize) {
    let mut g = Graph::from_knn(knn);
    let components = g.join_components(points);
    let c = g.compact();
    let (d0, d1) = rayon::join(|| c.dijkstra(x0), || c.dijkstra(x1));
    let omega = d0
        .iter()
        .zip(&d1)
        .map(|(a, b)| if a + b > 0.0 { a / (a + b) } else { 0.5 })
        .collect();
    (omega, components)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::fit_ward;
    use crate::manifold::knn::knn;
    use crate::manifold::rank::spearman;
    use crate::weathering::sample::{generate, Params as SampleParams};

    #[test]
    fn follows_the_true_degree_of_the_sample() {
        // Spearman ρ between the recovered and the true degree, on the built-in sample through
        // the whole chain (capture → Ward fit → kNN → degree): 0.9985 through the graph at this
        // size; the bound 0.994 is within 4× of that distance from 1 (the issue asked 0.95).
        let s = generate(&SampleParams {
            size: 32,
            ..SampleParams::default()
        });
        let ctx = NodeContext::detached(None);
        let f = fit_ward::fit(&ctx, &s.btf, &fit_ward::Params::default()).unwrap();
        let points = fit_ward::appearance(&f.maps, [1.0; 3]);
        let graph = knn(&points, 10).unwrap();
        let marked =
            |m: &Image| -> Vec<usize> { (0..m.data.len()).filter(|i| m.data[*i] > 0.5).collect() };
        let (x0, x1) = (marked(&s.least), marked(&s.most));
        assert!(!x0.is_empty() && !x1.is_empty());
        let (omega, _) = degree(&points, &graph, &x0, &x1);
        let truth: Vec<f64> = s.degree.data.iter().map(|v| *v as f64).collect();
        let rho = spearman(&omega, &truth);
        eprintln!("Spearman ρ(recovered, true degree) = {rho:.4}");
        assert!(rho >= 0.994, "{rho}");
        assert!(omega.iter().all(|w| (0.0..=1.0).contains(w)));
    }

    #[test]
    fn marked_sets_get_zero_and_one_and_a_line_is_linear() {
        // Points on a line 0..9 with k = 2: geodesics are |i − j|, so with X0 = {0}, X1 = {9}
        // ω(i) = i / 9 exactly (the closed form of eq. 6.71 on a path graph).
        let points = PointSet {
            n: 10,
            dims: 1,
            data: (0..10).map(|i| i as f64).collect(),
        };
        let (omega, c) = degree(&points, &knn(&points, 2).unwrap(), &[0], &[9]);
        assert_eq!(c, 1);
        for (i, w) in omega.iter().enumerate() {
            assert!((w - i as f64 / 9.0).abs() < 1e-12, "{i}: {w}");
        }
    }

    fn run(p: Params) -> Result<Outputs, NodeError> {
        let points = PointSet {
            n: 8,
            dims: 1,
            data: (0..8).map(|i| i as f64).collect(),
        };
        let graph = knn(&points, 2).unwrap();
        let inputs = Inputs::new()
            .with("points", std::sync::Arc::new(points))
            .with("graph", std::sync::Arc::new(graph));
        mesoflow_testkit::node::run(&Degree, &p, &inputs)
    }

    #[test]
    fn empty_overlapping_and_outside_sets_are_clear_errors() {
        let e = run(Params {
            x0: vec![],
            x1: vec![[3, 1]],
            width: 4,
        })
        .err()
        .unwrap();
        assert!(e.to_string().contains("no pixel is marked in x0"), "{e}");
        let e = run(Params {
            x0: vec![[1, 0], [2, 1]],
            x1: vec![[2, 1]],
            width: 4,
        })
        .err()
        .unwrap();
        assert!(e.to_string().contains("both least and most"), "{e}");
        let e = run(Params {
            x0: vec![[4, 0]],
            x1: vec![[2, 1]],
            width: 4,
        })
        .err()
        .unwrap();
        assert!(e.to_string().contains("outside"), "{e}");
        let e = run(Params {
            x0: vec![[0, 0]],
            x1: vec![[2, 1]],
            width: 0,
        })
        .err()
        .unwrap();
        assert!(e.to_string().contains("width"), "{e}");
        let ok = run(Params {
            x0: vec![[0, 0]],
            x1: vec![[3, 1]],
            width: 4,
        })
        .unwrap();
        assert!(ok.get("degree").is_some());
    }
}
