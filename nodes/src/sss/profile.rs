//! `sss.profile`: the radial diffuse reflectance Rd(r) of a homogeneous material, per channel,
//! on a log-spaced radius grid adapted to the material: from a thousandth of the smallest
//! transport length 1/σt′ out to the radius that holds 99.9% of every channel's reflected energy
//! (found on a fine cumulative table out to 10⁶ transport lengths; no bound derived from 1/σtr,
//! which is infinite without absorption). It carries the totals, the effective mean free paths
//! and a cumulative table for sampling radii.
//!
//! Models: `dipole` (Jensen et al. 2001, the domain notes' formulas), `better_dipole` (d'Eon
//! 2012), `pbd` (photon beam diffusion with single scattering, Habel et al. 2013) and
//! `montecarlo` (the reference: photon tracing, see `montecarlo.rs`). Rd is per unit of flux
//! transmitted into the medium, as the dipole defines it.

use super::diffusion::Medium;
use super::dipole::Dipole;
use super::montecarlo;
use crate::support::progress::Counter;
use crate::types::{DiffusionProfile, ScatteringMaterial};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Model {
    /// Jensen et al. 2001, as in the domain notes §5.
    Dipole,
    /// d'Eon 2012: Grosjean's diffusion coefficient, Fresnel-moment boundary.
    BetterDipole,
    /// Photon beam diffusion (Habel et al. 2013), multiple plus single scattering.
    Pbd,
    /// Photon beam diffusion's multiple scattering alone: for a render that adds single
    /// scattering itself (`sss.render`'s `single_scattering`), which `pbd` would count twice.
    PbdMultiple,
    /// Photon tracing in a semi-infinite medium: the reference.
    Montecarlo,
}

impl Model {
    pub fn name(self) -> &'static str {
        match self {
            Model::Dipole => "dipole",
            Model::BetterDipole => "better_dipole",
            Model::Pbd => "pbd",
            Model::PbdMultiple => "pbd_multiple",
            Model::Montecarlo => "montecarlo",
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// `pbd_multiple` (default: photon beam diffusion's multiple scattering alone, for a render that adds single scattering, as `sss.render` does by default), `pbd` (photon beam diffusion, multiple and single), `dipole` (Jensen et al. 2001), `better_dipole` (d'Eon 2012) or `montecarlo` (the photon-tracing reference).
    pub model: Model,
    /// Radius samples.
    #[schemars(range(min = 8, max = 1000000))]
    pub points: u32,
    /// Photons per channel (`montecarlo`).
    #[schemars(range(min = 1000))]
    pub photons: u64,
    /// Seed of the photon paths (`montecarlo`).
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            model: Model::PbdMultiple,
            points: 256,
            photons: 100_000,
            seed: 1,
        }
    }
}

/// Share of the reflected energy the grid must hold.
const ENERGY: f64 = 0.999;
/// Fine cumulative table for totals and the energy radius: points per decade of radius, and its
/// span in transport lengths either side of 1/σt′.
const PER_DECADE: usize = 60;
const SPAN_DECADES: i32 = 6;

pub struct Profile;

