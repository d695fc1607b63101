//! `heightfield.procedural`: periodic mesostructure tiles, the built-in data source. Every pattern
//! tiles seamlessly (opposite edges match), as a mesostructure mapped repeatedly over a surface must.

use crate::support::rng;
use crate::types::{HeightField, Image};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Pattern {
    /// A `count`×`count` grid of hemispherical bumps of diameter `width`·spacing.
    Bumps,
    /// Plain weave of `count` threads each way (even), thread width `width`·spacing.
    Weave,
    /// Raised Voronoi cells, `count`² jittered seeds, grooves of width `width`·spacing.
    Cells,
    /// Fractional Brownian motion of value noise, base frequency `count`, `octaves`, `persistence`.
    Noise,
    /// Terraces: `count` staircases across the tile, `levels` steps each.
    Steps,
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The pattern.
    pub pattern: Pattern,
    /// Tile side in texels.
    #[schemars(range(min = 4, max = 8192))]
    pub size: u32,
    /// Seed of the random patterns (cells, noise).
    pub seed: u64,
    /// Height of the tallest feature, in texels.
    #[schemars(range(min = 0.0, max = 4096.0))]
    pub depth: f64,
    /// Features per tile side: bumps, threads, cells, base noise frequency or staircases.
    #[schemars(range(min = 1, max = 1024))]
    pub count: u32,
    /// Bump diameter, thread width or groove width, as a fraction of the feature spacing.
    #[schemars(range(min = 0.01, max = 1.0))]
    pub width: f64,
    /// Octaves of the noise pattern.
    #[schemars(range(min = 1, max = 16))]
    pub octaves: u32,
    /// Amplitude ratio between successive noise octaves.
    #[schemars(range(min = 0.0, max = 1.0))]
    pub persistence: f64,
    /// Steps per staircase.
    #[schemars(range(min = 1, max = 4096))]
    pub levels: u32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            pattern: Pattern::Weave,
            size: 128,
            seed: 1,
            depth: 8.0,
            count: 8,
            width: 0.8,
            octaves: 5,
            persistence: 0.5,
            levels: 4,
        }
    }
}

pub struct Procedural;

impl Node for Procedural {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "heightfield.procedural",
            version: 1,
            doc: "Periodic mesostructure tile (bumps, weave, cells, fBm noise, steps); heights in texels.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::output("height", HeightField::TYPE, "heights in texels, periodic"),
                Port::output("preview", Image::TYPE, "heights scaled to [0, 1], grey"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        weave_count(p)
    }

    fn run(&self, ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let hf = generate(ctx, p)?;
        let n = hf.width;
        let (lo, hi) = hf.min_max();
        if hi <= lo && p.depth != 0.0 {
            // Every texel centre fell on the same phase of the pattern: a flat tile would make
            // every later stage's error exactly 0, which is not an answer.
            ctx.warn(format!(
                "the tile is flat: {} periods across {n} texels leave {:.1} texels each, which \
                 samples the pattern at one phase; raise `size` or lower `count`",
                p.count,
                n as f64 / p.count.max(1) as f64
            ));
        }
        let span = if hi > lo { hi - lo } else { 1.0 };
        let preview = Image {
            width: n,
            height: n,
            channels: 1,
            data: hf.data.iter().map(|h| (h - lo) / span).collect(),
        };
        Ok(Outputs::new().with("height", hf).with("preview", preview))
    }
}

/// A plain weave tiles only with an even thread count.
fn weave_count(p: &Params) -> Result<(), NodeError> {
    if p.pattern == Pattern::Weave && !p.count.is_multiple_of(2) {
        return Err(NodeError::param(
            "count",
            format!(
                "a plain weave tiles only with an even thread count, got {}",
                p.count
            ),
        ));
    }
    Ok(())
}

