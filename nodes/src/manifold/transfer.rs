//! `manifold.transfer`: the weathering of one sample applied to a target degree map — material
//! transfer with weathering effects (thesis §6; Wang et al. 2006). The target may have any size,
//! e.g. a degree map `synthesis.texture` laid onto a larger surface.
//!
//! Each target pixel of degree ω_t gets A(ω_t), the source sample's appearance at that degree
//! along its path (`path.rs`), plus the variation of one source pixel s: v(s) − A(ω(s)). Which s:
//! - with the optional `source` map (the `source` output of `synthesis.texture` run on the
//!   sample's degree map), the pixel the target pixel was synthesized from — the transferred
//!   maps then carry the sample's texture of appearance along with its degrees;
//! - otherwise a pixel among the `neighbours` of degree nearest ω_t, picked by a seeded hash,
//!   so the variation is one that really occurs at that degree.
//!
//! Using another sample's `maps` and `degree` with the same target swaps in that sample's
//! manifold: the same layout of weathering in a different material.

use super::evolve::relight;
use super::path::Path;
use crate::reflectance::ward::PairGeometry;
use crate::support::rng;
use crate::types::{BrdfMap, Direction, DirectionPair, Image, WARD_PARAMS};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Source pixels averaged for the appearance at a degree.
    #[schemars(range(min = 1))]
    pub neighbours: u32,
    /// Keep a source pixel's variation (false: every pixel of a degree looks the same).
    pub variation: bool,
    /// Light direction [θ, φ] of the preview, degrees.
    pub light: [f64; 2],
    /// View direction [θ, φ] of the preview, degrees.
    pub view: [f64; 2],
    /// Seed of the pick among pixels of the same degree (without a source map).
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            neighbours: 8,
            variation: true,
            light: [15.0, 0.0],
            view: [0.0, 0.0],
            seed: 1,
        }
    }
}

pub struct Transfer;

