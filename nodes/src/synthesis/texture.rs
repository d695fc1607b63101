//! `synthesis.texture`: example-based texture synthesis by texture optimisation (Kwatra et al.
//! 2005; see `optimize.rs`), multi-resolution, with optional guidance channels: an exemplar guide
//! paired with a target guide steers where each kind of texture goes, so a weathering-degree map
//! can be laid onto a target of another size and shape.
//!
//! Outputs the image, a source map (for each output pixel the exemplar pixel it came from, as
//! x/(W−1), y/(H−1) in the red and green channels) and the energy: the mean over the final grid
//! of patches of the RMS difference per channel to the nearest exemplar patch (guide channels
//! included, weighted as in the search).

use super::optimize::{self, Settings};
use super::patches::Plane;
use crate::types::Image;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Output width; 0 = the target guide's, else the exemplar's.
    pub width: u32,
    /// Output height; 0 = the target guide's, else the exemplar's.
    pub height: u32,
    /// Pyramid levels (coarse to fine).
    #[schemars(range(min = 1, max = 8))]
    pub levels: u32,
    /// Levels left out at the fine end (0 to levels − 1): the output is 2^k times smaller per
    /// side and is exactly the full run's result after that level (the same stages, the same
    /// seeds), for a view that cannot show the finest detail. The planner sets it.
    #[schemars(range(min = 0, max = 7))]
    pub stop_level: u32,
    /// Patch sizes in pixels (at least 2), used largest first at every level where they fit.
    #[schemars(length(min = 1), inner(range(min = 2)))]
    pub patch_sizes: Vec<u32>,
    /// Search-and-update iterations per patch size per level.
    #[schemars(range(min = 1, max = 100))]
    pub iterations: u32,
    /// Robust exponent r of E = Σ‖x_p − z_p‖^r (Kwatra: 0.8; 2 = plain least squares).
    #[schemars(range(max = 2.0), extend("exclusiveMinimum" = 0.0))]
    pub exponent: f64,
    /// Output tiles seamlessly (patches wrap around its edges).
    pub periodic: bool,
    /// Weight of the guide channels against the colour channels in the patch distance (0 to 10⁶).
    #[schemars(range(min = 0.0, max = 1e6))]
    pub guide_weight: f64,
    /// PatchMatch rounds per search.
    #[schemars(range(min = 1, max = 64))]
    pub search_rounds: u32,
    /// Seed of the initial nearest-patch field and of the random search.
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            width: 0,
            height: 0,
            levels: 3,
            stop_level: 0,
            patch_sizes: vec![32, 16, 8],
            iterations: 4,
            exponent: 0.8,
            periodic: false,
            guide_weight: 1.0,
            search_rounds: 4,
            seed: 1,
        }
    }
}

pub struct Texture;

