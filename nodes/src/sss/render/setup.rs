//! What every pixel shares: the Rd table, the near-disc energy, the irradiance samples as
//! octree sources (with the shadow map that decides which are lit).

use super::beam::{Beam, Beams};
use super::bounce;
use super::directional::Directional;
use super::emission::Exit;
use super::energy::{Energy, Scale};
use super::geometry::{ExitNormal, Geometry};
use super::{Params, Sources, Weights, MIN_POINTS};
use crate::sss::octree::{Octree, Source};
use crate::sss::points::{self, SamplePoint};
use crate::support::geometry::{bounding_sphere, dot, normalize, sub, V3};
use crate::support::optics::fresnel;
use crate::support::optics::fresnel::transmit_in;
use crate::support::progress::Counter;
use crate::support::raytrace::camera::Camera;
use crate::support::raytrace::layers::{self, Frag};
use crate::support::raytrace::light::Light;
use crate::support::raytrace::shadow::{shadow_bias, ShadowMap};
use crate::support::raytrace::tracer::Tracer;
use crate::types::{DiffusionProfile, Mesh, ScatteringMaterial};
use mesoflow_runtime::NodeError;
use rayon::prelude::*;

/// The log-uniform Rd table both gathers use, and P(ρ) for the near disc.
pub(super) struct Table {
    pub(super) ln_r0: f64,
    pub(super) inv_h: f64,
    pub(super) rd: [Vec<f64>; 3],
    /// The last radius, and per channel the tail's decay rate σ and power p, Rd ∝ e^(−σr)/r^p
    /// (`None` where the tail does not decay: no extrapolation).
    last: f64,
    tail: [Option<(f64, f64)>; 3],
}

impl Table {
    pub(super) fn new(p: &DiffusionProfile) -> Table {
        let n = p.radii.len();
        let (a, b) = (p.radii[0].ln(), p.radii[n - 1].ln());
        let h = (b - a) / (n - 1) as f64;
        // Resampled through log-linear interpolation: exact for sss.profile's log-uniform grid.
        let rd: [Vec<f64>; 3] = [0, 1, 2].map(|c| {
            (0..n)
                .map(|i| crate::sss::compare::sample(p, c, (a + h * i as f64).exp()))
                .collect()
        });
        // The tail as Rd ∝ e^(−σr)/r^p through three points eight table steps apart at the
        // end: a profile's far field is an exponential over a power of r (the dipole's flux
        // terms r⁻², the better dipole's fluence term r⁻¹).
        let k = 8.min((n - 1) / 2);
        let at = |i: usize| (a + h * i as f64).exp();
        let (i0, i1, i2) = (n - 1 - 2 * k, n - 1 - k, n - 1);
        let tail = [0, 1, 2].map(|c: usize| {
            let y = [i0, i1, i2].map(|i| rd[c][i]);
            if k == 0 || y.iter().any(|&v| v.is_nan() || v <= 0.0) {
                return None;
            }
            let r = [i0, i1, i2].map(at);
            let (d1, d2) = ((y[1] / y[0]).ln(), (y[2] / y[1]).ln());
            let (e1, e2) = (r[1] - r[0], r[2] - r[1]);
            let (l1, l2) = ((r[1] / r[0]).ln(), (r[2] / r[1]).ln());
            // d = −σe − p·l for both intervals.
            let det = e1 * l2 - e2 * l1;
            let sigma = -(d1 * l2 - d2 * l1) / det;
            let power = -(e1 * d2 - e2 * d1) / det;
            (sigma > 0.0 && sigma.is_finite() && power.is_finite()).then_some((sigma, power))
        });
        let last = b.exp();
        Table {
            ln_r0: a,
            inv_h: 1.0 / h,
            rd,
            last,
            tail,
        }
    }

    /// [`Table::at`], and beyond the last radius the tail's decay instead of 0.
    /// The table stops where the profile holds 99.9% of its energy (`sss.profile`), which
    /// the planar gather can ignore; the body's share cannot: it takes away the dipoles'
    /// fluence at every distance, and without their flux beyond the table a back-lit skin
    /// ball's far side lost two thirds of its red.
    pub(super) fn at_any_distance(&self, r: f64) -> [f64; 3] {
        if r <= self.last {
            return self.at(r);
        }
        [0, 1, 2].map(|c| match self.tail[c] {
            Some((sigma, power)) => {
                self.rd[c][self.rd[c].len() - 1]
                    * (-sigma * (r - self.last)).exp()
                    * (self.last / r).powf(power)
            }
            None => 0.0,
        })
    }