impl Node for Profile {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "sss.profile",
            // 3: the default model is `pbd_multiple` (was `dipole`), the profile `sss.render`'s
            // defaults are measured with.
            version: 3,
            doc: "Radial diffuse reflectance Rd(r) per channel (pbd_multiple by default, dipole, better_dipole, pbd or the montecarlo reference), on a grid out to 99.9% of the energy, with totals and a sampling table.",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("material", ScatteringMaterial::TYPE, "the medium")],
            outputs: vec![
                Port::output("profile", DiffusionProfile::TYPE, "Rd(r), mm⁻², radii in mm"),
                Port::output("total_r", "Scalar", "total diffuse reflectance, red"),
                Port::output("total_g", "Scalar", "total diffuse reflectance, green"),
                Port::output("total_b", "Scalar", "total diffuse reflectance, blue"),
                Port::output("stderr_r", "Scalar", "standard error of total_r (montecarlo; else 0)"),
                Port::output("stderr_g", "Scalar", "standard error of total_g (montecarlo; else 0)"),
                Port::output("stderr_b", "Scalar", "standard error of total_b (montecarlo; else 0)"),
                Port::output("max_radius", "Scalar", "largest radius of the grid, mm"),
            ],
            disk_cache: true,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let m = inputs.get::<ScatteringMaterial>("material")?;
        let chunks = if p.model == Model::Montecarlo {
            3 * montecarlo::chunks(p.photons)
        } else {
            0
        };
        let tab = tabulate(m, p, &Counter::new(ctx, chunks));
        ctx.check_cancel()?;
        if let Some(c) = (0..3).find(|&c| tab.lost[c] > 1e-4) {
            ctx.warn(format!(
                "{:.2}% of channel {c}'s photon weight was still inside after {} scattering events and is missing from the total (little or no absorption: the walk back to the surface is heavy-tailed); the total is low by about that much",
                100.0 * tab.lost[c],
                montecarlo::MAX_EVENTS
            ));
        }
        let profile = tab.profile;
        if profile.rd.iter().flatten().any(|v| !v.is_finite())
            || profile.total.iter().any(|v| !v.is_finite())
        {
            return Err(NodeError::Failed(format!(
                "the {} profile has a non-finite value: a bug, please report it with the material",
                p.model.name()
            )));
        }
        let [r, g, b] = profile.total;
        let [sr, sg, sb] = tab.stderr;
        let max_radius = profile.radii.last().copied().unwrap_or(0.0);
        Ok(Outputs::new()
            .with("profile", profile)
            .with("total_r", Scalar(r))
            .with("total_g", Scalar(g))
            .with("total_b", Scalar(b))
            .with("stderr_r", Scalar(sr))
            .with("stderr_g", Scalar(sg))
            .with("stderr_b", Scalar(sb))
            .with("max_radius", Scalar(max_radius)))
    }
}

/// A profile and, for Monte Carlo, the standard errors of its totals.
pub struct Tabulated {
    pub profile: DiffusionProfile,
    pub stderr: [f64; 3],
    /// Monte Carlo only: scattering events simulated, all channels.
    pub events: u64,
    /// Monte Carlo only: per channel, the share of photon weight given up after
    /// `montecarlo::MAX_EVENTS` events (without absorption the walk home is heavy-tailed).
    pub lost: [f64; 3],
}

/// One channel's Rd(r) for the analytic models.
fn analytic(
    m: &ScatteringMaterial,
    model: Model,
    c: usize,
) -> Box<dyn Fn(f64) -> f64 + Send + Sync> {
    match model {
        Model::Dipole | Model::Montecarlo => {
            let d = Dipole::new(m.sigma_s_prime[c], m.sigma_a[c], m.eta);
            Box::new(move |r| d.rd(r))
        }
        Model::BetterDipole => {
            let md = Medium::new(m.sigma_s_prime[c], m.sigma_a[c], m.g, m.eta);
            Box::new(move |r| md.better_dipole(r))
        }
        Model::Pbd => {
            let md = Medium::new(m.sigma_s_prime[c], m.sigma_a[c], m.g, m.eta);
            Box::new(move |r| md.pbd(r))
        }
        Model::PbdMultiple => {
            let md = Medium::new(m.sigma_s_prime[c], m.sigma_a[c], m.g, m.eta);
            Box::new(move |r| md.pbd_multiple(r))
        }
    }
}

/// ∫ Rd 2πr dr on the fine log table around the transport length `zr`: the total, and the
/// smallest table radius holding `ENERGY` of it. The disc inside the first radius holds
/// ≈ Rd(r₀)·π r₀²; then the trapezoid rule in ln r, where the integrand is smooth.
pub fn energy(rd: &dyn Fn(f64) -> f64, zr: f64) -> (f64, f64) {
    let n = 2 * SPAN_DECADES as usize * PER_DECADE;
    let lo = zr * 10f64.powi(-SPAN_DECADES);
    let h = std::f64::consts::LN_10 / PER_DECADE as f64;
    let radii: Vec<f64> = (0..=n).map(|i| lo * (i as f64 * h).exp()).collect();
    let g: Vec<f64> = radii.iter().map(|&r| rd(r) * 2.0 * PI * r * r).collect();
    let mut cum = vec![rd(lo) * PI * lo * lo];
    for i in 1..=n {
        cum.push(cum[i - 1] + 0.5 * (g[i - 1] + g[i]) * h);
    }
    let total = cum[n];
    let i = cum.partition_point(|&e| e < ENERGY * total).min(n);
    (total, radii[i].max(10.0 * zr))
}

