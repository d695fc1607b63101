//! `btf.read_ubo2014`: a Bonn University UBO2014 `.btf` file (DFMF, FMF or PVF, see `ubo2014.rs`)
//! as a `Btf`, or — for the variants whose factors are linear RGB or YUV — directly as a
//! `BtfBasis` without expanding it. A texel window and a stride apply to the factors' texel maps
//! (exact for every variant), box downsampling to the maps of a basis (linear) or to the expanded
//! values; view and light subsets apply to the expanded BTF.
//!
//! Values follow mesoflow's convention (radiance under unit irradiance, cos θi included): a file
//! whose cosine flag says the cosine is not in its data has each pair multiplied by cos θi. The
//! header's RGB scale factor is reported, not applied.

use super::reconstruct::pair_into;
use super::ubo2014::{self, Ubo2014};
use crate::types::{Btf, BtfBasis, Direction};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Output {
    /// The expanded BTF (`btf` output).
    Btf,
    /// The factors as they are (`basis` output); linear RGB/YUV variants only.
    Basis,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The `.btf` file, relative to the graph file.
    pub path: String,
    /// Which output to produce.
    #[serde(default = "btf")]
    pub output: Output,
    /// Texel window [x, y, width, height].
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
    /// Keep every n-th texel of the window along each axis (btflib's strides).
    #[serde(default = "one")]
    #[schemars(range(min = 1, max = 64))]
    pub stride: u32,
    /// Integer box-downsampling factor after the crop and stride (the mean of f × f texels;
    /// the size must divide by it).
    #[serde(default = "one")]
    #[schemars(range(min = 1, max = 64))]
    pub downsample: u32,
    /// Keep only these view directions [θ, φ] (degrees, nearest within 0.5°); `btf` output.
    #[serde(default)]
    pub views: Option<Vec<[f64; 2]>>,
    /// Keep only these light directions [θ, φ] (degrees, nearest within 0.5°); `btf` output.
    #[serde(default)]
    pub lights: Option<Vec<[f64; 2]>>,
    /// Refuse an expanded BTF larger than this (GB); default: 80% of physical memory.
    #[serde(default)]
    pub memory_budget_gb: Option<f64>,
}

fn btf() -> Output {
    Output::Btf
}
fn one() -> u32 {
    1
}

pub struct ReadUbo2014;

impl Node for ReadUbo2014 {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.read_ubo2014",
            version: 1,
            doc: "A Bonn UBO2014 .btf file (DFMF, FMF, PVF and their older signatures) as a Btf, or its linear factors as a BtfBasis; crop, stride, box downsampling, direction subsets.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::optional_output("btf", Btf::TYPE, "the expanded BTF (output: btf)"),
                Port::optional_output("basis", BtfBasis::TYPE, "the factors, not expanded (output: basis)"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        if p.output == Output::Basis && (p.views.is_some() || p.lights.is_some()) {
            return Err(NodeError::param(
                if p.views.is_some() { "views" } else { "lights" },
                "direction subsets apply to the expanded BTF; use output: btf",
            ));
        }
        Ok(())
    }

    fn files(&self, p: &Params, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(vec![base.join(&p.path)])
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let path = ctx.input_path("path", &p.path)?;
        let bytes = std::fs::read(&path).map_err(|e| NodeError::file(&path, e))?;
        let file = ubo2014::parse(&bytes).map_err(|e| NodeError::file(&path, e))?;
        if file.header.rgb_scale != [1.0; 3] {
            ctx.warn(format!(
                "the header's RGB scale factor {:?} is not applied",
                file.header.rgb_scale
            ));
        }
        ctx.progress(1, 3);
        let out = match p.output {
            Output::Basis => {
                if let Some(why) = ubo2014::nonlinear(&file) {
                    return Err(NodeError::param(
                        "output",
                        format!(
                            "{}: the factors are not a linear basis because {why}; use output: btf",
                            path.display()
                        ),
                    ));
                }
                // The factors are linear: averaging their texel maps averages the values.
                let basis = boxed_basis(window(ubo2014::to_basis(&file, true), p)?, p)?;
                Outputs::new().with("basis", basis)
            }
            Output::Btf => {
                let basis = window(ubo2014::to_basis(&file, false), p)?;
                let keep = subset(&basis, p)?;
                crate::support::memory::check(
                    (keep.len() * 3 * basis.texels() * 4) as u64,
                    &format!(
                        "a BTF of {} pairs × {} texels × RGB f32",
                        keep.len(),
                        basis.texels()
                    ),
                    p.memory_budget_gb,
                )?;
                ctx.progress(2, 3);
                let btf = finish(&file, &basis, &keep).map_err(|e| NodeError::file(&path, e))?;
                // After the non-linear steps: a mean of logarithms is not a mean of values.
                Outputs::new().with("btf", boxed_btf(btf, p)?)
            }
        };
        ctx.progress(3, 3);
        Ok(out)
    }
}