/// The tile `run` outputs, for callers that want the `HeightField` itself (tests, benches).
pub fn generate(ctx: &NodeContext, p: &Params) -> Result<HeightField, NodeError> {
    weave_count(p)?;
    let n = p.size as usize;
    let mut data = vec![0f32; n * n];
    let rows_done = std::sync::atomic::AtomicU64::new(0);
    data.par_chunks_mut(n)
        .enumerate()
        .try_for_each(|(y, row)| {
            ctx.check_cancel()?;
            for (x, h) in row.iter_mut().enumerate() {
                // Texel centres; v grows up the image (row 0 is the top).
                let u = (x as f64 + 0.5) / n as f64;
                let v = 1.0 - (y as f64 + 0.5) / n as f64;
                *h = (p.depth * unit_height(p, u, v)) as f32;
            }
            let done = rows_done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if done.is_multiple_of(64) || done == n as u64 {
                ctx.progress(done, n as u64);
            }
            Ok::<(), NodeError>(())
        })?;
    Ok(HeightField {
        width: n,
        height: n,
        data,
    })
}

/// Height in [0, 1] at tile coordinates (u, v) ∈ [0, 1)².
pub fn unit_height(p: &Params, u: f64, v: f64) -> f64 {
    let c = p.count as f64;
    match p.pattern {
        Pattern::Bumps => {
            let (fu, fv) = ((u * c).fract() - 0.5, (v * c).fract() - 0.5);
            cap((fu * fu + fv * fv).sqrt(), p.width / 2.0)
        }
        Pattern::Weave => {
            let (i, j) = ((u * c).floor(), (v * c).floor());
            let (fu, fv) = ((u * c).fract() - 0.5, (v * c).fract() - 0.5);
            // Warp thread i rises over weft j where i + j is even and dips under it elsewhere.
            let warp_rise = 0.5 + 0.5 * (PI * (v * c - 0.5 + i)).cos();
            let weft_rise = 0.5 - 0.5 * (PI * (u * c - 0.5 + j)).cos();
            let warp = cap(fu.abs(), p.width / 2.0) * (0.4 + 0.6 * warp_rise);
            let weft = cap(fv.abs(), p.width / 2.0) * (0.4 + 0.6 * weft_rise);
            warp.max(weft)
        }
        Pattern::Cells => {
            let (f1, f2) = worley(p.seed, p.count as i64, u * c, v * c);
            smoothstep(0.0, p.width / 2.0, f2 - f1)
        }
        Pattern::Noise => {
            let (mut sum, mut amp, mut norm) = (0.0, 1.0, 0.0);
            for o in 0..p.octaves {
                let f = p.count as i64 * (1i64 << o);
                sum += amp * value_noise(p.seed, o as u64, f, u * f as f64, v * f as f64);
                norm += amp;
                amp *= p.persistence;
            }
            if norm > 0.0 {
                sum / norm
            } else {
                0.0
            }
        }
        Pattern::Steps => {
            let l = p.levels as f64;
            ((u * c).fract() * l).floor() / l
        }
    }
}

/// Hemispherical profile of radius `r` at distance `d` from its centre, 1 at the centre.
fn cap(d: f64, r: f64) -> f64 {
    let t = d / r;
    (1.0 - t * t).max(0.0).sqrt()
}

fn smoothstep(a: f64, b: f64, x: f64) -> f64 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Distances to the nearest and second-nearest seed of a periodic jittered grid of `n`×`n` cells.
fn worley(seed: u64, n: i64, x: f64, y: f64) -> (f64, f64) {
    let (cx, cy) = (x.floor() as i64, y.floor() as i64);
    let (mut f1, mut f2) = (f64::INFINITY, f64::INFINITY);
    for dy in -2..=2 {
        for dx in -2..=2 {
            let (gx, gy) = (cx + dx, cy + dy);
            let (wx, wy) = (gx.rem_euclid(n) as u64, gy.rem_euclid(n) as u64);
            let px = gx as f64 + rng::unit(rng::hash(seed, &[wx, wy, 0]));
            let py = gy as f64 + rng::unit(rng::hash(seed, &[wx, wy, 1]));
            let d = ((px - x).powi(2) + (py - y).powi(2)).sqrt();
            if d < f1 {
                f2 = f1;
                f1 = d;
            } else if d < f2 {
                f2 = d;
            }
        }
    }
    (f1, f2)
}

