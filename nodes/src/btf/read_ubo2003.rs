//! `btf.read_ubo2003`: a folder (searched recursively) of UBO2003-named images — JPEG, PNG, EXR or
//! HDR, one per direction pair — as a `Btf`. 8-bit images (the JPEGs of the Bonn sets) are
//! sRGB-decoded to linear; 16-bit PNG, EXR and HDR are taken as linear (the design's rule). Optional texel crop, integer box downsampling and direction subsets let a user work on
//! a window of a large set. Pairs are ordered by the files' running index when every name has
//! one (so a written BTF reads back in its own order), else view-major by angle.

use super::ubo2003::{self, Name};
use crate::support::formats;
use crate::types::Btf;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Folder of images, relative to the graph file; searched recursively.
    pub path: String,
    /// Texel window [x, y, width, height] of the full images.
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
    /// Integer box-downsampling factor applied after the crop.
    #[serde(default = "one")]
    #[schemars(range(min = 1, max = 64))]
    pub downsample: u32,
    /// Keep only these view directions [θ, φ] (degrees).
    #[serde(default)]
    pub views: Option<Vec<[f64; 2]>>,
    /// Keep only these light directions [θ, φ] (degrees).
    #[serde(default)]
    pub lights: Option<Vec<[f64; 2]>>,
    /// Require every view × light combination present (a measured grid); false accepts any list.
    #[serde(default = "yes")]
    pub grid: bool,
    /// Refuse a BTF larger than this (GB); default: 80% of physical memory.
    #[serde(default)]
    pub memory_budget_gb: Option<f64>,
}

fn one() -> u32 {
    1
}
fn yes() -> bool {
    true
}

pub struct ReadUbo2003;

const EXTENSIONS: &[&str] = &["jpg", "jpeg", "png", "exr", "hdr"];

