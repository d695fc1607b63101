//! `heightfield.edit`: geometry edits of a recovered mesostructure (seed 003 §3, "geometry
//! replacement"): invert (bumps become dents, over the same range), scale about the mean, blend
//! with another height field, or replace it by another — given as heights, or as a normal map
//! that is integrated first (`heightfield.from_normals`' least squares, periodic). The other tile
//! is resampled (bilinear, periodic) to this one's size, so a material's geometry can come from
//! a sample captured at another resolution.

use super::from_normals;
use crate::types::{HeightField, Image, NormalMap};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Operation {
    /// h' = max + min − h: bumps become dents.
    Invert,
    /// h' = mean + amount·(h − mean).
    Scale,
    /// h' = (1 − amount)·h + amount·other.
    Blend,
    /// h' = amount·other (the other tile's heights, scaled).
    Replace,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The edit.
    pub operation: Operation,
    /// Scale factor (scale, replace) or the other tile's share (blend, in [0, 1]).
    #[schemars(range(min = -100.0, max = 100.0))]
    pub amount: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            operation: Operation::Invert,
            amount: 1.0,
        }
    }
}

pub struct Edit;

impl Node for Edit {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "heightfield.edit",
            version: 1,
            doc: "Edit a height field: invert, scale, blend with or replace by another height field or normal map (resampled to fit).",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("height", HeightField::TYPE, "the tile to edit, heights in texels"),
                Port::optional("other", HeightField::TYPE, "blend/replace: the other tile's heights"),
                Port::optional("other_normals", NormalMap::TYPE, "blend/replace: the other tile as normals (integrated first)"),
            ],
            outputs: vec![
                Port::output("height", HeightField::TYPE, "the edited heights"),
                Port::output("preview", Image::TYPE, "the edited heights scaled to [0, 1], grey"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        // The schema bounds `amount` to [-100, 100]; a blend's share is narrower.
        if p.operation == Operation::Blend && !(0.0..=1.0).contains(&p.amount) {
            return Err(NodeError::param(
                "amount",
                "a blend's share must be in [0, 1]",
            ));
        }
        Ok(())
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let hf = inputs.get::<HeightField>("height")?;
        let other = || -> Result<Vec<f32>, NodeError> {
            let tile = match (
                inputs.opt::<HeightField>("other")?,
                inputs.opt::<NormalMap>("other_normals")?,
            ) {
                (Some(_), Some(_)) => {
                    return Err(NodeError::input(
                        "other_normals",
                        "connect `other` or `other_normals`, not both",
                    ))
                }
                (Some(o), None) => o.clone(),
                (None, Some(n)) => from_normals::integrate(n, "other_normals")?,
                (None, None) => {
                    return Err(NodeError::param(
                        "operation",
                        "blend and replace need the `other` or `other_normals` input",
                    ));
                }
            };
            Ok(resample(&tile, hf.width, hf.height))
        };
        let (lo, hi) = hf.min_max();
        let mean =
            (hf.data.iter().map(|v| *v as f64).sum::<f64>() / hf.data.len().max(1) as f64) as f32;
        let a = p.amount as f32;
        let data: Vec<f32> = match p.operation {
            Operation::Invert => hf.data.iter().map(|v| hi + lo - v).collect(),
            Operation::Scale => hf.data.iter().map(|v| mean + a * (v - mean)).collect(),
            Operation::Blend => hf
                .data
                .iter()
                .zip(other()?)
                .map(|(v, o)| (1.0 - a) * v + a * o)
                .collect(),
            Operation::Replace => other()?.iter().map(|o| a * o).collect(),
        };
        let out = HeightField {
            width: hf.width,
            height: hf.height,
            data,
        };
        let preview = from_normals::preview(&out);
        Ok(Outputs::new().with("height", out).with("preview", preview))
    }
}

/// Bilinear, periodic resampling of a tile to w × h samples (sample centres aligned).
pub fn resample(tile: &HeightField, w: usize, h: usize) -> Vec<f32> {
    if (tile.width, tile.height) == (w, h) {
        return tile.data.clone();
    }
    let (sx, sy) = (tile.width as f64 / w as f64, tile.height as f64 / h as f64);
    (0..w * h)
        .map(|i| {
            let (u, v) = (
                ((i % w) as f64 + 0.5) * sx - 0.5,
                ((i / w) as f64 + 0.5) * sy - 0.5,
            );
            super::grid::bilerp(tile.width, tile.height, u, v, |t| [tile.data[t]])[0] as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    fn run(
        p: Params,
        hf: HeightField,
        other: Option<HeightField>,
    ) -> Result<HeightField, NodeError> {
        let mut inputs = Inputs::new().with("height", Arc::new(hf));
        if let Some(o) = other {
            inputs = inputs.with("other", Arc::new(o));
        }
        Edit.check(&p)?;
        let out = mesoflow_testkit::node::run(&Edit, &p, &inputs)?;
        Ok(out.value::<HeightField>("height").clone())
    }

    #[test]
    fn invert_scale_blend_and_replace_do_what_they_say() {
        let hf = HeightField::from_fn(4, 2, |x, y| (x + 4 * y) as f32);
        let inv = run(
            Params {
                operation: Operation::Invert,
                amount: 1.0,
            },
            hf.clone(),
            None,
        )
        .unwrap();
        assert_eq!(inv.data, (0..8).rev().map(|v| v as f32).collect::<Vec<_>>());
        let half = run(
            Params {
                operation: Operation::Scale,
                amount: 0.5,
            },
            hf.clone(),
            None,
        )
        .unwrap();
        assert_eq!(half.data[0], 3.5 - 1.75);
        let other = HeightField::from_fn(4, 2, |_, _| 10.0);
        let mix = run(
            Params {
                operation: Operation::Blend,
                amount: 0.25,
            },
            hf.clone(),
            Some(other.clone()),
        )
        .unwrap();
        assert_eq!(mix.data[4], 0.75 * 4.0 + 2.5);
        let rep = run(
            Params {
                operation: Operation::Replace,
                amount: 2.0,
            },
            hf.clone(),
            Some(other),
        )
        .unwrap();
        assert!(rep.data.iter().all(|v| *v == 20.0));
        let e = run(
            Params {
                operation: Operation::Blend,
                amount: 0.5,
            },
            hf.clone(),
            None,
        )
        .unwrap_err();
        assert!(
            matches!(&e, NodeError::Param { param, .. } if param == "operation"),
            "{e}"
        );
        let e = run(
            Params {
                operation: Operation::Blend,
                amount: 1.5,
            },
            hf,
            None,
        )
        .unwrap_err();
        assert!(
            matches!(&e, NodeError::Param { param, .. } if param == "amount"),
            "{e}"
        );
    }

    #[test]
    fn resampling_a_periodic_ramp_keeps_its_samples_where_they_coincide() {
        // Halving a 8-wide tile: sample x of the result sits at 2x + 0.5 of the source, the mean
        // of its samples 2x and 2x + 1. Doubling back lands between samples, linearly.
        let src = HeightField::from_fn(8, 1, |x, _| x as f32);
        assert_eq!(resample(&src, 4, 1), vec![0.5, 2.5, 4.5, 6.5]);
        let up = resample(&HeightField::from_fn(2, 1, |x, _| 4.0 * x as f32), 4, 1);
        // Centres at −0.25, 0.25, 0.75, 1.25 of the source (periodic: −0.25 mixes 4 and 0).
        assert_eq!(up, vec![1.0, 1.0, 3.0, 3.0]);
    }
}
