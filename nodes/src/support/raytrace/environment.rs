//! Environment light: radiance arriving from every direction, held as a linear lat-long image
//! (an EXR or `.npy` file, or a procedural sky or studio made here), with what the renderers
//! need of it — the radiance along a direction, importance sampling in proportion to radiance
//! (for the path tracers' truth to converge) and the image's texels as a quadrature of the
//! sphere (for `render.mesh`'s per-vertex projection).
//!
//! **Convention.** World +z is up: row 0 of the image looks towards +z, the last row towards −z,
//! θ = π (row + ½)/H from +z. Column c looks along azimuth φ = 2π (c + ½)/W + rotation from +x
//! towards +y. The radiance is piecewise constant over texels (what is sampled is what is
//! looked up, so the sampling is unbiased). `export.mitsuba` and `export.pbrt` map the same image
//! onto their own conventions.

use crate::support::geometry::V3;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A lat-long environment with its sampling tables.
pub struct Environment {
    pub width: usize,
    pub height: usize,
    /// Linear RGB radiance per texel, row-major from the top, the light's intensity applied.
    pub radiance: Vec<[f32; 3]>,
    /// Rotation about +z, radians.
    pub rotation: f64,
    /// Cumulative sampling weight over rows (H + 1 entries, last 1) and within each row
    /// (H × (W + 1)); weights ∝ mean RGB × sin θ.
    rows: Vec<f64>,
    cols: Vec<f64>,
    /// Identity of the content (pixels, rotation), for caches and equality.
    pub id: [u8; 32],
}

impl std::fmt::Debug for Environment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Environment({} × {})", self.width, self.height)
    }
}

impl PartialEq for Environment {
    fn eq(&self, o: &Self) -> bool {
        self.id == o.id
    }
}

impl Environment {
    /// From linear RGB texels (row-major, row 0 towards +z), scaled by `intensity`, rotated by
    /// `rotation` radians about +z. Errors say what is wrong with the pixels.
    pub fn new(
        width: usize,
        height: usize,
        texels: &[[f32; 3]],
        intensity: f64,
        rotation: f64,
    ) -> Result<Environment, String> {
        if width < 2 || height < 1 || texels.len() != width * height {
            return Err(format!(
                "a lat-long environment needs at least 2 × 1 texels, got {width} × {height} ({} values)",
                texels.len()
            ));
        }
        if let Some(i) = texels
            .iter()
            .position(|t| t.iter().any(|c| !(c.is_finite() && *c >= 0.0)))
        {
            return Err(format!(
                "texel ({}, {}) is {:?}: radiance must be finite and not negative",
                i % width,
                i / width,
                texels[i]
            ));
        }
        let radiance: Vec<[f32; 3]> = texels
            .iter()
            .map(|t| t.map(|c| (c as f64 * intensity) as f32))
            .collect();
        let mut rows = vec![0.0; height + 1];
        let mut cols = vec![0.0; height * (width + 1)];
        for y in 0..height {
            let sin = (PI * (y as f64 + 0.5) / height as f64).sin();
            let row = &mut cols[y * (width + 1)..(y + 1) * (width + 1)];
            for x in 0..width {
                let t = radiance[y * width + x];
                row[x + 1] = row[x] + (t[0] as f64 + t[1] as f64 + t[2] as f64) * sin;
            }
            rows[y + 1] = rows[y] + row[width];
        }
        let mut h = blake3::Hasher::new();
        h.update(&(width as u64).to_le_bytes());
        h.update(&(height as u64).to_le_bytes());
        h.update(&rotation.to_le_bytes());
        for t in &radiance {
            for c in t {
                h.update(&c.to_le_bytes());
            }
        }
        Ok(Environment {
            width,
            height,
            radiance,
            rotation,
            rows,
            cols,
            id: *h.finalize().as_bytes(),
        })
    }

    /// Whether no light arrives at all.
    pub fn is_black(&self) -> bool {
        self.rows[self.height] <= 0.0
    }