    pub(super) fn at(&self, r: f64) -> [f64; 3] {
        let f = (r.max(1e-300).ln() - self.ln_r0) * self.inv_h;
        let n = self.rd[0].len();
        if f <= 0.0 {
            return [0, 1, 2].map(|c| self.rd[c][0]);
        }
        let i = f.floor() as usize;
        if i + 1 >= n {
            return [0.0; 3];
        }
        let t = f - i as f64;
        [0, 1, 2].map(|c| self.rd[c][i] * (1.0 - t) + self.rd[c][i + 1] * t)
    }
}

/// Energy of the profile inside radius ρ per channel: total × CDF(ρ), linear in ln r.
pub(super) fn disc_energy(p: &DiffusionProfile, rho: f64) -> [f64; 3] {
    let radii = &p.radii;
    [0, 1, 2].map(|c| {
        let cdf = &p.cdf[c];
        let i = radii.partition_point(|&r| r < rho);
        let f = if i == 0 {
            // Inside the first radius Rd is flat: the disc's share grows as ρ².
            cdf[0] * (rho / radii[0]).powi(2)
        } else if i >= radii.len() {
            1.0
        } else {
            let t = (rho.ln() - radii[i - 1].ln()) / (radii[i].ln() - radii[i - 1].ln());
            cdf[i - 1] * (1.0 - t) + cdf[i] * t
        };
        p.total[c] * f
    })
}

/// Everything the pixels share: samples as sources (mm, E·ΔA), the table, the near disc.
pub(super) struct Setup {
    pub(super) table: Table,
    pub(super) sources: Vec<Source>,
    pub(super) octree: Octree,
    /// Area each source stands for, mm².
    pub(super) area_each: f64,
    /// ρ₀ in mm and P(ρ₀) per channel.
    pub(super) near: f64,
    pub(super) near_energy: [f64; 3],
    pub(super) spacing_mm: f64,
    pub(super) shadow: Option<ShadowMap>,
    pub(super) eta: f64,
    /// mm per world unit.
    pub(super) unit: f64,
    /// The shape's term, with `exit_normal` or `body` geometry and point sources.
    pub(super) exit_normal: Option<ExitNormal>,
    /// The shape's and the light's angle's term, with those geometries and beam sources,
    /// entered for `octree`'s points.
    pub(super) beam: Option<Beams>,
    /// With `directional` geometry, the directional dipole's factor.
    pub(super) directional: Option<Directional>,
    /// With `energy: half_space`, the factor on the light entering.
    pub(super) energy: Option<Scale>,
    /// The profile's total diffuse reflectance per channel.
    pub(super) total: [f64; 3],
    /// How the exitance leaves in angle (`emission`).
    pub(super) exit: Exit,
    /// With `bounces`, the light between parts.
    pub(super) bounced: Option<Bounced>,
    /// Wall time of the bounces' rounds, s (0 without them).
    pub(super) bounce_seconds: f64,
}

