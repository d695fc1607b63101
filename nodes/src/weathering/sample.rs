//! `weathering.sample`: a flat weathered sample with its ground truth.
//!
//! - **Degree field** ω(x) ∈ [0, 1]: rust grows from `seeds` random points. With d the distance
//!   to the nearest seed (in sample widths) and n(x) ∈ [0, 1] smooth value noise (three octaves),
//!   ω = clamp(1 − d / `radius` + `roughness` · (n − ½), 0, 1).
//! - **Appearance path**: (ρd RGB, ρs, ln α) runs piecewise linearly through three states as ω
//!   rises — bare metal (ω = 0), orange rust (ω = ½), dark pitted rust (ω = 1) — a path with a
//!   bend, as real weathering paths are. Each pixel keeps its own variation: ρd × (1 ± 4%) and
//!   ρs × (1 ± 8%) from noise of its own.
//! - **Capture**: each pixel is Ward × cos θi under unit irradiance (as `btf.capture` renders a
//!   flat tile) for every (view, light) pair, with optional relative Gaussian noise.
//!
//! Outputs the capture (`Btf`), the true degree (`Image`, 1 channel), the true Ward parameters
//! (`BrdfMap`) and two masks marking the least (ω ≤ 0.02) and most (ω ≥ 0.98) weathered pixels,
//! the sets a user would mark for `manifold.degree`.

use crate::btf::directions::DirectionSet;
use crate::reflectance::ward::PairGeometry;
use crate::support::rng;
use crate::types::{BrdfMap, Btf, DirectionPair, Image, NormalMap, WARD_PARAMS};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Width and height in pixels.
    #[schemars(range(min = 4, max = 4096))]
    pub size: u32,
    /// Points rust grows from.
    #[schemars(range(min = 1, max = 1000))]
    pub seeds: u32,
    /// Distance (in sample widths) at which the degree falls to 0 without noise (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub radius: f64,
    /// Amplitude of the noise on the degree.
    #[schemars(range(min = 0.0))]
    pub roughness: f64,
    /// Light directions (degrees).
    pub lights: DirectionSet,
    /// View directions (degrees).
    pub views: DirectionSet,
    /// Relative Gaussian noise on captured values (0 = exact).
    #[schemars(range(min = 0.0))]
    pub noise: f64,
    /// Relief height in sample widths (0 = flat): smooth bumps whose normals tilt the Ward
    /// lobe per pixel, for fits that need photometric-stereo normals.
    #[schemars(range(min = 0.0))]
    pub bumps: f64,
    /// The reflectance the capture is rendered with: `ward` (the model `brdf.fit_ward` fits, for
    /// solver checks) or `cook_torrance` (Beckmann, Fresnel, masking–shadowing: a model the
    /// Ward fit cannot reproduce, for cross-model checks).
    pub reflectance: Reflectance,
    /// Seed of the rust seeds, the noise and the per-pixel variation.
    pub seed: u64,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Reflectance {
    #[default]
    Ward,
    CookTorrance,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            size: 64,
            seeds: 4,
            radius: 0.4,
            roughness: 0.5,
            lights: DirectionSet::Rings {
                thetas: vec![0.0, 8.0, 16.0, 28.0, 45.0, 65.0],
                phis: vec![0.0, 60.0, 120.0, 180.0, 240.0, 300.0],
            },
            views: DirectionSet::List(vec![[0.0, 0.0]]),
            noise: 0.0,
            bumps: 0.0,
            reflectance: Reflectance::Ward,
            seed: 1,
        }
    }
}

/// (ρd R, G, B, ρs, α) at ω = 0, ½, 1: bare metal, orange rust, dark pitted rust.
const STATES: [[f64; 5]; 3] = [
    [0.06, 0.06, 0.07, 0.35, 0.10],
    [0.50, 0.22, 0.07, 0.08, 0.25],
    [0.10, 0.05, 0.035, 0.04, 0.40],
];

/// Ward parameters (ρd RGB, ρs, α) on the path at degree ω.
pub fn path(omega: f64) -> [f64; WARD_PARAMS] {
    let t = omega.clamp(0.0, 1.0) * 2.0;
    let (a, b, f) = if t <= 1.0 {
        (STATES[0], STATES[1], t)
    } else {
        (STATES[1], STATES[2], t - 1.0)
    };
    // Linear in ρd and ρs, geometric in α (linear in ln α).
    let mut q = [0.0; 5];
    for d in 0..4 {
        q[d] = a[d] + f * (b[d] - a[d]);
    }
    q[4] = a[4] * (b[4] / a[4]).powf(f);
    q
}

