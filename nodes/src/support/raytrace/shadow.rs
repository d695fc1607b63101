//! Shadow maps: the distance from a light's camera to the nearest surface per texel, and the
//! biased test of whether the light sees a point. `sss.render` and `qh.render` build a full one
//! of the mesh ([`ShadowMap`]); `render.mesh` a lazy one of the displaced mesostructure
//! ([`LazyShadowMap`]), whose texels are traced only when a pixel first asks for them: a frame
//! of 77 k pixels asks for about as many texels, where a full 2 048² map traces 4.2 M.

use super::camera::Camera;
use crate::support::geometry::V3;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

/// A shadow map: distance along the light camera's ray to the displaced surface per texel.
pub struct ShadowMap {
    pub camera: Camera,
    pub depth: Vec<f64>,
    /// Depth bias, world units (two texels' footprint at the scene).
    pub bias: f64,
}

/// Two shadow-map texels' footprint across the scene: enough for the slopes a texel spans.
pub fn shadow_bias(radius: f64, size: u32) -> f64 {
    2.0 * (2.0 * radius / size as f64)
}

/// The texel of `camera`'s image that `p` falls in, and `p`'s distance along that texel's
/// ray; `None` outside the map (lit: nothing in the map can shadow it).
fn texel(camera: &Camera, p: V3) -> Option<(usize, f64)> {
    let (x, y, t) = camera.project(p)?;
    let (w, h) = (camera.width as f64, camera.height as f64);
    if !(0.0..w).contains(&x) || !(0.0..h).contains(&y) {
        return None;
    }
    Some((y as usize * camera.width as usize + x as usize, t))
}

/// The biased comparison: the bias grows as the light grazes the surface (`cos_light`,
/// local), where one texel spans more depth.
fn sees(t: f64, depth: f64, bias: f64, cos_light: f64) -> bool {
    t <= depth + bias / cos_light.max(0.1)
}

impl ShadowMap {
    /// Whether the light sees `p` (nearest shadow-map texel, biased comparison).
    pub fn lit(&self, p: V3, cos_light: f64) -> bool {
        texel(&self.camera, p).is_none_or(|(i, t)| sees(t, self.depth[i], self.bias, cos_light))
    }
}

/// The side of a block of texels allocated together.
const BLOCK: usize = 16;

/// A texel not traced yet: no depth has these bits (the traced ones are finite or +∞).
const UNTRACED: u64 = u64::MAX;

/// A shadow map whose texels are traced on first use: the same depths, texel for texel, as the
/// full map the same `trace` would fill (a texel's depth is a function of the texel alone, so
/// which thread traces it first, or whether two trace it at once, changes no bit), at the cost
/// of the texels the frame looks up. The depths are kept in blocks of 16 × 16 texels, each
/// allocated when a texel of it is first asked for (2 KiB), so a frame that touches a few
/// thousand texels of a 2 048² map neither allocates nor clears its 32 MiB.
pub struct LazyShadowMap<'a> {
    pub camera: Camera,
    /// Depth bias, world units.
    pub bias: f64,
    blocks_x: usize,
    blocks: Vec<OnceLock<Box<[AtomicU64]>>>,
    trace: Box<dyn Fn(u32, u32) -> f64 + Sync + 'a>,
    traced: AtomicU64,
    /// Time spent tracing texels, summed over the threads that traced them, ns.
    nanos: AtomicU64,
}

impl<'a> LazyShadowMap<'a> {
    /// A map over `camera`'s texels; `trace(x, y)` is the depth of texel (x, y).
    pub fn new(
        camera: Camera,
        bias: f64,
        trace: impl Fn(u32, u32) -> f64 + Sync + 'a,
    ) -> LazyShadowMap<'a> {
        let blocks_x = (camera.width as usize).div_ceil(BLOCK);
        let blocks_y = (camera.height as usize).div_ceil(BLOCK);
        LazyShadowMap {
            blocks_x,
            blocks: (0..blocks_x * blocks_y).map(|_| OnceLock::new()).collect(),
            camera,
            bias,
            trace: Box::new(trace),
            traced: AtomicU64::new(0),
            nanos: AtomicU64::new(0),
        }
    }

    /// Texel `i`'s depth, traced now if no pixel has asked for it before.
    pub fn depth(&self, i: usize) -> f64 {
        let w = self.camera.width as usize;
        let (x, y) = (i % w, i / w);
        let block = self.blocks[(y / BLOCK) * self.blocks_x + x / BLOCK].get_or_init(|| {
            (0..BLOCK * BLOCK)
                .map(|_| AtomicU64::new(UNTRACED))
                .collect()
        });
        let slot = &block[(y % BLOCK) * BLOCK + x % BLOCK];
        let bits = slot.load(Ordering::Relaxed);
        if bits != UNTRACED {
            return f64::from_bits(bits);
        }
        let clock = std::time::Instant::now();
        let d = (self.trace)(x as u32, y as u32);
        let ns = clock.elapsed().as_nanos() as u64;
        self.nanos.fetch_add(ns, Ordering::Relaxed);
        if slot.swap(d.to_bits(), Ordering::Relaxed) == UNTRACED {
            self.traced.fetch_add(1, Ordering::Relaxed);
        }
        d
    }

    /// Whether the light sees `p` (nearest texel, biased comparison), as [`ShadowMap::lit`].
    pub fn lit(&self, p: V3, cos_light: f64) -> bool {
        texel(&self.camera, p).is_none_or(|(i, t)| sees(t, self.depth(i), self.bias, cos_light))
    }

    /// How many texels have been traced.
    pub fn traced(&self) -> u64 {
        self.traced.load(Ordering::Relaxed)
    }

    /// The time spent tracing them, summed over threads, ms.
    pub fn thread_ms(&self) -> f64 {
        self.nanos.load(Ordering::Relaxed) as f64 / 1e6
    }
}