    /// The texel a world direction looks into.
    fn texel_of(&self, w: V3) -> (usize, usize) {
        let theta = w[2].clamp(-1.0, 1.0).acos();
        let phi = (w[1].atan2(w[0]) - self.rotation).rem_euclid(2.0 * PI);
        let x = ((phi / (2.0 * PI) * self.width as f64) as usize).min(self.width - 1);
        let y = ((theta / PI * self.height as f64) as usize).min(self.height - 1);
        (x, y)
    }

    /// World direction at image coordinates (u, v) ∈ [0, 1)² (u along a row, v down).
    pub fn direction(&self, u: f64, v: f64) -> V3 {
        let (theta, phi) = (PI * v, 2.0 * PI * u + self.rotation);
        let s = theta.sin();
        [s * phi.cos(), s * phi.sin(), theta.cos()]
    }

    /// Radiance arriving from world direction `w` (unit), i.e. seen looking along `w`.
    pub fn radiance(&self, w: V3) -> [f64; 3] {
        let (x, y) = self.texel_of(w);
        self.radiance[y * self.width + x].map(|c| c as f64)
    }

    /// Probability density (per steradian) of [`Environment::sample`] giving `w`.
    pub fn pdf(&self, w: V3) -> f64 {
        let total = self.rows[self.height];
        if total <= 0.0 {
            return 0.0;
        }
        let (x, y) = self.texel_of(w);
        let row = &self.cols[y * (self.width + 1)..];
        let p_texel = (row[x + 1] - row[x]) / total;
        let sin = (1.0 - w[2] * w[2]).max(0.0).sqrt();
        if sin <= 0.0 {
            return 0.0;
        }
        // Uniform within the texel in (u, v): its area is 2π²/(W·H) per unit sin θ.
        p_texel * (self.width * self.height) as f64 / (2.0 * PI * PI * sin)
    }

    /// A direction drawn in proportion to radiance × sin θ over the image (mean RGB), from two
    /// uniform numbers: (direction, radiance along it, pdf per steradian). `None` for a black
    /// environment.
    pub fn sample(&self, u1: f64, u2: f64) -> Option<(V3, [f64; 3], f64)> {
        let total = self.rows[self.height];
        if total <= 0.0 {
            return None;
        }
        let find = |cdf: &[f64], target: f64| -> (usize, f64) {
            // The first bin whose upper edge exceeds the target, and where in it.
            let n = cdf.len() - 1;
            let i = cdf[1..].partition_point(|&c| c <= target).min(n - 1);
            let w = cdf[i + 1] - cdf[i];
            let f = if w > 0.0 { (target - cdf[i]) / w } else { 0.5 };
            (i, f.clamp(0.0, 1.0 - 1e-12))
        };
        let (y, fy) = find(&self.rows, u1 * total);
        let row = &self.cols[y * (self.width + 1)..(y + 1) * (self.width + 1)];
        let (x, fx) = find(row, u2 * row[self.width]);
        let u = (x as f64 + fx) / self.width as f64;
        let v = (y as f64 + fy) / self.height as f64;
        let w = self.direction(u, v);
        let pdf = self.pdf(w);
        if pdf <= 0.0 {
            return None;
        }
        Some((w, self.radiance[y * self.width + x].map(|c| c as f64), pdf))
    }