impl Node for Transfer {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "manifold.transfer",
            version: 1,
            doc: "Applies a sample's weathering to a target degree map of any size: the sample's appearance at each target degree along its path, plus a source pixel's own variation (from a synthesis source map, or picked among pixels of that degree).",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("maps", BrdfMap::TYPE, "the source sample's Ward parameters"),
                Port::input("degree", Image::TYPE, "the source sample's degree, 1 channel"),
                Port::input("target", Image::TYPE, "the target's degree, first channel in [0, 1]"),
                Port::optional("source", Image::TYPE, "per target pixel the source pixel x/(W−1), y/(H−1) (synthesis.texture's source)"),
            ],
            outputs: vec![
                Port::output("maps", BrdfMap::TYPE, "Ward parameters over the target"),
                Port::output("preview", Image::TYPE, "the target relit under `light`, linear"),
                Port::output("mean_degree", "Scalar", "mean target degree"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let maps = inputs.get::<BrdfMap>("maps")?;
        let degree = inputs.get::<Image>("degree")?;
        let target = inputs.get::<Image>("target")?;
        let source = inputs.opt::<Image>("source")?;
        let n = maps.width * maps.height;
        if n == 0 {
            return Err(NodeError::input("maps", "the source maps are empty"));
        }
        if (degree.width, degree.height) != (maps.width, maps.height) {
            return Err(NodeError::input(
                "degree",
                format!(
                    "{} × {} for {} × {} maps",
                    degree.width, degree.height, maps.width, maps.height
                ),
            ));
        }
        for (port, img) in [("degree", degree), ("target", target)] {
            if let Some(i) =
                (0..img.width * img.height).find(|i| !img.data[i * img.channels].is_finite())
            {
                return Err(NodeError::input(
                    port,
                    format!("pixel ({}, {}) is not finite", i % img.width, i / img.width),
                ));
            }
        }
        if let Some(s) = source {
            if (s.width, s.height) != (target.width, target.height) || s.channels < 3 {
                return Err(NodeError::input(
                    "source",
                    format!(
                        "{} × {} × {} for a {} × {} target (needs the same size and x, y channels)",
                        s.width, s.height, s.channels, target.width, target.height
                    ),
                ));
            }
            if s.data
                .iter()
                .any(|v| !(v.is_finite() && (-1e-3..=1.0 + 1e-3).contains(v)))
            {
                return Err(NodeError::input("source", "coordinates must be in [0, 1]"));
            }
        }
        for (name, d) in [("light", p.light), ("view", p.view)] {
            if !(0.0..90.0).contains(&d[0]) || !d[1].is_finite() {
                return Err(NodeError::param(name, "θ must be in [0°, 90°)"));
            }
        }
        let omega: Vec<f64> = (0..n)
            .map(|i| (degree.data[i * degree.channels] as f64).clamp(0.0, 1.0))
            .collect();
        let path = Path::new(maps, &omega, p.neighbours.max(1) as usize);
        let tn = target.width * target.height;
        let mut data = Vec::with_capacity(tn * WARD_PARAMS);
        let mut sum = 0.0;
        for t in 0..tn {
            let w = (target.data[t * target.channels] as f64).clamp(0.0, 1.0);
            sum += w;
            let s = match source {
                Some(src) => {
                    let sx = (src.data[t * src.channels] as f64 * (maps.width - 1) as f64).round()
                        as usize;
                    let sy = (src.data[t * src.channels + 1] as f64 * (maps.height - 1) as f64)
                        .round() as usize;
                    sy.min(maps.height - 1) * maps.width + sx.min(maps.width - 1)
                }
                None => path.pixel_near(w, rng::unit(rng::hash(p.seed, &[t as u64]))),
            };
            let q = if p.variation {
                path.moved(s, path.degree_of(s), w)
            } else {
                let a = path.at(w);
                [
                    a[0].max(0.0),
                    a[1].max(0.0),
                    a[2].max(0.0),
                    a[3].max(0.0),
                    a[4].exp(),
                ]
            };
            data.extend(q);
        }
        let out = BrdfMap {
            width: target.width,
            height: target.height,
            data,
        };
        let geo = PairGeometry::flat(&DirectionPair {
            view: Direction::degrees(p.view[0], p.view[1]),
            light: Direction::degrees(p.light[0], p.light[1]),
        });
        let preview = relight(&out, &geo, 1.0);
        Ok(Outputs::new()
            .with("maps", out)
            .with("preview", preview)
            .with("mean_degree", Scalar(sum / tn.max(1) as f64)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::weathering::sample::{generate, path as true_path, Params as SampleParams};
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    fn sample() -> (BrdfMap, Image) {
        let s = generate(&SampleParams {
            size: 32,
            ..SampleParams::default()
        });
        (s.maps, s.degree)
    }

    fn run(p: &Params, inputs: Inputs) -> Result<Outputs, NodeError> {
        mesoflow_testkit::node::run(&Transfer, p, &inputs)
    }

    fn maps_of(out: &Outputs) -> BrdfMap {
        out.value::<BrdfMap>("maps").clone()
    }

    #[test]
    fn identity_source_map_gives_back_the_sample() {
        // Target = the sample's own degree and each pixel its own source: A(ω) + v − A(ω) = v,
        // so only rounding (1e-12 relative) may differ.
        let (maps, degree) = sample();
        let (w, h) = (degree.width, degree.height);
        let source = Image {
            width: w,
            height: h,
            channels: 3,
            data: (0..w * h)
                .flat_map(|i| {
                    [
                        (i % w) as f32 / (w - 1) as f32,
                        (i / w) as f32 / (h - 1) as f32,
                        0.0,
                    ]
                })
                .collect(),
        };
        let degree = Arc::new(degree);
        let out = run(
            &Params::default(),
            Inputs::new()
                .with("maps", Arc::new(maps.clone()))
                .with("degree", degree.clone())
                .with("target", degree)
                .with("source", Arc::new(source)),
        )
        .unwrap();
        for (a, b) in maps_of(&out).data.iter().zip(&maps.data) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-12), "{a} vs {b}");
        }
    }

    #[test]
    fn a_ramp_target_follows_the_true_weathering_path() {
        // A 96 × 8 target whose degree rises from 0 to 1 left to right: the column means must
        // follow the generator's own path (weathering::sample::path, independent of this code)
        // up to the sample's per-pixel variation (ρd ± 4%, ρs ± 8%, averaged over 8 rows and
        // the path's 8 neighbours) and the fit of degree to the true path: 12% of each value.
        let (maps, degree) = sample();
        let target = Image {
            width: 96,
            height: 8,
            channels: 1,
            data: (0..96 * 8).map(|i| (i % 96) as f32 / 95.0).collect(),
        };
        let out = run(
            &Params::default(),
            Inputs::new()
                .with("maps", Arc::new(maps))
                .with("degree", Arc::new(degree))
                .with("target", Arc::new(target)),
        )
        .unwrap();
        let m = maps_of(&out);
        assert_eq!((m.width, m.height), (96, 8));
        for x in [8usize, 48, 88] {
            let want = true_path(x as f64 / 95.0);
            for (d, want) in want.iter().enumerate() {
                let mean = (0..8).map(|y| m.pixel(y * 96 + x)[d]).sum::<f64>() / 8.0;
                assert!(
                    (mean - *want).abs() <= 0.12 * *want,
                    "x {x}, parameter {d}: {mean} vs {}",
                    *want
                );
            }
        }
    }

    #[test]
    fn mismatched_inputs_are_clear_errors() {
        let (maps, degree) = sample();
        let target = Arc::new(Image {
            width: 10,
            height: 10,
            channels: 1,
            data: vec![0.5; 100],
        });
        let src = Arc::new(Image {
            width: 9,
            height: 10,
            channels: 3,
            data: vec![0.5; 270],
        });
        let e = run(
            &Params::default(),
            Inputs::new()
                .with("maps", Arc::new(maps))
                .with("degree", Arc::new(degree))
                .with("target", target)
                .with("source", src),
        )
        .unwrap_err();
        assert!(e.to_string().contains("source"), "{e}");
    }
}