pub struct WeatheringSample;

impl Node for WeatheringSample {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "weathering.sample",
            version: 2,
            doc: "A synthetic weathered sample, flat or with bumps (metal → orange rust → dark rust along a bent path in Ward space) captured under many lights, with the true degree and parameter maps.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::output("btf", Btf::TYPE, "the capture"),
                Port::output("degree", Image::TYPE, "true weathering degree, 1 channel"),
                Port::output("maps", BrdfMap::TYPE, "true Ward parameters"),
                Port::output("normals", NormalMap::TYPE, "true normals (x right, y up the image)"),
                Port::output("least", Image::TYPE, "mask of the least weathered pixels (ω ≤ 0.02)"),
                Port::output("most", Image::TYPE, "mask of the most weathered pixels (ω ≥ 0.98)"),
                Port::output("photo", Image::TYPE, "the capture under the light nearest θ = 30°, first view"),
            ],
            disk_cache: false,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        p.lights
            .validate()
            .map_err(|e| NodeError::param("lights", e))?;
        p.views
            .validate()
            .map_err(|e| NodeError::param("views", e))?;
        // The capture: RGB f32 per pixel and (view, light) pair; checked before it is made.
        let pairs =
            (p.views.directions().len() as u64).saturating_mul(p.lights.directions().len() as u64);
        let pixels = u64::from(p.size) * u64::from(p.size);
        crate::support::memory::check_param(
            crate::support::memory::product(&[pairs, pixels, 3, 4]),
            &format!("a {0} × {0} capture under {pairs} direction pairs", p.size),
            "lights",
        )
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        let s = generate(p);
        Ok(Outputs::new()
            .with("btf", s.btf)
            .with("degree", s.degree)
            .with("maps", s.maps)
            .with("normals", s.normals)
            .with("least", s.least)
            .with("most", s.most)
            .with("photo", s.photo))
    }
}

pub struct Sample {
    pub btf: Btf,
    pub degree: Image,
    pub maps: BrdfMap,
    pub normals: NormalMap,
    pub least: Image,
    pub most: Image,
    pub photo: Image,
}

/// Smooth value noise in [0, 1], periodic over the sample, three octaves.
fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let mut sum = 0.0;
    let mut weight = 0.0;
    for (octave, cells) in [4u64, 8, 16].into_iter().enumerate() {
        let (fx, fy) = (x * cells as f64, y * cells as f64);
        let (ix, iy) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - ix, fy - iy);
        let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
        let corner = |dx: u64, dy: u64| {
            let cx = (ix as u64 + dx) % cells;
            let cy = (iy as u64 + dy) % cells;
            rng::unit(rng::hash(seed, &[octave as u64, cx, cy]))
        };
        let (sx, sy) = (smooth(tx), smooth(ty));
        let top = corner(0, 0) * (1.0 - sx) + corner(1, 0) * sx;
        let bottom = corner(0, 1) * (1.0 - sx) + corner(1, 1) * sx;
        let w = 0.5f64.powi(octave as i32);
        sum += w * (top * (1.0 - sy) + bottom * sy);
        weight += w;
    }
    sum / weight
}