    /// The image box-filtered to `width` × `height` texels (each a whole number of the
    /// original's per side where it divides, else the nearest original texels averaged by
    /// area), as (direction at the texel's centre, mean radiance, solid angle): a quadrature of
    /// the sphere whose weights sum to 4π.
    pub fn quadrature(&self, width: usize, height: usize) -> Vec<(V3, [f64; 3], f64)> {
        let (width, height) = (width.clamp(2, self.width), height.clamp(1, self.height));
        let mut out = Vec::with_capacity(width * height);
        for y in 0..height {
            let (y0, y1) = (
                y * self.height / height,
                ((y + 1) * self.height / height).max(y * self.height / height + 1),
            );
            let (t0, t1) = (
                PI * y as f64 / height as f64,
                PI * (y + 1) as f64 / height as f64,
            );
            let omega_row = 2.0 * PI * (t0.cos() - t1.cos()) / width as f64;
            for x in 0..width {
                let (x0, x1) = (
                    x * self.width / width,
                    ((x + 1) * self.width / width).max(x * self.width / width + 1),
                );
                let mut sum = [0.0; 3];
                let mut weight = 0.0;
                for yy in y0..y1 {
                    let sin = (PI * (yy as f64 + 0.5) / self.height as f64).sin();
                    for xx in x0..x1 {
                        let t = self.radiance[yy * self.width + xx];
                        for k in 0..3 {
                            sum[k] += t[k] as f64 * sin;
                        }
                        weight += sin;
                    }
                }
                let l = sum.map(|s| if weight > 0.0 { s / weight } else { 0.0 });
                let d = self.direction(
                    (x as f64 + 0.5) / width as f64,
                    (y as f64 + 0.5) / height as f64,
                );
                out.push((d, l, omega_row));
            }
        }
        out
    }
}

/// A clear sky with a soft sun, made at 256 × 128 texels: `zenith` blending to `horizon` as
/// the sky falls towards it, `ground` below, and a sun of radiance `sun_radiance` whose glow
/// falls off as exp(−(γ/`sun_size`)²) with the angle γ from `sun`. The defaults give about 1
/// of irradiance on an upward plane per unit of the light's `intensity` (a third of it from the
/// sun), so the default intensity, 3, lights a scene as the default directional light does.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SkyParams {
    /// Direction towards the sun (world, z up; need not be unit length).
    pub sun: [f64; 3],
    /// Angular size of the sun's glow, degrees.
    #[schemars(range(min = 0.5, max = 90.0))]
    pub sun_size: f64,
    /// Linear RGB radiance at the glow's centre.
    pub sun_radiance: [f64; 3],
    /// Linear RGB radiance of the sky at the zenith.
    pub zenith: [f64; 3],
    /// Linear RGB radiance of the sky at the horizon.
    pub horizon: [f64; 3],
    /// Linear RGB radiance below the horizon.
    pub ground: [f64; 3],
}

impl Default for SkyParams {
    fn default() -> Self {
        SkyParams {
            sun: [0.6, -0.35, 0.7],
            sun_size: 6.0,
            sun_radiance: [16.0, 15.0, 13.5],
            zenith: [0.12, 0.2, 0.38],
            horizon: [0.3, 0.33, 0.38],
            ground: [0.05, 0.045, 0.04],
        }
    }
}

/// A studio made at 256 × 128 texels: two soft-edged windows (discs of angular radius `size`
/// whose edge softens over a tenth of it) in a dim room, `floor` below the horizon and `walls`
/// above. The defaults give about 1 of irradiance on an upward plane per unit of intensity.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct StudioParams {
    /// The windows: direction (world, z up), angular radius in degrees, linear RGB radiance.
    pub windows: Vec<Window>,
    /// Linear RGB radiance of the room above the horizon, between the windows.
    pub walls: [f64; 3],
    /// Linear RGB radiance below the horizon.
    pub floor: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// Direction towards the window's centre (world, z up; need not be unit length).
    pub direction: [f64; 3],
    /// Angular radius, degrees.
    #[schemars(range(min = 0.5, max = 90.0))]
    pub size: f64,
    /// Linear RGB radiance.
    pub radiance: [f64; 3],
}

impl Default for StudioParams {
    fn default() -> Self {
        StudioParams {
            windows: vec![
                Window {
                    direction: [0.8, 0.2, 0.55],
                    size: 18.0,
                    radiance: [4.1, 4.0, 3.9],
                },
                Window {
                    direction: [-0.45, -0.75, 0.5],
                    size: 12.0,
                    radiance: [2.1, 2.2, 2.4],
                },
            ],
            walls: [0.04, 0.04, 0.04],
            floor: [0.02, 0.02, 0.02],
        }
    }
}

/// Texels of a procedural environment, 256 × 128.
pub const PROCEDURAL_SIZE: (usize, usize) = (256, 128);

