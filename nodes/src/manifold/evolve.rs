//! `manifold.evolve`: a time-variant sequence from one capture (thesis §6: the weathering
//! degree map advanced over time and mapped back to appearance through the manifold).
//!
//! - **Time**: frame f (0 … frames−1) has degree ω_f(x) = clamp(ω(x) ± f · `step` · rate(x), 0, 1)
//!   — `+` to weather, `−` to de-weather; rate is 1 or the optional `rate` image (its first
//!   channel, ≥ 0).
//! - **Back to appearance**: the sample's own pixels, ordered by their degree, are the manifold's
//!   samples along the weathering path. The appearance at degree w, A(w), is the mean Ward
//!   vector (ρd RGB, ρs, ln α) of the `neighbours` pixels whose degree is nearest w. Each pixel
//!   keeps its own variation, its offset from the path at its own degree: the pixel's vector at
//!   frame f is A(ω_f) + (v(x) − A(ω(x))), ρd and ρs clamped at 0. Frame 0 is the input exactly
//!   (to rounding).
//! - **Frames**: each frame is relit (flat sample, Ward × cos θi under unit irradiance, times
//!   `exposure`) from `view` and `light` and written as `<prefix>_NNN.png` (8-bit sRGB) and one
//!   looping `<prefix>.gif`.

use super::path::Path;
use crate::reflectance::ward::PairGeometry;
use crate::support::formats;
use crate::types::{BrdfMap, Direction, DirectionPair, Image};
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{
    Artifact, Artifacts, Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Course {
    Weather,
    Deweather,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Frames of the sequence (the first is the sample as captured).
    #[schemars(range(min = 1, max = 1000))]
    pub frames: u32,
    /// Degree change per frame at rate 1.
    #[schemars(range(min = 0.0))]
    pub step: f64,
    /// `weather` (the degree rises) or `deweather` (it falls).
    pub direction: Course,
    /// Pixels averaged for the appearance at a degree.
    #[schemars(range(min = 1))]
    pub neighbours: u32,
    /// Light direction [θ, φ], degrees.
    pub light: [f64; 2],
    /// View direction [θ, φ], degrees.
    pub view: [f64; 2],
    /// Scale of the relit values before sRGB encoding (0 to 10⁶).
    #[schemars(range(max = 1e6), extend("exclusiveMinimum" = 0.0))]
    pub exposure: f64,
    /// Milliseconds per GIF frame.
    pub frame_ms: u32,
    /// Path prefix of the written frames, relative to the output folder.
    #[schemars(extend("x-output-path" = true))]
    pub prefix: String,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            frames: 8,
            step: 0.1,
            direction: Course::Weather,
            neighbours: 8,
            light: [30.0, 0.0],
            view: [0.0, 0.0],
            exposure: 1.0,
            frame_ms: 250,
            prefix: "weathering".into(),
        }
    }
}

pub struct Evolve;