/// The profile of `p.model` for material `m`. A Monte Carlo profile counts its photon chunks on
/// `watch` and stops early once it is stopped (the result is then partial: check cancellation).
pub fn tabulate(m: &ScatteringMaterial, p: &Params, watch: &Counter) -> Tabulated {
    let n = p.points.max(8) as usize;
    let zr = [0, 1, 2].map(|c| 1.0 / (m.sigma_s_prime[c] + m.sigma_a[c]));
    // Monte Carlo tallies on the dipole's grid: a material-adapted guide that needs no photons.
    let guide = if p.model == Model::Montecarlo {
        Model::Dipole
    } else {
        p.model
    };
    let fns = [0, 1, 2].map(|c| analytic(m, guide, c));
    let energies = [0, 1, 2].map(|c| energy(&fns[c], zr[c]));
    let r_min = 1e-3 * zr.iter().copied().fold(f64::INFINITY, f64::min);
    let r_max = energies.iter().map(|e| e.1).fold(0.0, f64::max);
    let (a, b) = (r_min.ln(), r_max.ln());
    let radii: Vec<f64> = (0..n)
        .map(|i| (a + (b - a) * i as f64 / (n - 1) as f64).exp())
        .collect();
    let mut stderr = [0.0; 3];
    let mut events = 0;
    let mut lost = [0.0; 3];
    let (rd, total) = if p.model == Model::Montecarlo {
        // Bins around each radius: edges at the geometric midpoints, the first from 0.
        let mut edges = vec![0.0];
        edges.extend(radii.windows(2).map(|w| (w[0] * w[1]).sqrt()));
        edges.push(radii[n - 1] * (radii[n - 1] / radii[n - 2]).sqrt());
        let mut rd: [Vec<f64>; 3] = Default::default();
        let mut total = [0.0; 3];
        for c in 0..3 {
            let medium = montecarlo::Medium {
                sigma_s: m.sigma_s_prime[c] / (1.0 - m.g),
                sigma_a: m.sigma_a[c],
                g: m.g,
                eta: m.eta,
            };
            let t = montecarlo::trace(&medium, &edges, p.photons, p.seed, c as u64, watch);
            let photons = t.photons as f64;
            rd[c] = t
                .bins
                .iter()
                .enumerate()
                .map(|(i, w)| w / (photons * PI * (edges[i + 1].powi(2) - edges[i].powi(2))))
                .collect();
            total[c] = t.total();
            stderr[c] = t.stderr();
            events += t.events;
            lost[c] = t.lost / photons;
        }
        (rd, total)
    } else {
        let rd = [0, 1, 2].map(|c| radii.iter().map(|&r| fns[c](r)).collect::<Vec<f64>>());
        let total = [0, 1, 2].map(|c| match p.model {
            Model::Dipole => Dipole::new(m.sigma_s_prime[c], m.sigma_a[c], m.eta).total(),
            _ => energies[c].0,
        });
        (rd, total)
    };
    let cdf = [0, 1, 2].map(|c| cumulative(&radii, &rd[c]));
    let mfp = [0, 1, 2].map(|c| {
        let sigma_tr = match p.model {
            Model::BetterDipole | Model::Pbd | Model::PbdMultiple => {
                Medium::new(m.sigma_s_prime[c], m.sigma_a[c], m.g, m.eta).sigma_tr()
            }
            _ => Dipole::new(m.sigma_s_prime[c], m.sigma_a[c], m.eta).sigma_tr,
        };
        if sigma_tr > 0.0 {
            1.0 / sigma_tr
        } else {
            f64::INFINITY
        }
    });
    Tabulated {
        profile: DiffusionProfile {
            model: p.model.name().into(),
            radii,
            rd,
            total,
            mfp,
            cdf,
        },
        stderr,
        events,
        lost,
    }
}