fn unit(v: [f64; 3], what: &str) -> Result<V3, String> {
    crate::support::geometry::normalize(v)
        .filter(|u| u.iter().all(|c| c.is_finite()))
        .ok_or_else(|| format!("{what} has zero length"))
}

fn check_rgb(v: [f64; 3], what: &str) -> Result<(), String> {
    if v.iter().all(|c| c.is_finite() && *c >= 0.0) {
        Ok(())
    } else {
        Err(format!("{what} must be finite and not negative"))
    }
}

/// Texels of `f` (radiance by world direction, unrotated) at the procedural size.
fn tabulate(f: impl Fn(V3) -> [f64; 3]) -> Vec<[f32; 3]> {
    let (w, h) = PROCEDURAL_SIZE;
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        let theta = PI * (y as f64 + 0.5) / h as f64;
        for x in 0..w {
            let phi = 2.0 * PI * (x as f64 + 0.5) / w as f64;
            let d = [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ];
            out.push(f(d).map(|c| c as f32));
        }
    }
    out
}

fn angle(a: V3, b: V3) -> f64 {
    crate::support::geometry::dot(a, b).clamp(-1.0, 1.0).acos()
}

impl SkyParams {
    pub fn texels(&self) -> Result<Vec<[f32; 3]>, String> {
        let sun = unit(self.sun, "sky.sun")?;
        for (v, what) in [
            (self.sun_radiance, "sky.sun_radiance"),
            (self.zenith, "sky.zenith"),
            (self.horizon, "sky.horizon"),
            (self.ground, "sky.ground"),
        ] {
            check_rgb(v, what)?;
        }
        if !(0.5..=90.0).contains(&self.sun_size) {
            return Err("sky.sun_size must be in [0.5, 90] degrees".into());
        }
        let size = self.sun_size.to_radians();
        Ok(tabulate(|d| {
            let base = if d[2] < 0.0 {
                self.ground
            } else {
                let t = d[2].sqrt();
                [0, 1, 2].map(|k| self.horizon[k] * (1.0 - t) + self.zenith[k] * t)
            };
            let g = (-(angle(d, sun) / size).powi(2)).exp();
            [0, 1, 2].map(|k| base[k] + self.sun_radiance[k] * g)
        }))
    }
}