impl Setup {
    /// The irradiance samples on `tracer`'s mesh and their octree (the bounces trace through
    /// its BVH).
    pub(super) fn new(
        tracer: &Tracer,
        material: &ScatteringMaterial,
        profile: &DiffusionProfile,
        p: &Params,
        light: &Light,
        weights: &dyn Weights,
        warnings: &mut Vec<String>,
    ) -> Result<Setup, NodeError> {
        let mesh = tracer.mesh;
        let unit = p.mm_per_unit;
        let area_mm2 = points::area(mesh) * unit * unit;
        if area_mm2 <= 0.0 {
            return Err(NodeError::input("mesh", "has no area"));
        }
        let finite_mfp = profile.mfp.iter().copied().filter(|m| m.is_finite());
        let wanted = match p.spacing {
            Some(s) if s > 0.0 && s.is_finite() => s,
            Some(s) => {
                return Err(NodeError::param(
                    "spacing",
                    format!("{s} is not a positive length (mm)"),
                ))
            }
            // Without absorption 1/σtr is infinite: a tenth of the grid's extent instead.
            None => {
                0.25 * finite_mfp
                    .fold(f64::INFINITY, f64::min)
                    .min(0.1 * profile.radii.last().copied().unwrap_or(1.0))
            }
        };
        let mut spacing = wanted;
        let cap = (area_mm2 / p.max_points.max(64) as f64).sqrt();
        if spacing < cap {
            warnings.push(format!(
                "max_points {} caps the irradiance samples: spacing {cap:.4} mm instead of the {wanted:.4} mm the profile asks for",
                p.max_points
            ));
            spacing = cap;
        }
        let floor = (area_mm2 / MIN_POINTS).sqrt();
        if spacing > floor {
            warnings.push(format!(
                "the mesh ({area_mm2:.3} mm²) is small against the sample spacing {spacing:.4} mm: using {MIN_POINTS} samples at {floor:.4} mm"
            ));
            spacing = floor;
        }
        let mut samples = points::sample(mesh, spacing / unit, p.seed);
        // Dart throwing lands near, not exactly at, the count the spacing implies.
        let most = p.max_points.max(64) as usize;
        if samples.points.len() > most {
            samples.points.truncate(most);
            samples.area = samples.total_area / most as f64;
        }
        let area_each = samples.area * unit * unit;
        let shadow = if p.shadows {
            Some(shadow_map(mesh, light, p.shadow_resolution)?)
        } else {
            None
        };
        let energy = energy_scale(material, profile, p)?;
        let sources: Vec<Source> = samples
            .points
            .par_iter()
            .map(|s| {
                let e = irradiance(light, shadow.as_ref(), s.p, s.n, material.eta);
                let f = if e > 0.0 {
                    let at = Frag {
                        t: 0.0,
                        tri: s.tri,
                        b1: s.b1,
                        b2: s.b2,
                    };
                    let to_light = light.at(s.p).0;
                    let k = energy
                        .as_ref()
                        .map_or([1.0; 3], |k| k.at(dot(s.n, to_light)));
                    let f = weights.entrance(&at, to_light);
                    [0, 1, 2].map(|c| f[c] * k[c])
                } else {
                    [0.0; 3]
                };
                Source {
                    p: s.p.map(|v| v * unit),
                    n: s.n,
                    power: f.map(|f| f * e * area_each),
                }
            })
            .collect();
        let mut setup = Setup::assemble(
            tracer,
            material,
            profile,
            p,
            light,
            (sources, area_each, spacing),
            shadow,
        )?;
        if p.bounces > 0 {
            let start = std::time::Instant::now();
            setup.bounce(tracer, &samples.points, p, area_each);
            setup.bounce_seconds = start.elapsed().as_secs_f64();
        }
        Ok(setup)
    }

    /// The set-up around lit sources (mm, E·ΔA each of `area_each` mm², `spacing` mm apart):
    /// their octree, beams and the tables, without bounces. [`Setup::new`] bounces the light
    /// after; `lighting.rs` gives the sources a cached `sss.lighting` kept after its bounces.
    pub(super) fn assemble(
        tracer: &Tracer,
        material: &ScatteringMaterial,
        profile: &DiffusionProfile,
        p: &Params,
        light: &Light,
        (sources, area_each, spacing): (Vec<Source>, f64, f64),
        shadow: Option<ShadowMap>,
    ) -> Result<Setup, NodeError> {
        let unit = p.mm_per_unit;
        let octree = Octree::build(sources.clone(), area_each);
        let near = 2.0 * area_each.sqrt();
        let follows_the_shape = matches!(
            p.geometry,
            Geometry::Auto | Geometry::ExitNormal | Geometry::Body
        );
        let beam = (follows_the_shape && p.sources == Sources::Beam)
            .then(|| Beams::new(Beam::new(material, light, unit), &octree, tracer));
        Ok(Setup {
            table: Table::new(profile),
            sources,
            octree,
            area_each,
            near,
            near_energy: disc_energy(profile, near),
            spacing_mm: spacing,
            shadow,
            eta: material.eta,
            unit,
            exit_normal: (follows_the_shape && p.sources == Sources::Point)
                .then(|| ExitNormal::new(material)),
            beam,
            directional: (p.geometry == Geometry::Directional)
                .then(|| Directional::new(material, light, unit)),
            energy: energy_scale(material, profile, p)?,
            total: profile.total,
            exit: Exit::for_material(p.emission, material, p.single_scattering)?,
            bounced: None,
            bounce_seconds: 0.0,
        })
    }

