//! `material.transfer`: one recovered material's reflectance on another's geometry (seed 003 §3,
//! "material transfer"): the Ward maps of material A are laid over material B's height field —
//! repeated at their own texel scale (`tile`) or stretched so one tile of A covers one tile of B
//! (`stretch`, bilinear and periodic, parameter by parameter) — and B's normals are recomputed,
//! so the pair renders (`btf.capture` with `maps`, `render.relief`) as a new material.

use crate::heightfield::normals::normals_cpu;
use crate::types::{BrdfMap, HeightField, Image, NormalMap, WARD_PARAMS};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Fit {
    /// A's texels keep their size: A's tile repeats (or is cut) over B's.
    Tile,
    /// A's tile is resampled to B's size.
    Stretch,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// How A's maps are fitted to B's tile.
    pub fit: Fit,
}

impl Default for Params {
    fn default() -> Self {
        Params { fit: Fit::Tile }
    }
}

pub struct Transfer;

impl Node for Transfer {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "material.transfer",
            version: 1,
            doc: "Material A's Ward maps on material B's height field (tiled or stretched), with B's normals recomputed.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("maps", BrdfMap::TYPE, "material A's reflectance (Ward per pixel)"),
                Port::input("height", HeightField::TYPE, "material B's geometry, heights in texels"),
            ],
            outputs: vec![
                Port::output("maps", BrdfMap::TYPE, "A's reflectance at B's size"),
                Port::output("height", HeightField::TYPE, "B's heights (unchanged)"),
                Port::output("normals", NormalMap::TYPE, "B's normals (central differences)"),
                Port::output("albedo", Image::TYPE, "the transferred diffuse albedo ρd, RGB"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let a = inputs.get::<BrdfMap>("maps")?;
        let b = inputs.get::<HeightField>("height")?;
        if a.width == 0 || a.height == 0 {
            return Err(NodeError::input("maps", "is empty"));
        }
        let (w, h) = (b.width, b.height);
        let data: Vec<f64> = match p.fit {
            Fit::Tile => (0..w * h)
                .flat_map(|i| {
                    a.pixel((i / w % a.height) * a.width + i % w % a.width)
                        .to_vec()
                })
                .collect(),
            Fit::Stretch => stretch(a, w, h),
        };
        let maps = BrdfMap {
            width: w,
            height: h,
            data,
        };
        let albedo = Image {
            width: w,
            height: h,
            channels: 3,
            data: maps
                .data
                .chunks_exact(WARD_PARAMS)
                .flat_map(|px| [px[0] as f32, px[1] as f32, px[2] as f32])
                .collect(),
        };
        let normals = NormalMap {
            width: w,
            height: h,
            data: normals_cpu(b, 1.0),
        };
        Ok(Outputs::new()
            .with("maps", maps)
            .with("height", b.clone())
            .with("normals", normals)
            .with("albedo", albedo))
    }
}

/// Bilinear, periodic resampling of every parameter plane (centres aligned).
fn stretch(a: &BrdfMap, w: usize, h: usize) -> Vec<f64> {
    let (sx, sy) = (a.width as f64 / w as f64, a.height as f64 / h as f64);
    (0..w * h)
        .flat_map(|i| {
            let (u, v) = (
                ((i % w) as f64 + 0.5) * sx - 0.5,
                ((i / w) as f64 + 0.5) * sy - 0.5,
            );
            crate::heightfield::grid::bilerp(a.width, a.height, u, v, |t| {
                let p = a.pixel(t);
                [p[0], p[1], p[2], p[3], p[4]]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    #[test]
    fn tiling_repeats_and_stretching_resamples_material_a_over_b() {
        // A: 2×1 pixels, ρd 0.2 then 0.6 (all channels), ρs 0, α 0.1 then 0.3.
        let a = BrdfMap {
            width: 2,
            height: 1,
            data: vec![0.2, 0.2, 0.2, 0.0, 0.1, 0.6, 0.6, 0.6, 0.0, 0.3],
        };
        let b = HeightField::from_fn(4, 2, |x, _| x as f32);
        let run = |fit| {
            let inputs = Inputs::new()
                .with("maps", Arc::new(a.clone()))
                .with("height", Arc::new(b.clone()));
            let out = mesoflow_testkit::node::run(&Transfer, &Params { fit }, &inputs).unwrap();
            out.value::<BrdfMap>("maps").clone()
        };
        let tiled = run(Fit::Tile);
        let rho: Vec<f64> = tiled.data.chunks(5).map(|p| p[0]).collect();
        assert_eq!(rho, vec![0.2, 0.6, 0.2, 0.6, 0.2, 0.6, 0.2, 0.6]);
        // Stretched ×2: centres at −0.25, 0.25, 0.75, 1.25 of A (periodic: −0.25 lies between
        // A's pixel 1 and pixel 0), so ρd 0.25·0.6 + 0.75·0.2, 0.75·0.2 + 0.25·0.6, then 0.5 twice.
        let stretched = run(Fit::Stretch);
        let rho: Vec<f64> = stretched.data.chunks(5).take(4).map(|p| p[0]).collect();
        let want = [0.3, 0.3, 0.5, 0.5];
        assert!(
            rho.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-12),
            "{rho:?}"
        );
    }
}