impl StudioParams {
    pub fn texels(&self) -> Result<Vec<[f32; 3]>, String> {
        check_rgb(self.walls, "studio.walls")?;
        check_rgb(self.floor, "studio.floor")?;
        let mut windows = Vec::new();
        for (i, w) in self.windows.iter().enumerate() {
            let d = unit(w.direction, &format!("studio.windows[{i}].direction"))?;
            check_rgb(w.radiance, &format!("studio.windows[{i}].radiance"))?;
            if !(0.5..=90.0).contains(&w.size) {
                return Err(format!(
                    "studio.windows[{i}].size must be in [0.5, 90] degrees"
                ));
            }
            windows.push((d, w.size.to_radians(), w.radiance));
        }
        Ok(tabulate(|d| {
            let mut l = if d[2] < 0.0 { self.floor } else { self.walls };
            for &(c, r, rad) in &windows {
                // A disc whose edge softens over a tenth of its radius.
                let edge = ((r - angle(d, c)) / (0.1 * r)).clamp(-0.5, 0.5) + 0.5;
                for k in 0..3 {
                    l[k] += rad[k] * edge;
                }
            }
            l
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::geometry::dot;

    fn sky() -> Environment {
        let (w, h) = PROCEDURAL_SIZE;
        Environment::new(w, h, &SkyParams::default().texels().unwrap(), 1.0, 0.4).unwrap()
    }

    /// Irradiance on a plane facing `n` by the texels themselves (exact for the piecewise
    /// constant image up to the texels' own quadrature).
    fn irradiance(env: &Environment, n: V3) -> [f64; 3] {
        let mut e = [0.0; 3];
        for (d, l, omega) in env.quadrature(env.width, env.height) {
            let c = dot(d, n).max(0.0);
            for k in 0..3 {
                e[k] += l[k] * c * omega;
            }
        }
        e
    }

    #[test]
    fn the_quadrature_covers_the_sphere_and_keeps_the_light() {
        let env = sky();
        let q = env.quadrature(64, 32);
        let total: f64 = q.iter().map(|t| t.2).sum();
        assert!((total - 4.0 * PI).abs() < 1e-9, "{total}");
        // The box filter keeps the power: ∫ L dω alike at both resolutions (to the sin θ
        // weights' difference between a texel's centre and its rows', well under 1%).
        let power = |q: &[(V3, [f64; 3], f64)]| q.iter().map(|t| t.1[1] * t.2).sum::<f64>();
        let full = power(&env.quadrature(env.width, env.height));
        assert!(
            (power(&q) / full - 1.0).abs() < 0.01,
            "{} vs {full}",
            power(&q)
        );
    }

    #[test]
    fn the_default_sky_and_studio_give_about_unit_irradiance_upwards() {
        let (w, h) = PROCEDURAL_SIZE;
        for texels in [
            SkyParams::default().texels().unwrap(),
            StudioParams::default().texels().unwrap(),
        ] {
            let env = Environment::new(w, h, &texels, 1.0, 0.0).unwrap();
            let e = irradiance(&env, [0.0, 0.0, 1.0]);
            let mean = (e[0] + e[1] + e[2]) / 3.0;
            assert!((0.7..1.4).contains(&mean), "{e:?}");
        }
    }

    /// The sampler's estimate of the irradiance on a tilted plane, E[L cos / pdf], against the
    /// texels' sum: 20 000 samples, within 3 standard errors of the estimate.
    #[test]
    fn importance_sampling_is_unbiased() {
        let env = sky();
        let n = crate::support::geometry::normalize([0.3, -0.2, 0.9]).unwrap();
        let want = irradiance(&env, n)[0];
        let count = 20_000u64;
        let (mut sum, mut sq) = (0.0, 0.0);
        for i in 0..count {
            let h = crate::support::rng::hash(7, &[i]);
            let (d, l, pdf) = env
                .sample(
                    crate::support::rng::unit(h),
                    crate::support::rng::unit(crate::support::rng::mix(h)),
                )
                .unwrap();
            assert!((pdf / env.pdf(d) - 1.0).abs() < 1e-9);
            assert_eq!(l, env.radiance(d));
            let x = l[0] * dot(d, n).max(0.0) / pdf;
            sum += x;
            sq += x * x;
        }
        let mean = sum / count as f64;
        let se = ((sq / count as f64 - mean * mean) / count as f64).sqrt();
        assert!(
            (mean - want).abs() < 3.0 * se + 1e-3 * want,
            "{mean} vs {want} (se {se})"
        );
    }

    #[test]
    fn rotation_turns_the_image_about_up() {
        let (w, h) = PROCEDURAL_SIZE;
        let texels = SkyParams::default().texels().unwrap();
        let a = Environment::new(w, h, &texels, 1.0, 0.0).unwrap();
        let b = Environment::new(w, h, &texels, 2.0, PI / 2.0).unwrap();
        let sun = crate::support::geometry::normalize(SkyParams::default().sun).unwrap();
        let turned = [-sun[1], sun[0], sun[2]];
        let (la, lb) = (a.radiance(sun), b.radiance(turned));
        assert!((lb[0] / la[0] - 2.0).abs() < 0.05, "{la:?} {lb:?}");
        assert_ne!(a, b);
    }

    #[test]
    fn bad_texels_and_parameters_are_named() {
        assert!(
            Environment::new(2, 1, &[[0.0, f32::NAN, 0.0], [0.0; 3]], 1.0, 0.0)
                .unwrap_err()
                .contains("(0, 0)")
        );
        let bad = SkyParams {
            sun: [0.0; 3],
            ..Default::default()
        };
        assert!(bad.texels().unwrap_err().contains("sky.sun"));
    }
}