    /// Rd per channel between the shaded point `xo` (mm, normal `no`) and a source at `q` with
    /// normal `nq`, d² apart, the term `key` of a gather over `octree`.
    pub(super) fn rd(&self, xo: V3, no: V3, key: usize, q: V3, nq: V3, d2: f64) -> [f64; 3] {
        let (f, r) = match (&self.exit_normal, &self.beam, &self.directional) {
            (Some(en), _, _) => (
                en.factor(xo, no, q, nq),
                self.table.at_any_distance(d2.sqrt()),
            ),
            (_, Some(beam), _) => (
                beam.factor(xo, no, key),
                self.table.at_any_distance(d2.sqrt()),
            ),
            (_, _, Some(dd)) => (dd.factor(xo, no, q, nq), self.table.at(d2.sqrt())),
            _ => return self.table.at(d2.sqrt()),
        };
        [0, 1, 2].map(|c| r[c] * f[c])
    }

    /// `bounces` rounds of light between parts (`bounce.rs`): each gathers the samples' own
    /// exitance from the light so far, sends it to the samples that see it, and rebuilds the
    /// sources from their direct and arriving light. None when under [`bounce::NEGLIGIBLE`] of
    /// the first round's rays return to the object.
    fn bounce(&mut self, tracer: &Tracer, points: &[SamplePoint], p: &Params, area_each: f64) {
        let direct: Vec<[f64; 3]> = self
            .sources
            .iter()
            .map(|s| s.power.map(|v| v / area_each))
            .collect();
        // The light between parts varies on the scale of the parts, not of the profile's peak:
        // it is computed on a uniform subset (a prefix of the dart-throwing order) and each
        // sample takes its nearest member's.
        let count = points.len().min(bounce::MOST_POINTS);
        let subset = &points[..count];
        // An object that hardly sees itself (a convex one) has no light to send between parts:
        // the rounds would cost three quarters of the node and change nothing.
        if !bounce::sees_itself(tracer, subset, p.seed) {
            return;
        }
        let spacing = self.spacing_mm / self.unit * (points.len() as f64 / count as f64).sqrt();
        let nearest = bounce::Nearest::new(subset, spacing);
        let member: Vec<usize> = points
            .par_iter()
            .enumerate()
            .map(|(i, s)| {
                if i < count {
                    i
                } else {
                    nearest.find(s.p).unwrap_or(0)
                }
            })
            .collect();
        // Light from other parts arrives from every side: the energy's hemispherical factor.
        let k = self.energy.as_ref().map_or([1.0; 3], Scale::diffuse);
        let into = [0, 1, 2].map(|c| (1.0 - 2.0 * fresnel::moment(1, 1.0 / self.eta)) * k[c]);
        let mut arriving = vec![[0.0; 3]; count];
        for round in 0..p.bounces {
            let exitance: Vec<[f64; 3]> = self.sources[..count]
                .par_iter()
                .enumerate()
                .map(|(i, s)| {
                    let (sum, _) =
                        self.octree
                            .gather_keyed(s.p, self.near, p.threshold, &|key, q, nq, d2| {
                                self.rd(s.p, s.n, key, q, nq, d2)
                            });
                    let e = [0, 1, 2].map(|c| direct[i][c] + into[c] * arriving[i][c]);
                    [0, 1, 2].map(|c| sum[c] + e[c] * self.near_energy[c])
                })
                .collect();
            arriving = bounce::arriving(tracer, subset, &nearest, &exitance, p.seed ^ round as u64);
            for (i, s) in self.sources.iter_mut().enumerate() {
                let a = arriving[member[i]];
                s.power = [0, 1, 2].map(|c| (direct[i][c] + into[c] * a[c]) * area_each);
            }
            self.octree = Octree::build(self.sources.clone(), area_each);
            self.beam = self.beam.take().map(|b| b.rebuilt(&self.octree, tracer));
        }
        self.bounced = Some(Bounced {
            nearest,
            arriving: arriving
                .into_iter()
                .map(|a| [0, 1, 2].map(|c| a[c] * into[c]))
                .collect(),
        });
    }