/// Every UBO2003-named image under `dir`, sorted by path. Each folder is walked once (a link
/// back to one already walked is passed over: two links to `.` once walked forever, issue 43),
/// at most [`DEPTH`] deep; only regular files are images (a FIFO named like one blocked the
/// read); an angle past what UBO2003 names hold (θ over 90°, φ of 360° or more) is refused by
/// file.
fn list(dir: &Path) -> Result<Vec<(PathBuf, Name)>, NodeError> {
    if !dir.is_dir() {
        return Err(NodeError::file(dir, "no such folder"));
    }
    let mut out = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    let mut stack = vec![(dir.to_path_buf(), 0usize)];
    while let Some((d, depth)) = stack.pop() {
        let Ok(real) = std::fs::canonicalize(&d) else {
            continue;
        };
        if !seen.insert(real) || depth > DEPTH {
            continue;
        }
        let entries = std::fs::read_dir(&d).map_err(|e| NodeError::file(&d, e))?;
        for e in entries {
            let path = e.map_err(|e| NodeError::file(&d, e))?.path();
            let Ok(meta) = std::fs::metadata(&path) else {
                continue;
            };
            if meta.is_dir() {
                stack.push((path, depth + 1));
                continue;
            }
            if !meta.is_file() {
                continue;
            }
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .unwrap_or_default();
            let name = path
                .file_name()
                .and_then(|n| n.to_str())
                .and_then(ubo2003::parse);
            if let (true, Some(name)) = (EXTENSIONS.contains(&ext.as_str()), name) {
                let [tl, pl, tv, pv] = name.angles;
                if tl > 90 || tv > 90 || pl >= 360 || pv >= 360 {
                    return Err(NodeError::file(
                        &path,
                        format!("its name's angles (light θ {tl}°, φ {pl}°, view θ {tv}°, φ {pv}°) are past θ 90° or φ 360°"),
                    ));
                }
                out.push((path, name));
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Folders below the named one that are walked at most.
const DEPTH: usize = 16;

fn matches(list: &Option<Vec<[f64; 2]>>, theta: u16, phi: u16) -> bool {
    list.as_ref().is_none_or(|l| {
        l.iter().any(|[t, p]| {
            (t - theta as f64).abs() < 1e-6
                && ((p - phi as f64).rem_euclid(360.0) < 1e-6
                    || (p - phi as f64).rem_euclid(360.0) > 360.0 - 1e-6
                    || theta == 0)
        })
    })
}

fn angles(a: [u16; 2]) -> String {
    format!("(θ {}°, φ {}°)", a[0], a[1])
}

impl Node for ReadUbo2003 {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "btf.read_ubo2003",
            version: 1,
            doc: "Reads a UBO2003-style folder of tl/pl/tv/pv-named images (JPEG, PNG, EXR, HDR) as a linear BTF; crop, downsample, direction subsets.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::output("btf", Btf::TYPE, "the BTF, linear RGB"),
                Port::output("preview", crate::types::Image::TYPE, "the first pair's image"),
            ],
            disk_cache: true,
        }
    }

    fn files(&self, p: &Params, base: &Path) -> Result<Vec<PathBuf>, NodeError> {
        Ok(list(&base.join(&p.path))?
            .into_iter()
            .map(|(p, _)| p)
            .collect())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let dir = ctx.input_path("path", &p.path)?;
        let all = list(&dir)?;
        if all.is_empty() {
            return Err(NodeError::param(
                "path",
                format!(
                    "no images named like tl015_pl060_tv000_pv000.{{jpg,png,exr,hdr}} under {}",
                    dir.display()
                ),
            ));
        }
        // One file per angle quadruple.
        let mut by_angles: BTreeMap<[u16; 4], (PathBuf, Name)> = BTreeMap::new();
        for (path, name) in all {
            if let Some((other, _)) = by_angles.get(&name.view_major()) {
                return Err(NodeError::param(
                    "path",
                    format!(
                        "duplicate direction pair (view {}, light {}): {} and {}",
                        angles([name.angles[2], name.angles[3]]),
                        angles([name.angles[0], name.angles[1]]),
                        other.display(),
                        path.display()
                    ),
                ));
            }
            by_angles.insert(name.view_major(), (path, name));
        }
        let kept: Vec<(PathBuf, Name)> = by_angles
            .into_values()
            .filter(|(_, n)| {
                matches(&p.views, n.angles[2], n.angles[3])
                    && matches(&p.lights, n.angles[0], n.angles[1])
            })
            .collect();
        if kept.is_empty() {
            return Err(NodeError::param(
                "views",
                "no image matches the requested view and light subsets",
            ));
        }
        if p.grid {
            let views: BTreeSet<[u16; 2]> = kept
                .iter()
                .map(|(_, n)| [n.angles[2], n.angles[3]])
                .collect();
            let lights: BTreeSet<[u16; 2]> = kept
                .iter()
                .map(|(_, n)| [n.angles[0], n.angles[1]])
                .collect();
            let have: BTreeSet<[u16; 4]> = kept.iter().map(|(_, n)| n.view_major()).collect();
            let missing: Vec<String> = views
                .iter()
                .flat_map(|v| lights.iter().map(move |l| (v, l)))
                .filter(|(v, l)| !have.contains(&[v[0], v[1], l[0], l[1]]))
                .map(|(v, l)| format!("view {} light {}", angles(*v), angles(*l)))
                .collect();
            if !missing.is_empty() {
                let shown: Vec<&str> = missing.iter().take(10).map(String::as_str).collect();
                return Err(NodeError::param(
                    "path",
                    format!(
                        "{} of {} × {} direction pairs are missing{}: {}{} (set \"grid\": false to read an incomplete set)",
                        missing.len(),
                        views.len(),
                        lights.len(),
                        if p.views.is_some() || p.lights.is_some() { " from the subset" } else { "" },
                        shown.join("; "),
                        if missing.len() > 10 { "; …" } else { "" }
                    ),
                ));
            }
        }
        let mut kept = kept;
        if kept.iter().all(|(_, n)| n.index.is_some()) {
            kept.sort_by_key(|(_, n)| (n.index, n.view_major()));
        }

        // The first image fixes the size; the window and factor must fit it.
        let first = formats::read_image(&kept[0].0)?;
        let (fw, fh) = (first.width, first.height);
        let [cx, cy, cw, ch] = p
            .crop
            .map(|c| c.map(|v| v as usize))
            .unwrap_or([0, 0, fw, fh]);
        if cw == 0 || ch == 0 || cx + cw > fw || cy + ch > fh {
            return Err(NodeError::param(
                "crop",
                format!("window [{cx}, {cy}, {cw}, {ch}] does not fit the {fw}×{fh} images"),
            ));
        }
        let f = p.downsample.max(1) as usize;
        if !cw.is_multiple_of(f) || !ch.is_multiple_of(f) {
            return Err(NodeError::param(
                "downsample",
                format!("{cw}×{ch} texels are not divisible by {f}"),
            ));
        }
        let (w, h) = (cw / f, ch / f);
        let bytes = (kept.len() * 3 * w * h * 4) as u64;
        crate::support::memory::check(
            bytes,
            &format!("a BTF of {} pairs × {w}×{h} texels × RGB f32", kept.len()),
            p.memory_budget_gb,
        )?;

        let plane = w * h;
        let mut data = vec![0f32; kept.len() * 3 * plane];
        let done = AtomicU64::new(0);
        let total = kept.len() as u64;
        data.par_chunks_mut(3 * plane.max(1))
            .zip(kept.par_iter())
            .enumerate()
            .try_for_each(|(i, (out, (path, _)))| -> Result<(), NodeError> {
                ctx.check_cancel()?;
                // The first image was decoded above for its size.
                let decoded;
                let img = if i == 0 {
                    &first
                } else {
                    decoded = formats::read_image(path)?;
                    &decoded
                };
                if (img.width, img.height) != (fw, fh) {
                    return Err(NodeError::file(
                        path,
                        format!(
                            "is {}×{}, the other images {fw}×{fh}",
                            img.width, img.height
                        ),
                    ));
                }
                if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
                    let px = i / img.channels;
                    return Err(NodeError::file(
                        path,
                        format!(
                            "pixel ({}, {}) is {} (not finite)",
                            px % fw,
                            px / fw,
                            img.data[i]
                        ),
                    ));
                }
                let c = img.channels;
                let sample = |x: usize, y: usize, ch: usize| -> f64 {
                    // Grey images give R = G = B.
                    img.data[(y * fw + x) * c + if c < 3 { 0 } else { ch }] as f64
                };
                for ch_i in 0..3 {
                    for y in 0..h {
                        for x in 0..w {
                            let mut s = 0.0;
                            for dy in 0..f {
                                for dx in 0..f {
                                    s += sample(cx + x * f + dx, cy + y * f + dy, ch_i);
                                }
                            }
                            out[ch_i * plane + y * w + x] = (s / (f * f) as f64) as f32;
                        }
                    }
                }
                ctx.progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
                Ok(())
            })?;
        let pairs = kept.iter().map(|(_, n)| n.pair()).collect();
        let btf = Btf {
            width: w,
            height: h,
            pairs,
            data,
        };
        let preview = btf.preview(0);
        Ok(Outputs::new().with("btf", btf).with("preview", preview))
    }
}