impl Node for Texture {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "synthesis.texture",
            version: 3,
            doc: "Example-based texture synthesis by texture optimisation (Kwatra et al. 2005), multi-resolution, PatchMatch search, optional guide channels; outputs the image, its source map and its energy (mean nearest-patch RMS distance).",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("exemplar", Image::TYPE, "the example texture"),
                Port::optional("exemplar_guide", Image::TYPE, "guide channels over the exemplar (its size)"),
                Port::optional("target_guide", Image::TYPE, "guide channels over the output (same channel count)"),
            ],
            outputs: vec![
                Port::output("image", Image::TYPE, "the synthesized texture, the exemplar's channels"),
                Port::output("source", Image::TYPE, "exemplar pixel per output pixel: x/(W−1), y/(H−1), 0"),
                Port::output("energy", "Scalar", "mean RMS distance per channel from each output patch to its nearest exemplar patch"),
                Port::output("energy_start", "Scalar", "the same after the first search of the finest stage"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        let smallest = p
            .patch_sizes
            .iter()
            .min()
            .ok_or_else(|| NodeError::param("patch_sizes", "give at least one size"))?;
        if *smallest < 2 {
            return Err(NodeError::param(
                "patch_sizes",
                "sizes must be at least 2 pixels",
            ));
        }
        if !(p.exponent.is_finite() && p.exponent > 0.0 && p.exponent <= 2.0) {
            return Err(NodeError::param("exponent", "must be in (0, 2]"));
        }
        if p.stop_level >= p.levels {
            return Err(NodeError::param(
                "stop_level",
                format!(
                    "{} leaves no level of {}: at most levels − 1",
                    p.stop_level, p.levels
                ),
            ));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let ex = inputs.get::<Image>("exemplar")?;
        let ex_guide = inputs.opt::<Image>("exemplar_guide")?;
        let target_guide = inputs.opt::<Image>("target_guide")?;
        let mut sizes: Vec<usize> = p.patch_sizes.iter().map(|&s| s as usize).collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        sizes.dedup();
        let smallest = *sizes
            .last()
            .ok_or_else(|| NodeError::param("patch_sizes", "give at least one size"))?;
        if ex.width < smallest || ex.height < smallest {
            return Err(NodeError::input(
                "exemplar",
                format!(
                    "the exemplar ({} × {}) is smaller than the smallest patch ({smallest} px): use a smaller patch_sizes entry or a larger exemplar",
                    ex.width, ex.height
                ),
            ));
        }
        check_values("exemplar", ex)?;
        let guides = match (ex_guide, target_guide) {
            (None, None) => None,
            (Some(eg), Some(tg)) => {
                if (eg.width, eg.height) != (ex.width, ex.height) {
                    return Err(NodeError::input(
                        "exemplar_guide",
                        format!(
                            "{} × {} for a {} × {} exemplar",
                            eg.width, eg.height, ex.width, ex.height
                        ),
                    ));
                }
                if tg.channels != eg.channels {
                    return Err(NodeError::input(
                        "target_guide",
                        format!(
                            "{} channels for an exemplar guide of {}",
                            tg.channels, eg.channels
                        ),
                    ));
                }
                check_values("exemplar_guide", eg)?;
                check_values("target_guide", tg)?;
                Some((eg, tg))
            }
            (Some(_), None) => {
                return Err(NodeError::input(
                    "target_guide",
                    "an exemplar guide needs a target guide",
                ))
            }
            (None, Some(_)) => {
                return Err(NodeError::input(
                    "exemplar_guide",
                    "a target guide needs an exemplar guide",
                ))
            }
        };
        let default = guides.map_or((ex.width, ex.height), |(_, tg)| (tg.width, tg.height));
        let width = if p.width == 0 {
            default.0
        } else {
            p.width as usize
        };
        let height = if p.height == 0 {
            default.1
        } else {
            p.height as usize
        };
        if let Some((_, tg)) = guides {
            if (tg.width, tg.height) != (width, height) {
                return Err(NodeError::input(
                    "target_guide",
                    format!(
                        "{} × {} for a {width} × {height} output",
                        tg.width, tg.height
                    ),
                ));
            }
        }
        for (name, v) in [("width", width), ("height", height)] {
            if v < smallest {
                return Err(NodeError::param(
                    name,
                    format!("{v} px is smaller than the smallest patch ({smallest} px)"),
                ));
            }
            if v > 1 << 14 {
                return Err(NodeError::param(name, format!("{v} px is more than 16384")));
            }
        }
        let scale = p.guide_weight.sqrt() as f32;
        let exemplar = features(ex, guides.map(|(eg, _)| eg), scale);
        let target = guides.map(|(_, tg)| plane(tg, scale));
        let settings = Settings {
            width,
            height,
            levels: p.levels as usize,
            stop: p.stop_level as usize,
            sizes,
            iterations: p.iterations as usize,
            exponent: p.exponent,
            periodic: p.periodic,
            rounds: p.search_rounds as usize,
            seed: p.seed,
        };
        if p.stop_level > 0 {
            let stages = optimize::plan((ex.width, ex.height), (width, height), &settings);
            if stages.last().map(|(l, _)| *l) != Some(p.stop_level as usize) {
                return Err(NodeError::param(
                    "stop_level",
                    format!(
                        "no patch size fits level {} (the exemplar {} × {} and the output {width} × {height} halved {} times): stop at a finer level",
                        p.stop_level, ex.width, ex.height, p.stop_level
                    ),
                ));
            }
        }
        let out = optimize::synthesize(
            &exemplar,
            ex.channels,
            target.as_ref(),
            &settings,
            |done, total| {
                ctx.check_cancel()?;
                ctx.progress(done as u64, total as u64);
                Ok::<(), NodeError>(())
            },
        )?;
        let energy_start = out
            .stages
            .last()
            .and_then(|s| s.distances.first())
            .map_or(out.energy, |e| *e);
        let (sw, sh) = (
            (out.exemplar_size.0 - 1).max(1) as f32,
            (out.exemplar_size.1 - 1).max(1) as f32,
        );
        let (width, height) = (out.image.width, out.image.height);
        let source = Image {
            width,
            height,
            channels: 3,
            data: out
                .sources
                .iter()
                .flat_map(|&(x, y)| [x as f32 / sw, y as f32 / sh, 0.0])
                .collect(),
        };
        Ok(Outputs::new()
            .with(
                "image",
                Image {
                    width,
                    height,
                    channels: ex.channels,
                    data: out.image.data,
                },
            )
            .with("source", source)
            .with("energy", Scalar(out.energy))
            .with("energy_start", Scalar(energy_start)))
    }
}

/// Pixels must be finite and at most [`MAX_VALUE`] in magnitude: patch distances are f32 sums of
/// squares over up to 32² pixels, channels and a guide weight up to 10⁶, which overflow beyond.
fn check_values(port: &str, img: &Image) -> Result<(), NodeError> {
    match img
        .data
        .iter()
        .position(|v| !(v.is_finite() && v.abs() <= MAX_VALUE))
    {
        Some(i) => {
            let px = i / img.channels;
            Err(NodeError::input(
                port,
                format!(
                    "pixel ({}, {}) is {}: values must be finite and within ±{MAX_VALUE:e}",
                    px % img.width,
                    px / img.width,
                    img.data[i]
                ),
            ))
        }
        None => Ok(()),
    }
}

const MAX_VALUE: f32 = 1e12;

fn plane(img: &Image, scale: f32) -> Plane {
    Plane {
        width: img.width,
        height: img.height,
        channels: img.channels,
        data: img.data.iter().map(|v| v * scale).collect(),
    }
}

/// The exemplar's colour channels followed by its guide channels times `scale`.
fn features(ex: &Image, guide: Option<&Image>, scale: f32) -> Plane {
    let Some(g) = guide else {
        return plane(ex, 1.0);
    };
    let c = ex.channels + g.channels;
    let mut data = Vec::with_capacity(ex.width * ex.height * c);
    for i in 0..ex.width * ex.height {
        data.extend_from_slice(&ex.data[i * ex.channels..(i + 1) * ex.channels]);
        data.extend(
            g.data[i * g.channels..(i + 1) * g.channels]
                .iter()
                .map(|v| v * scale),
        );
    }
    Plane {
        width: ex.width,
        height: ex.height,
        channels: c,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Image {
        Image {
            width: w,
            height: h,
            channels: 1,
            data: (0..w * h).map(|i| f(i % w, i / w)).collect(),
        }
    }

    fn run(p: &Params, inputs: Inputs) -> Result<Outputs, NodeError> {
        mesoflow_testkit::node::run(&Texture, p, &inputs)
    }

    fn scalar(out: &Outputs, name: &str) -> f64 {
        out.scalar(name)
    }

    fn img(out: &Outputs, name: &str) -> Image {
        out.take::<Image>(name)
    }

    /// Soft diagonal stripes of period 12, a texture whose every patch is easy to tell apart from
    /// a seam.
    fn stripes(w: usize, h: usize) -> Image {
        image(w, h, |x, y| {
            (0.5 + 0.5 * (std::f32::consts::TAU * (x + 2 * y) as f32 / 12.0).sin()).clamp(0.0, 1.0)
        })
    }

    #[test]
    fn output_has_the_exemplar_size_unless_told_otherwise() {
        let ex = Arc::new(stripes(40, 30));
        let p = Params {
            levels: 2,
            patch_sizes: vec![8],
            iterations: 2,
            ..Params::default()
        };
        let out = run(&p, Inputs::new().with("exemplar", ex.clone())).unwrap();
        let im = img(&out, "image");
        assert_eq!((im.width, im.height, im.channels), (40, 30, 1));
        let p2 = Params {
            width: 52,
            height: 33,
            ..p
        };
        let im = img(
            &run(&p2, Inputs::new().with("exemplar", ex)).unwrap(),
            "image",
        );
        assert_eq!((im.width, im.height), (52, 33));
    }

    #[test]
    fn stop_level_halves_the_output_per_level_or_says_why_it_cannot() {
        let ex = Arc::new(stripes(40, 32));
        let p = Params {
            width: 64,
            height: 48,
            levels: 3,
            stop_level: 1,
            patch_sizes: vec![8],
            iterations: 1,
            ..Params::default()
        };
        let out = run(&p, Inputs::new().with("exemplar", ex.clone())).unwrap();
        assert_eq!(
            (img(&out, "image").width, img(&out, "image").height),
            (32, 24)
        );
        assert_eq!(
            (img(&out, "source").width, img(&out, "source").height),
            (32, 24)
        );
        // Source coordinates are in the level's exemplar (20 × 16), normalised to [0, 1].
        assert!(img(&out, "source")
            .data
            .iter()
            .all(|v| (0.0..=1.0).contains(v)));
        // Level 2's exemplar is 10 × 8: an 8-pixel patch is more than half of it.
        let e = run(
            &Params {
                stop_level: 2,
                ..p.clone()
            },
            Inputs::new().with("exemplar", ex),
        )
        .unwrap_err();
        assert!(e.to_string().contains("stop_level"), "{e}");
        assert!(Texture.check(&Params { stop_level: 3, ..p }).is_err());
    }

    #[test]
    fn periodic_output_has_no_seam_where_it_wraps() {
        // Patches straddling the wrap-around edge are measured against the exemplar's (exhaustive
        // search). With `periodic` they were part of the optimisation and match like the rest;
        // without it they straddle two unrelated edges. The bound: the seam patches of the
        // periodic output are within 2× its interior energy and below the non-periodic seam's.
        let ex = Arc::new(stripes(36, 36));
        let mut energies = Vec::new();
        for periodic in [true, false] {
            let p = Params {
                width: 48,
                height: 48,
                levels: 2,
                patch_sizes: vec![12, 8],
                iterations: 3,
                periodic,
                ..Params::default()
            };
            let out = run(&p, Inputs::new().with("exemplar", ex.clone())).unwrap();
            let im = img(&out, "image");
            let plane = super::plane(&im, 1.0);
            let exp = super::plane(&ex, 1.0);
            let seam = |x0: usize, y0: usize| {
                let mut patch = Vec::new();
                for i in 0..8 {
                    for j in 0..8 {
                        patch.push(plane.pixel((x0 + j) % 48, (y0 + i) % 48)[0]);
                    }
                }
                let m = crate::synthesis::patches::nearest_exact(&exp, 8, &patch);
                (m.d2 as f64 / 64.0).sqrt()
            };
            let across: f64 = (0..12)
                .map(|k| seam(44, k * 4) + seam(k * 4, 44))
                .sum::<f64>()
                / 24.0;
            let inside: f64 = (0..12)
                .map(|k| seam(20, k * 3) + seam(k * 3, 20))
                .sum::<f64>()
                / 24.0;
            energies.push((across, inside));
        }
        let ((pa, pi), (na, _)) = (energies[0], energies[1]);
        assert!(
            pa <= 2.0 * pi.max(0.01),
            "periodic: seam {pa} vs inside {pi}"
        );
        assert!(pa < na, "periodic seam {pa} vs non-periodic {na}");
    }

    #[test]
    fn a_guide_puts_each_texture_where_the_target_asks() {
        // Exemplar: dark noise on the left half, bright noise on the right; the guide is 0 and 1
        // over the halves. Target guide: 1 on the top half, 0 below. The output must be bright
        // on top and dark below.
        let noise = |x: usize, y: usize| {
            crate::support::rng::unit(crate::support::rng::hash(3, &[x as u64, y as u64])) as f32
                * 0.2
        };
        let ex = image(40, 40, |x, y| {
            if x < 20 {
                noise(x, y)
            } else {
                0.8 + noise(x, y)
            }
        });
        let eg = image(40, 40, |x, _| if x < 20 { 0.0 } else { 1.0 });
        let tg = image(48, 48, |_, y| if y < 24 { 1.0 } else { 0.0 });
        let p = Params {
            levels: 2,
            patch_sizes: vec![8],
            iterations: 3,
            guide_weight: 4.0,
            ..Params::default()
        };
        let out = run(
            &p,
            Inputs::new()
                .with("exemplar", Arc::new(ex))
                .with("exemplar_guide", Arc::new(eg))
                .with("target_guide", Arc::new(tg)),
        )
        .unwrap();
        let im = img(&out, "image");
        assert_eq!((im.width, im.height), (48, 48));
        let mean = |rows: std::ops::Range<usize>| {
            let n = rows.len() * 48;
            rows.flat_map(|y| (0..48).map(move |x| (x, y)))
                .map(|(x, y)| im.data[y * 48 + x])
                .sum::<f32>()
                / n as f32
        };
        // Away from the boundary (4 rows either side): bright ≈ 0.9, dark ≈ 0.1.
        assert!(mean(0..20) > 0.8, "top {}", mean(0..20));
        assert!(mean(28..48) < 0.2, "bottom {}", mean(28..48));
    }

    #[test]
    fn clear_errors() {
        let small = Arc::new(stripes(6, 6));
        let e = run(&Params::default(), Inputs::new().with("exemplar", small)).unwrap_err();
        assert!(
            e.to_string().contains("smaller than the smallest patch"),
            "{e}"
        );
        let ex = Arc::new(stripes(20, 20));
        let only = Inputs::new()
            .with("exemplar", ex.clone())
            .with("exemplar_guide", ex.clone());
        let e = run(
            &Params {
                patch_sizes: vec![8],
                ..Params::default()
            },
            only,
        )
        .unwrap_err();
        assert!(e.to_string().contains("target_guide"), "{e}");
        let e = run(
            &Params {
                patch_sizes: vec![],
                ..Params::default()
            },
            Inputs::new().with("exemplar", ex.clone()),
        )
        .unwrap_err();
        assert!(e.to_string().contains("patch_sizes"), "{e}");
        let mut bad = stripes(20, 20);
        bad.data[45] = f32::NAN;
        let e = run(
            &Params {
                patch_sizes: vec![8],
                ..Params::default()
            },
            Inputs::new().with("exemplar", Arc::new(bad)),
        )
        .unwrap_err();
        assert!(e.to_string().contains("(5, 2)"), "{e}");
    }

    #[test]
    fn constant_image_synthesizes_to_itself() {
        let out = run(
            &Params {
                width: 24,
                height: 24,
                patch_sizes: vec![8],
                ..Params::default()
            },
            Inputs::new().with("exemplar", Arc::new(image(16, 16, |_, _| 0.42))),
        )
        .unwrap();
        assert!(img(&out, "image")
            .data
            .iter()
            .all(|v| (v - 0.42).abs() < 1e-6));
        assert_eq!(scalar(&out, "energy"), 0.0);
        let src = img(&out, "source");
        assert!(src.data.iter().all(|v| (0.0..=1.0).contains(v)));
    }
}