/// A standard normal variate from two hashes (Box–Muller).
fn gaussian(seed: u64, parts: &[u64]) -> f64 {
    let h = rng::hash(seed, parts);
    let u1 = rng::unit(h).max(1e-300);
    let u2 = rng::unit(rng::mix(h ^ 0x9e37_79b9_7f4a_7c15));
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Normals of the relief z = bumps · H(u, v), H the periodic value noise (u right, v down the
/// image, in sample widths; y of the normal points up the image). None when flat.
fn relief_normals(p: &Params, size: usize) -> Option<Vec<[f64; 3]>> {
    if p.bumps <= 0.0 {
        return None;
    }
    let e = 1e-4;
    let h = |u: f64, v: f64| value_noise(p.seed ^ 0xb0b5, u.rem_euclid(1.0), v.rem_euclid(1.0));
    Some(
        (0..size * size)
            .map(|i| {
                let u = ((i % size) as f64 + 0.5) / size as f64;
                let v = ((i / size) as f64 + 0.5) / size as f64;
                let du = p.bumps * (h(u + e, v) - h(u - e, v)) / (2.0 * e);
                let dv = p.bumps * (h(u, v + e) - h(u, v - e)) / (2.0 * e);
                let len = (du * du + dv * dv + 1.0).sqrt();
                [-du / len, dv / len, 1.0 / len]
            })
            .collect(),
    )
}

pub fn generate(p: &Params) -> Sample {
    let size = p.size.max(4) as usize;
    let n = size * size;
    let seeds: Vec<[f64; 2]> = (0..p.seeds.max(1) as u64)
        .map(|i| {
            [
                rng::unit(rng::hash(p.seed, &[1, i, 0])),
                rng::unit(rng::hash(p.seed, &[1, i, 1])),
            ]
        })
        .collect();
    let mut degree = Vec::with_capacity(n);
    let mut maps = Vec::with_capacity(n * WARD_PARAMS);
    for y in 0..size {
        for x in 0..size {
            let (u, v) = (
                (x as f64 + 0.5) / size as f64,
                (y as f64 + 0.5) / size as f64,
            );
            let d = seeds
                .iter()
                .map(|s| ((u - s[0]).powi(2) + (v - s[1]).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min);
            let noise = value_noise(p.seed ^ 0x5eed, u, v);
            let omega = (1.0 - d / p.radius + p.roughness * (noise - 0.5)).clamp(0.0, 1.0);
            let mut q = path(omega);
            let i = (y * size + x) as u64;
            let own = |k: u64| rng::unit(rng::hash(p.seed, &[2, i, k])) - 0.5;
            let tint = 1.0 + 0.08 * own(0);
            for rho in &mut q[..3] {
                *rho *= tint;
            }
            q[3] *= 1.0 + 0.16 * own(1);
            degree.push(omega as f32);
            maps.extend(q);
        }
    }
    let views = p.views.directions();
    let lights = p.lights.directions();
    let pairs: Vec<DirectionPair> = views
        .iter()
        .flat_map(|v| {
            lights.iter().map(move |l| DirectionPair {
                view: *v,
                light: *l,
            })
        })
        .collect();
    let normals = relief_normals(p, size);
    let geo: Vec<PairGeometry> = pairs.iter().map(PairGeometry::flat).collect();
    let mut data = vec![0.0f32; pairs.len() * 3 * n];
    data.par_chunks_mut(n).enumerate().for_each(|(plane, out)| {
        let (pair, c) = (plane / 3, plane % 3);
        for (i, o) in out.iter_mut().enumerate() {
            let q = &maps[i * WARD_PARAMS..(i + 1) * WARD_PARAMS];
            let mut v = match p.reflectance {
                Reflectance::Ward => {
                    let g = match &normals {
                        Some(nv) => PairGeometry::with_normal(&pairs[pair], nv[i]),
                        None => geo[pair],
                    };
                    g.value(q[c], q[3], q[4])
                }
                Reflectance::CookTorrance => {
                    let n = normals.as_ref().map_or([0.0, 0.0, 1.0], |nv| nv[i]);
                    crate::reflectance::cook_torrance::value(&pairs[pair], n, q[c], q[3], q[4])
                }
            };
            if p.noise > 0.0 {
                v *= 1.0 + p.noise * gaussian(p.seed, &[3, plane as u64, i as u64]);
            }
            *o = v.max(0.0) as f32;
        }
    });
    let mask = |keep: &dyn Fn(f32) -> bool| Image {
        width: size,
        height: size,
        channels: 1,
        data: degree
            .iter()
            .map(|d| f32::from(u8::from(keep(*d))))
            .collect(),
    };
    let least = mask(&|d| d <= 0.02);
    let most = mask(&|d| d >= 0.98);
    let lit = (0..lights.len())
        .min_by(|a, b| {
            let off = |i: usize| (lights[i].theta - 30f64.to_radians()).abs();
            off(*a).total_cmp(&off(*b))
        })
        .unwrap_or(0);
    let photo = Image {
        width: size,
        height: size,
        channels: 3,
        data: (0..n)
            .flat_map(|i| {
                (0..3)
                    .map(|c| data[(lit * 3 + c) * n + i])
                    .collect::<Vec<_>>()
            })
            .collect(),
    };
    Sample {
        photo,
        btf: Btf {
            width: size,
            height: size,
            pairs,
            data,
        },
        degree: Image {
            width: size,
            height: size,
            channels: 1,
            data: degree,
        },
        maps: BrdfMap {
            width: size,
            height: size,
            data: maps,
        },
        normals: NormalMap {
            width: size,
            height: size,
            data: match &normals {
                Some(nv) => nv.iter().flat_map(|v| v.map(|c| c as f32)).collect(),
                None => [0.0f32, 0.0, 1.0].repeat(n),
            },
        },
        least,
        most,
    }
}