/// Normalised ∫₀^r Rd 2πr′ dr′ at each radius (a disc inside the first, then trapezoids in ln r).
fn cumulative(radii: &[f64], rd: &[f64]) -> Vec<f64> {
    let mut acc = rd[0] * PI * radii[0] * radii[0];
    let mut out = vec![acc];
    let g = |j: usize| rd[j] * 2.0 * PI * radii[j] * radii[j];
    for i in 1..radii.len() {
        acc += 0.5 * (g(i - 1) + g(i)) * (radii[i].ln() - radii[i - 1].ln());
        out.push(acc);
    }
    if acc > 0.0 {
        out.iter_mut().for_each(|v| *v /= acc);
    }
    out
}

/// The dipole profile (kept for callers that want the classical model directly).
pub fn dipole_profile(m: &ScatteringMaterial, n: usize) -> DiffusionProfile {
    let p = Params {
        model: Model::Dipole,
        points: n as u32,
        ..Default::default()
    };
    tabulate(m, &p, &Counter::none()).profile
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sss::material::{self, Preset};

    fn preset(p: Preset) -> ScatteringMaterial {
        material::material(&material::Params {
            preset: Some(p),
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn jensen_table_totals_match_the_domain_notes() {
        // Totals recomputed in the domain notes §5 (three decimals).
        let table = [
            (Preset::Apple, [0.846, 0.841, 0.528]),
            (Preset::Chicken1, [0.314, 0.156, 0.126]),
            (Preset::Cream, [0.976, 0.900, 0.725]),
            (Preset::Ketchup, [0.164, 0.006, 0.002]),
            (Preset::Marble, [0.867, 0.834, 0.801]),
            (Preset::Potato, [0.764, 0.613, 0.213]),
            (Preset::Skimmilk, [0.815, 0.813, 0.682]),
            (Preset::Skin1, [0.436, 0.227, 0.131]),
            (Preset::Skin2, [0.623, 0.433, 0.343]),
            (Preset::Wholemilk, [0.908, 0.881, 0.759]),
        ];
        for (p, want) in table {
            let prof = dipole_profile(&preset(p), 64);
            // Three decimals in the table: half a unit of the last place plus rounding.
            for (c, (got, want)) in prof.total.iter().zip(want).enumerate() {
                assert!((got - want).abs() < 6e-4, "{p:?} channel {c}: {got}");
            }
        }
    }

    #[test]
    fn the_grid_holds_the_energy_and_the_cdf_is_a_distribution() {
        for p in [Preset::Marble, Preset::Ketchup, Preset::Spectralon] {
            let prof = dipole_profile(&preset(p), 512);
            for c in 0..3 {
                let cdf = &prof.cdf[c];
                assert!(cdf.windows(2).all(|w| w[1] >= w[0]), "{p:?}: monotone");
                assert!((cdf[cdf.len() - 1] - 1.0).abs() < 1e-12);
                // The tabulated energy is ≥ 99.9% of the closed-form total (trapezoid on 512
                // log-spaced points: within 1e-3 of the integral).
                let d = Dipole::new(prof_material(p).0[c], prof_material(p).1[c], 1.3);
                let held = trapezoid(&d, 1e-6 * d.zr, *prof.radii.last().unwrap(), 20_000);
                assert!(
                    held >= 0.9985 * prof.total[c],
                    "{p:?} {c}: {held} of {}",
                    prof.total[c]
                );
            }
            assert!(prof.rd.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
        }
    }

    /// ∫_{lo}^{hi} Rd 2πr dr by the trapezoid rule in ln r, independent of the node's table.
    fn trapezoid(d: &Dipole, lo: f64, hi: f64, n: usize) -> f64 {
        let (a, b) = (lo.ln(), hi.ln());
        let h = (b - a) / n as f64;
        let f = |u: f64| {
            let r = u.exp();
            d.rd(r) * 2.0 * PI * r * r
        };
        (0..=n)
            .map(|i| if i == 0 || i == n { 0.5 } else { 1.0 } * f(a + i as f64 * h))
            .sum::<f64>()
            * h
    }

    fn prof_material(p: Preset) -> ([f64; 3], [f64; 3]) {
        p.coefficients()
    }

    #[test]
    fn no_absorption_extremes_and_low_eta_stay_finite() {
        // Spectralon has σa = 0: σtr = 0, an r⁻³ tail, total 1, infinite mean free path.
        let prof = dipole_profile(&preset(Preset::Spectralon), 128);
        assert!(prof.total.iter().all(|t| (t - 1.0).abs() < 1e-12));
        assert!(prof.mfp.iter().all(|m| m.is_infinite()));
        assert!(prof.radii.last().unwrap().is_finite());
        // α′ → 0 (almost pure absorber), α′ → 1, and η < 1.
        for (sp, sa, eta) in [
            (1e-9, 1.0, 1.3),
            (1.0, 1e-12, 1.3),
            (1.0, 0.1, 0.8),
            (1.0, 0.1, 1.0),
        ] {
            let m = ScatteringMaterial {
                sigma_s_prime: [sp; 3],
                sigma_a: [sa; 3],
                eta,
                g: 0.0,
            };
            let prof = dipole_profile(&m, 64);
            assert!(
                prof.rd
                    .iter()
                    .flatten()
                    .chain(prof.cdf.iter().flatten())
                    .all(|v| v.is_finite()),
                "σs′ {sp} σa {sa} η {eta}"
            );
            assert!(prof.total.iter().all(|t| (0.0..=1.0).contains(t)));
        }
    }

    #[test]
    #[ignore = "slow: Monte Carlo profiles of every Jensen material, 2 min"]
    fn every_model_against_monte_carlo_for_the_jensen_materials() {
        use crate::sss::compare::compare;
        let all = [
            Preset::Apple,
            Preset::Chicken1,
            Preset::Chicken2,
            Preset::Cream,
            Preset::Ketchup,
            Preset::Marble,
            Preset::Potato,
            Preset::Skimmilk,
            Preset::Skin1,
            Preset::Skin2,
            Preset::Spectralon,
            Preset::Wholemilk,
        ];
        let mut worst = [0.0f64; 3];
        for p in all {
            let m = preset(p);
            let mc = tabulate(
                &m,
                &Params {
                    model: Model::Montecarlo,
                    photons: 20_000,
                    points: 64,
                    ..Default::default()
                },
                &Counter::none(),
            );
            let mut dipole_l1 = None;
            if p == Preset::Ketchup {
                // The domain notes: the dipole is ≈ 12% high for ketchup red (low albedo).
                let d = dipole_profile(&m, 64).total[0];
                let rel = (d - mc.profile.total[0]) / mc.profile.total[0];
                assert!((0.05..0.2).contains(&rel), "ketchup red: {rel}");
            }
            for (k, model) in [Model::Dipole, Model::BetterDipole, Model::Pbd]
                .into_iter()
                .enumerate()
            {
                let t = tabulate(
                    &m,
                    &Params {
                        model,
                        points: 64,
                        ..Default::default()
                    },
                    &Counter::none(),
                );
                let e = compare(&mc.profile, &t.profile).unwrap();
                // Every preset reflects in every channel: the relative errors exist.
                let total: Vec<f64> = e.total.iter().map(|v| v.unwrap()).collect();
                let l1: Vec<f64> = e.l1.iter().map(|v| v.unwrap()).collect();
                println!(
                    "{p:?} {model:?}: total {:?} vs MC {:?} ± {:?}: rel {:?} l1 {:?}",
                    t.profile.total, mc.profile.total, mc.stderr, total, l1
                );
                let dipole_l1 = dipole_l1.get_or_insert(l1.clone());
                worst[k] = total.iter().fold(worst[k], |w, v| w.max(v.abs()));
                // PBD integrates the beam and adds single scattering: its profile shape is
                // closer to the reference than the single-source dipole's everywhere.
                if model == Model::Pbd {
                    let closer = l1.iter().zip(dipole_l1.iter()).all(|(a, b)| a < b);
                    assert!(closer, "{p:?}: pbd l1 {l1:?} vs dipole {dipole_l1:?}");
                }
            }
        }
        println!("worst |relative total error|: dipole, better_dipole, pbd = {worst:?}");
        // Bounds measured with 20 000 photons (MC standard error ≤ 0.0026 absolute; this test's
        // own output): dipole 0.164 (ketchup blue), better dipole 0.111 (chicken1 green), PBD
        // 0.097 (skin1 blue); the bounds leave room for the Monte Carlo noise only.
        assert!(
            worst[0] < 0.2 && worst[1] < 0.14 && worst[2] < 0.12,
            "{worst:?}"
        );
    }
}