    /// The light from other parts transmitted in at the sample nearest to `x` (world units).
    pub(super) fn bounced_at(&self, x: V3) -> [f64; 3] {
        self.bounced
            .as_ref()
            .and_then(|b| b.nearest.find(x).map(|i| b.arriving[i]))
            .unwrap_or([0.0; 3])
    }
}

/// What the bounces leave for the pixels' near discs.
pub(super) struct Bounced {
    pub(super) nearest: bounce::Nearest,
    /// Per sample the transmitted irradiance arriving from other parts.
    pub(super) arriving: Vec<[f64; 3]>,
}

impl Setup {
    /// The `brdf` mode's setup: no samples; the whole profile's energy is the "near disc", so
    /// each pixel's exitance is its own transmitted irradiance times the total reflectance.
    pub(super) fn local(
        mesh: &Mesh,
        material: &ScatteringMaterial,
        profile: &DiffusionProfile,
        p: &Params,
        light: &Light,
    ) -> Result<Setup, NodeError> {
        let shadow = if p.shadows {
            Some(shadow_map(mesh, light, p.shadow_resolution)?)
        } else {
            None
        };
        Ok(Setup {
            table: Table::new(profile),
            sources: Vec::new(),
            octree: Octree::build(Vec::new(), 0.0),
            area_each: 0.0,
            near: f64::INFINITY,
            near_energy: profile.total,
            spacing_mm: 0.0,
            shadow,
            eta: material.eta,
            unit: p.mm_per_unit,
            exit_normal: None,
            beam: None,
            directional: None,
            energy: energy_scale(material, profile, p)?,
            total: profile.total,
            exit: Exit::for_material(p.emission, material, p.single_scattering)?,
            bounced: None,
            bounce_seconds: 0.0,
        })
    }
}

/// The `energy` parameter's factor, when it is `half_space`.
fn energy_scale(
    m: &ScatteringMaterial,
    profile: &DiffusionProfile,
    p: &Params,
) -> Result<Option<Scale>, NodeError> {
    match p.energy {
        Energy::Profile => Ok(None),
        Energy::HalfSpace => Scale::new(m, profile, p.single_scattering).map(Some),
    }
}

impl Setup {
    /// The energy factor for light arriving at incidence cosine `mu0` (1 with the profile's).
    pub(super) fn energy_at(&self, mu0: f64) -> [f64; 3] {
        self.energy.as_ref().map_or([1.0; 3], |k| k.at(mu0))
    }
}

/// Transmitted irradiance at a surface point with normal n (world units).
pub(super) fn irradiance(light: &Light, shadow: Option<&ShadowMap>, x: V3, n: V3, eta: f64) -> f64 {
    let (l, e) = light.at(x);
    let cos = dot(n, l);
    if cos <= 0.0 {
        return 0.0;
    }
    if let Some(s) = shadow {
        if !s.lit(x, cos) {
            return 0.0;
        }
    }
    e * cos * transmit_in(cos, eta)
}

/// Nearest-surface depth map from the light (one ray-cast layer).
pub fn shadow_map(mesh: &Mesh, light: &Light, size: u32) -> Result<ShadowMap, NodeError> {
    let (camera, bias) = shadow_camera(mesh, light, size)?;
    let l = layers::trace(mesh, &camera, 1, &Counter::none());
    let depth = l
        .front
        .iter()
        .map(|f| f.map_or(f64::INFINITY, |f| f.t))
        .collect();
    Ok(ShadowMap {
        bias,
        camera,
        depth,
    })
}

/// The light's view of the mesh a [`shadow_map`] of `size` texels a side is traced from, and
/// its depth bias.
pub(super) fn shadow_camera(
    mesh: &Mesh,
    light: &Light,
    size: u32,
) -> Result<(Camera, f64), NodeError> {
    let (c, r) = bounding_sphere(mesh);
    let (dir, from) = match light.position {
        Some(lp) => (
            normalize(sub(c, lp)).ok_or_else(|| {
                NodeError::param("light", "the point light is at the mesh's centre")
            })?,
            Some(lp),
        ),
        None => (light.direction.map(|v| -v), None),
    };
    let camera =
        Camera::enclosing(c, r, dir, from, size).map_err(|e| NodeError::param("light", e))?;
    Ok((camera, shadow_bias(r, size)))
}