/// The texel window and stride, applied to every block's per-texel maps and means.
fn window(mut b: BtfBasis, p: &Params) -> Result<BtfBasis, NodeError> {
    let [x0, y0, w, h] = p
        .crop
        .map_or([0, 0, b.width, b.height], |c| c.map(|v| v as usize));
    if w == 0 || h == 0 || x0 + w > b.width || y0 + h > b.height {
        return Err(NodeError::param(
            "crop",
            format!(
                "[{x0}, {y0}, {w}, {h}] is not inside the file's {}×{} texels",
                b.width, b.height
            ),
        ));
    }
    let s = p.stride as usize;
    if (x0, y0, w, h, s) == (0, 0, b.width, b.height, 1) {
        return Ok(b);
    }
    let xs: Vec<usize> = (x0..x0 + w).step_by(s).collect();
    let ys: Vec<usize> = (y0..y0 + h).step_by(s).collect();
    let (t_old, t_new) = (b.texels(), xs.len() * ys.len());
    let pick = |plane: &[f32]| -> Vec<f32> {
        ys.iter()
            .flat_map(|y| xs.iter().map(move |x| plane[y * b.width + x]))
            .collect()
    };
    for blk in &mut b.blocks {
        blk.maps = blk.maps.chunks(t_old).flat_map(&pick).collect();
        if blk.centring == crate::types::Centring::Texels {
            blk.mean = pick(&blk.mean);
        }
    }
    debug_assert!(b
        .blocks
        .iter()
        .all(|blk| blk.maps.len() == t_new * blk.rank()));
    b.width = xs.len();
    b.height = ys.len();
    Ok(b)
}

/// The downsampling factor, checked against a `w`×`h` size.
fn factor(p: &Params, w: usize, h: usize) -> Result<usize, NodeError> {
    let f = p.downsample.max(1) as usize;
    if !w.is_multiple_of(f) || !h.is_multiple_of(f) {
        return Err(NodeError::param(
            "downsample",
            format!("{w}×{h} texels (after crop and stride) are not divisible by {f}"),
        ));
    }
    Ok(f)
}

/// The mean of each f × f block of a row-major `w`-wide plane.
fn box_plane(plane: &[f32], w: usize, h: usize, f: usize) -> Vec<f32> {
    let (nw, nh) = (w / f, h / f);
    (0..nw * nh)
        .map(|i| {
            let (x, y) = (i % nw * f, i / nw * f);
            let sum: f64 = (0..f * f)
                .map(|k| plane[(y + k / f) * w + x + k % f] as f64)
                .sum();
            (sum / (f * f) as f64) as f32
        })
        .collect()
}

fn boxed_basis(mut b: BtfBasis, p: &Params) -> Result<BtfBasis, NodeError> {
    let f = factor(p, b.width, b.height)?;
    if f == 1 {
        return Ok(b);
    }
    let (w, h, t) = (b.width, b.height, b.texels());
    for blk in &mut b.blocks {
        blk.maps = blk
            .maps
            .chunks(t)
            .flat_map(|m| box_plane(m, w, h, f))
            .collect();
        if blk.centring == crate::types::Centring::Texels {
            blk.mean = box_plane(&blk.mean, w, h, f);
        }
    }
    (b.width, b.height) = (w / f, h / f);
    Ok(b)
}

fn boxed_btf(b: Btf, p: &Params) -> Result<Btf, NodeError> {
    let f = factor(p, b.width, b.height)?;
    if f == 1 {
        return Ok(b);
    }
    let (w, h) = (b.width, b.height);
    let data = b
        .data
        .chunks(w * h)
        .flat_map(|plane| box_plane(plane, w, h, f))
        .collect();
    Ok(Btf {
        width: w / f,
        height: h / f,
        pairs: b.pairs,
        data,
    })
}

/// The pairs kept by the view and light subsets, in the file's order.
fn subset(b: &BtfBasis, p: &Params) -> Result<Vec<usize>, NodeError> {
    let matches = |want: &Option<Vec<[f64; 2]>>,
                   name: &str,
                   get: &dyn Fn(usize) -> Direction|
     -> Result<Vec<bool>, NodeError> {
        let Some(list) = want else {
            return Ok(vec![true; b.pairs.len()]);
        };
        let mut keep = vec![false; b.pairs.len()];
        for d in list {
            let d = Direction::degrees(d[0], d[1]);
            let mut found = false;
            for (i, k) in keep.iter_mut().enumerate() {
                if get(i).angle_to(&d) < 0.5f64.to_radians() {
                    *k = true;
                    found = true;
                }
            }
            if !found {
                return Err(NodeError::param(
                    name,
                    format!(
                        "[{:.1}, {:.1}] is not within 0.5° of any of the file's directions",
                        d.theta.to_degrees(),
                        d.phi.to_degrees()
                    ),
                ));
            }
        }
        Ok(keep)
    };
    let v = matches(&p.views, "views", &|i| b.pairs[i].view)?;
    let l = matches(&p.lights, "lights", &|i| b.pairs[i].light)?;
    Ok((0..b.pairs.len()).filter(|i| v[*i] && l[*i]).collect())
}

/// The kept pairs expanded, with the file's non-linear steps and the cosine applied.
fn finish(file: &Ubo2014, basis: &BtfBasis, keep: &[usize]) -> Result<Btf, String> {
    // Only the kept pairs are expanded: the memory check counted those alone.
    let t = basis.texels();
    let owners = basis.column_owners();
    let mut data = vec![0f32; keep.len() * 3 * t];
    for (out, &pair) in data.chunks_mut(3 * t).zip(keep) {
        pair_into(basis, &owners, pair, out);
        let cos = if file.header.cosine_in_data {
            1.0
        } else {
            basis.pairs[pair].light.theta.cos()
        };
        for i in 0..t {
            let v = ubo2014::finish_values(file, [0, 1, 2].map(|c| out[c * t + i] as f64))?;
            for c in 0..3 {
                out[c * t + i] = (v[c] * cos) as f32;
            }
        }
    }
    Ok(Btf {
        width: basis.width,
        height: basis.height,
        pairs: keep.iter().map(|i| basis.pairs[*i]).collect(),
        data,
    })
}