/// Value noise on a lattice of period `period`, quintic interpolation, values in [0, 1].
fn value_noise(seed: u64, octave: u64, period: i64, x: f64, y: f64) -> f64 {
    let (ix, iy) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - ix as f64, y - iy as f64);
    let lattice = |i: i64, j: i64| {
        rng::unit(rng::hash(
            seed,
            &[
                octave,
                i.rem_euclid(period) as u64,
                j.rem_euclid(period) as u64,
            ],
        ))
    };
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (fade(fx), fade(fy));
    let a = lattice(ix, iy) + sx * (lattice(ix + 1, iy) - lattice(ix, iy));
    let b = lattice(ix, iy + 1) + sx * (lattice(ix + 1, iy + 1) - lattice(ix, iy + 1));
    a + sy * (b - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(pattern: Pattern) -> Params {
        Params {
            pattern,
            ..Params::default()
        }
    }

    #[test]
    fn every_pattern_tiles_seamlessly() {
        // Periodicity means height(u, v) == height(u + 1, v): compare across the seam at fine
        // offsets. The formulas use floor/fract, so equality holds to rounding (1e-9).
        for pattern in [
            Pattern::Bumps,
            Pattern::Weave,
            Pattern::Cells,
            Pattern::Noise,
        ] {
            let p = params(pattern);
            for k in 0..50 {
                let t = k as f64 / 50.0 + 0.003;
                let a = unit_height(&p, 0.0004, t);
                let b = unit_height(&p, 1.0004, t);
                assert!(
                    (a - b).abs() < 1e-9,
                    "{pattern:?} u-seam at {t}: {a} vs {b}"
                );
                let a = unit_height(&p, t, 0.0004);
                let b = unit_height(&p, t, 1.0004);
                assert!(
                    (a - b).abs() < 1e-9,
                    "{pattern:?} v-seam at {t}: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn bump_profile_is_a_hemisphere() {
        // At the bump centre the height is 1; at distance d the closed form is sqrt(1 - (d/r)²).
        let p = Params {
            pattern: Pattern::Bumps,
            count: 1,
            width: 0.8,
            ..Params::default()
        };
        assert!((unit_height(&p, 0.5, 0.5) - 1.0).abs() < 1e-12);
        let d: f64 = 0.2;
        let expected = (1.0 - (d / 0.4).powi(2)).sqrt();
        assert!((unit_height(&p, 0.5 + d, 0.5) - expected).abs() < 1e-12);
        assert_eq!(unit_height(&p, 0.95, 0.95), 0.0);
    }

    #[test]
    fn weave_alternates_over_and_under() {
        // At crossing (i, j) = (0, 0) the warp is on top; at (1, 0) the weft is.
        let p = Params {
            pattern: Pattern::Weave,
            count: 2,
            ..Params::default()
        };
        let warp_top = unit_height(&p, 0.25, 0.25);
        let weft_top = unit_height(&p, 0.75, 0.25);
        assert!((warp_top - 1.0).abs() < 1e-9 && (weft_top - 1.0).abs() < 1e-9);
        // Just off the warp's centre line along u, the warp profile decides at (0,0) ...
        let p_off = unit_height(&p, 0.25 + 0.1, 0.25);
        assert!((p_off - cap(0.2, 0.4)).abs() < 1e-9, "{p_off}");
    }

    #[test]
    fn odd_weave_is_a_parameter_error() {
        let ctx = NodeContext::detached(None);
        let p = Params {
            pattern: Pattern::Weave,
            count: 3,
            size: 16,
            ..Params::default()
        };
        let err =
            mesoflow_testkit::node::run_in(&ctx, &Procedural, &p, &Inputs::new()).unwrap_err();
        assert!(
            matches!(err, NodeError::Param { ref param, .. } if param == "count"),
            "{err}"
        );
    }
}