impl Node for Evolve {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "manifold.evolve",
            version: 2,
            doc: "Weathering or de-weathering sequence: the degree map advanced per frame and mapped back to Ward parameters along the sample's own degree ordering, relit frames as PNGs and an animated GIF.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("maps", BrdfMap::TYPE, "fitted Ward parameters"),
                Port::input("degree", Image::TYPE, "weathering degree, 1 channel"),
                Port::optional("rate", Image::TYPE, "per-pixel rate (first channel, ≥ 0)"),
            ],
            outputs: vec![
                Port::output("files", Artifacts::TYPE, "the PNG frames and the GIF"),
                Port::output("last", BrdfMap::TYPE, "Ward parameters of the last frame"),
                Port::output("last_frame", Image::TYPE, "the last relit frame, linear"),
                Port::output("strip", Image::TYPE, "every frame side by side (2 px white gaps), linear"),
                Port::output("mean_degree", "Scalar", "mean degree of the last frame"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        if !(p.exposure.is_finite() && p.exposure > 0.0) {
            return Err(NodeError::param("exposure", "must be finite and positive"));
        }
        for (name, d) in [("light", p.light), ("view", p.view)] {
            if !(0.0..90.0).contains(&d[0]) || !d[1].is_finite() {
                return Err(NodeError::param(name, "θ must be in [0°, 90°)"));
            }
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let maps = inputs.get::<BrdfMap>("maps")?;
        let degree = inputs.get::<Image>("degree")?;
        let rate = inputs.opt::<Image>("rate")?;
        let n = maps.width * maps.height;
        for (port, img) in [("degree", Some(degree)), ("rate", rate)] {
            if let Some(img) = img {
                if img.width != maps.width || img.height != maps.height {
                    return Err(NodeError::input(
                        port,
                        format!(
                            "{} × {} for {} × {} maps",
                            img.width, img.height, maps.width, maps.height
                        ),
                    ));
                }
                if let Some(i) = (0..n).find(|i| !img.data[i * img.channels].is_finite()) {
                    return Err(NodeError::input(
                        port,
                        format!("pixel ({}, {}) is not finite", i % img.width, i / img.width),
                    ));
                }
            }
        }
        if let Some(r) = rate {
            if (0..n).any(|i| r.data[i * r.channels] < 0.0) {
                return Err(NodeError::input("rate", "rates must not be negative"));
            }
        }
        let omega: Vec<f64> = (0..n)
            .map(|i| (degree.data[i * degree.channels] as f64).clamp(0.0, 1.0))
            .collect();
        let rates: Vec<f64> = (0..n)
            .map(|i| rate.map_or(1.0, |r| r.data[i * r.channels] as f64))
            .collect();
        let path = Path::new(maps, &omega, p.neighbours.max(1) as usize);
        let geo = PairGeometry::flat(&DirectionPair {
            view: Direction::degrees(p.view[0], p.view[1]),
            light: Direction::degrees(p.light[0], p.light[1]),
        });
        let sign = match p.direction {
            Course::Weather => 1.0,
            Course::Deweather => -1.0,
        };
        let mut files = Vec::new();
        let mut gif_frames = Vec::new();
        let mut last = None;
        let gap = 2;
        let (w, h) = (maps.width, maps.height);
        let strip_w = p.frames as usize * (w + gap) - gap;
        let mut strip = vec![1.0f32; strip_w * h * 3];
        for f in 0..p.frames as usize {
            ctx.check_cancel()?;
            let target: Vec<f64> = omega
                .iter()
                .zip(&rates)
                .map(|(w, r)| (w + sign * f as f64 * p.step * r).clamp(0.0, 1.0))
                .collect();
            let frame_maps = path.advance(maps, &omega, &target);
            let img = relight(&frame_maps, &geo, p.exposure);
            for y in 0..h {
                let at = (y * strip_w + f * (w + gap)) * 3;
                strip[at..at + w * 3].copy_from_slice(&img.data[y * w * 3..(y + 1) * w * 3]);
            }
            let png = formats::encode_png(&img, 8)
                .map_err(|e| NodeError::Failed(format!("encoding frame {f}: {e}")))?;
            let rgba = image::load_from_memory(&png)
                .map_err(|e| NodeError::Failed(format!("frame {f}: {e}")))?
                .to_rgba8();
            gif_frames.push(Frame::from_parts(
                RgbaImage::from_raw(rgba.width(), rgba.height(), rgba.into_raw())
                    .ok_or_else(|| NodeError::Failed("frame buffer size".into()))?,
                0,
                0,
                Delay::from_numer_denom_ms(p.frame_ms, 1),
            ));
            files.push(Artifact {
                path: format!("{}_{f:03}.png", p.prefix),
                bytes: png,
            });
            let mean = target.iter().sum::<f64>() / n as f64;
            last = Some((frame_maps, img, mean));
            ctx.progress(f as u64 + 1, p.frames as u64);
        }
        let mut gif = Vec::new();
        {
            let mut enc = GifEncoder::new_with_speed(&mut gif, 10);
            enc.set_repeat(Repeat::Infinite)
                .and_then(|_| enc.encode_frames(gif_frames))
                .map_err(|e| NodeError::Failed(format!("encoding the GIF: {e}")))?;
        }
        files.push(Artifact {
            path: format!("{}.gif", p.prefix),
            bytes: gif,
        });
        let (last_maps, last_frame, mean) =
            last.ok_or_else(|| NodeError::param("frames", "at least one frame"))?;
        Ok(Outputs::new()
            .with("files", Artifacts { files })
            .with("last", last_maps)
            .with("last_frame", last_frame)
            .with(
                "strip",
                Image {
                    width: strip_w,
                    height: h,
                    channels: 3,
                    data: strip,
                },
            )
            .with("mean_degree", Scalar(mean)))
    }
}

/// The flat sample under one light, linear RGB.
pub fn relight(maps: &BrdfMap, geo: &PairGeometry, exposure: f64) -> Image {
    let n = maps.width * maps.height;
    let data = (0..n)
        .flat_map(|i| {
            let q = maps.pixel(i);
            (0..3).map(move |c| (exposure * geo.value(q[c], q[3], q[4])) as f32)
        })
        .collect();
    Image {
        width: maps.width,
        height: maps.height,
        channels: 3,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::weathering::sample::{generate, path, Params as SampleParams};
    use mesoflow_testkit::node::OutputsExt;

    fn sample() -> (BrdfMap, Vec<f64>) {
        let s = generate(&SampleParams {
            size: 32,
            ..SampleParams::default()
        });
        let omega = s.degree.data.iter().map(|v| *v as f64).collect();
        (s.maps, omega)
    }

    #[test]
    fn frame_zero_is_the_input() {
        // A(ω) + (v − A(ω)) = v: only rounding (1e-12 relative) may differ.
        let (maps, omega) = sample();
        let p = Path::new(&maps, &omega, 8);
        let same = p.advance(&maps, &omega, &omega);
        for (a, b) in same.data.iter().zip(&maps.data) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-12), "{a} vs {b}");
        }
    }

    #[test]
    fn full_weathering_and_deweathering_reach_the_ends_of_the_true_path() {
        // Advancing every pixel to ω = 1 (or 0) must give the generator's own end states
        // (weathering::sample::path, independent of this code) up to each pixel's variation:
        // ρd ± 4%, ρs ± 8% around the path, and the average of 8 path neighbours carries that
        // variation too — the sample mean is within 5% for ρd and ρs, 5% for α.
        let (maps, omega) = sample();
        let p = Path::new(&maps, &omega, 8);
        for (target, want) in [(1.0, path(1.0)), (0.0, path(0.0))] {
            let t = vec![target; omega.len()];
            let out = p.advance(&maps, &omega, &t);
            let n = omega.len() as f64;
            for d in 0..5 {
                let mean = out.data.chunks(5).map(|q| q[d]).sum::<f64>() / n;
                assert!(
                    (mean - want[d]).abs() <= 0.05 * want[d],
                    "ω → {target}, parameter {d}: {mean} vs {}",
                    want[d]
                );
            }
        }
    }

    #[test]
    fn writes_frames_and_a_gif_and_the_degree_rises() {
        let (maps, omega) = sample();
        let degree = Image {
            width: 32,
            height: 32,
            channels: 1,
            data: omega.iter().map(|v| *v as f32).collect(),
        };
        let inputs = Inputs::new()
            .with("maps", std::sync::Arc::new(maps))
            .with("degree", std::sync::Arc::new(degree));
        let p = Params {
            frames: 4,
            ..Params::default()
        };
        let out = mesoflow_testkit::node::run(&Evolve, &p, &inputs).unwrap();
        let files = out.value::<Artifacts>("files");
        let names: Vec<&str> = files.files.iter().map(|f| f.path.as_str()).collect();
        assert_eq!(
            names,
            [
                "weathering_000.png",
                "weathering_001.png",
                "weathering_002.png",
                "weathering_003.png",
                "weathering.gif"
            ]
        );
        assert_eq!(&files.files[4].bytes[..6], b"GIF89a");
        let mean0 = omega.iter().sum::<f64>() / omega.len() as f64;
        let last = out.value::<Scalar>("mean_degree").0;
        assert!(last > mean0 + 0.2, "{last} vs {mean0}");
    }
}
