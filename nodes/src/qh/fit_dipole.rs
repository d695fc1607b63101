//! `qh.fit_dipole`: the homogeneous part of a quasi-homogeneous material — σs′ and σa per
//! channel recovered from a measured radial exitance profile by nonlinear least squares, as the
//! thesis fits its global dipole to a spot-lit flat sample.
//!
//! The measurement is a `DiffusionProfile` (e.g. from Monte Carlo) or an `Image` of a flat
//! sample lit by a narrow spot, azimuthally averaged around the spot (its brightest pixel) into
//! Rd(r) with `mm_per_pixel` and the incident `power`. The fit minimises Σ (ln Rd_model −
//! ln Rd_measured)² over the radii between 2% and 98% of the measured energy (the logarithm
//! weighs decades of falloff alike; the ends are where a measurement has the fewest photons),
//! over ln σs′ and ln σa (positive by construction): a coarse search along σt′ at the albedo
//! whose total matches, then Levenberg–Marquardt. Reports the RMS log residual per channel.
//!
//! The forward model is one of the analytic profiles (dipole, better_dipole, pbd: fast, but a
//! fit through a model inherits its bias — PBD's total is 4–10% above Monte Carlo, so its σs′,
//! σa come out 5–10% off) or `montecarlo`: a white Monte Carlo table (`white_table.rs`) of the
//! same physics as `sss.profile`'s reference, built once per run (`photons`, `seed`) and
//! rescaled to every candidate medium, isotropic scattering (the fitted material has g = 0).

use super::white_table::WhiteTable;
use crate::sss::diffusion::Medium;
use crate::sss::dipole::Dipole;
use crate::sss::material::total_at;
use crate::sss::profile::Model;
use crate::types::{DiffusionProfile, Image, ScatteringMaterial};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The forward model: dipole, better_dipole, pbd, or montecarlo (a white Monte Carlo table).
    pub model: Model,
    /// montecarlo: photons of the table (its noise is the fit's).
    #[schemars(range(min = 1000))]
    pub photons: u64,
    /// montecarlo: seed of the table.
    pub seed: u64,
    /// Relative index of refraction of the sample.
    #[schemars(range(min = 0.1, max = 10.0))]
    pub eta: f64,
    /// Image input: millimetres per pixel.
    pub mm_per_pixel: f64,
    /// Image input: incident flux of the spot, in the image's units × mm².
    pub power: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            model: Model::Pbd,
            photons: 1_000_000,
            seed: 1,
            eta: 1.3,
            mm_per_pixel: 0.1,
            power: 1.0,
        }
    }
}

pub struct FitDipole;

impl Node for FitDipole {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "qh.fit_dipole",
            version: 2,
            doc: "σs′ and σa per channel from a measured radial exitance profile (a DiffusionProfile, or an image of a spot-lit flat sample) by nonlinear least squares on ln Rd, through an analytic profile or a white Monte Carlo table.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::any_of(
                    "measured",
                    &[DiffusionProfile::TYPE, Image::TYPE],
                    "radial exitance: a profile, or an image of a spot-lit flat sample",
                ),
                Port::optional("truth", ScatteringMaterial::TYPE, "the true coefficients, for the error metrics"),
            ],
            outputs: vec![
                Port::output("material", ScatteringMaterial::TYPE, "the fitted coefficients"),
                Port::output("residual_r", "Scalar", "RMS of ln Rd residuals, red"),
                Port::output("residual_g", "Scalar", "RMS of ln Rd residuals, green"),
                Port::output("residual_b", "Scalar", "RMS of ln Rd residuals, blue"),
                Port::output("residual", "Scalar", "largest of the three"),
                Port::optional_output("error_sigma_s_prime", "Scalar", "largest relative error of σs′ over the channels vs `truth` (absent without)"),
                Port::optional_output("error_sigma_a", "Scalar", "largest relative error of σa over the channels vs `truth` (absent without)"),
            ],
            disk_cache: false,
        }
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let value = inputs.value("measured")?;
        let measured = if let Some(prof) = value.as_any().downcast_ref::<DiffusionProfile>() {
            Measured::from_profile(prof)
        } else if let Some(img) = value.as_any().downcast_ref::<Image>() {
            if !(p.mm_per_pixel > 0.0 && p.power > 0.0) {
                return Err(NodeError::param(
                    "mm_per_pixel",
                    "mm_per_pixel and power must be positive",
                ));
            }
            Measured::from_image(img, p.mm_per_pixel, p.power)
                .map_err(|e| NodeError::input("measured", e))?
        } else {
            return Err(NodeError::input(
                "measured",
                "expected a DiffusionProfile or an Image",
            ));
        };
        let mut windows = Vec::with_capacity(3);
        for c in 0..3 {
            let (r, rd) = measured.window(c);
            if r.len() < 4 {
                return Err(NodeError::input(
                    "measured",
                    format!("channel {c} has fewer than 4 usable radii (no light measured?)"),
                ));
            }
            windows.push((r, rd));
        }
        let table;
        let mut limit = None;
        let forward = if p.model == Model::Montecarlo {
            // Walks are followed until α′^events < 1e-8 for the highest albedo the totals
            // suggest (PBD's inversion, moved a third of the way closer to 1 for safety).
            let alpha_hi = (0..3)
                .map(|c| albedo_for_total(&Forward::Analytic(Model::Pbd, p.eta), measured.total[c]))
                .fold(0.0f64, f64::max);
            let alpha_hi = 1.0 - (1.0 - alpha_hi) / 3.0;
            let max_events = ((1e-8f64).ln() / alpha_hi.ln()).clamp(1_000.0, 200_000.0) as u32;
            let watch = crate::support::progress::Counter::new(
                ctx,
                crate::sss::montecarlo::chunks(p.photons),
            );
            table = WhiteTable::build(p.eta, p.photons, p.seed, max_events, &watch);
            ctx.check_cancel()?;
            limit = Some(alpha_hi);
            Forward::Table(&table)
        } else {
            Forward::Analytic(p.model, p.eta)
        };
        let mut s = [0.0; 3];
        let mut a = [0.0; 3];
        let mut res = [0.0; 3];
        for (c, (r, rd)) in windows.iter().enumerate() {
            let f = fit(&forward, r, rd, measured.total[c]);
            (s[c], a[c], res[c]) = (f.0, f.1, f.2);
            if let Some(hi) = limit {
                // The table followed walks for albedos up to `hi`; beyond it, long walks it
                // dropped would have carried weight, and the fit leans low on σs′.
                if f.0 / (f.0 + f.1) > hi {
                    ctx.warn(format!(
                        "channel {c}: fitted albedo {:.6} is beyond the {hi:.6} the Monte Carlo table was built for; raise the table's reach by fitting a profile with a higher total, or use model pbd",
                        f.0 / (f.0 + f.1)
                    ));
                }
            }
        }
        let errors = match inputs.opt::<ScatteringMaterial>("truth")? {
            Some(t) => {
                let worst = |got: [f64; 3], want: [f64; 3]| {
                    (0..3)
                        .map(|c| (got[c] / want[c] - 1.0).abs())
                        .fold(0.0f64, f64::max)
                };
                Some([worst(s, t.sigma_s_prime), worst(a, t.sigma_a)])
            }
            None => None,
        };
        let mut out = Outputs::new();
        if let Some(e) = errors {
            out = out
                .with("error_sigma_s_prime", Scalar(e[0]))
                .with("error_sigma_a", Scalar(e[1]));
        }
        Ok(out
            .with(
                "material",
                ScatteringMaterial {
                    sigma_s_prime: s,
                    sigma_a: a,
                    eta: p.eta,
                    g: 0.0,
                },
            )
            .with("residual_r", Scalar(res[0]))
            .with("residual_g", Scalar(res[1]))
            .with("residual_b", Scalar(res[2]))
            .with("residual", Scalar(res.iter().copied().fold(0.0, f64::max))))
    }
}

/// A measured radial profile: radii (mm), Rd per channel, energy fraction inside each radius,
/// and the total.
pub struct Measured {
    radii: Vec<f64>,
    rd: [Vec<f64>; 3],
    cdf: [Vec<f64>; 3],
    total: [f64; 3],
}

impl Measured {
    pub fn from_profile(p: &DiffusionProfile) -> Measured {
        Measured {
            radii: p.radii.clone(),
            rd: p.rd.clone(),
            cdf: p.cdf.clone(),
            total: p.total,
        }
    }

    /// Azimuthal average in one-pixel rings around the brightest pixel (by channel sum).
    pub fn from_image(img: &Image, mm_per_pixel: f64, power: f64) -> Result<Measured, String> {
        if img.channels < 3 {
            return Err(format!("{} channels; need RGB", img.channels));
        }
        let (w, h, ch) = (img.width, img.height, img.channels);
        let lum = |i: usize| (0..3).map(|c| img.data[i * ch + c] as f64).sum::<f64>();
        let peak = (0..w * h)
            .max_by(|&a, &b| lum(a).total_cmp(&lum(b)))
            .ok_or("empty image")?;
        let (cx, cy) = ((peak % w) as f64, (peak / w) as f64);
        let rings = ((w.max(h)) as f64 * std::f64::consts::SQRT_2) as usize + 1;
        let mut sum = vec![[0.0; 3]; rings];
        let mut count = vec![0usize; rings];
        for y in 0..h {
            for x in 0..w {
                let d = ((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)).sqrt();
                let k = d.round() as usize;
                for (c, s) in sum[k].iter_mut().enumerate() {
                    *s += img.data[(y * w + x) * ch + c] as f64;
                }
                count[k] += 1;
            }
        }
        let mut radii = Vec::new();
        let mut rd: [Vec<f64>; 3] = Default::default();
        // Ring k ≥ 1 (the centre pixel mixes the spot with its own footprint).
        for k in 1..rings {
            if count[k] == 0 {
                continue;
            }
            radii.push(k as f64 * mm_per_pixel);
            for c in 0..3 {
                // Image values are exitance per pixel area; Rd = M / incident power.
                rd[c].push(sum[k][c] / count[k] as f64 / power);
            }
        }
        let mut cdf: [Vec<f64>; 3] = Default::default();
        let mut total = [0.0; 3];
        for c in 0..3 {
            let mut acc = 0.0;
            let mut out = Vec::with_capacity(radii.len());
            for (i, &r) in radii.iter().enumerate() {
                acc += rd[c][i] * 2.0 * PI * r * mm_per_pixel;
                out.push(acc);
            }
            total[c] = acc;
            if acc > 0.0 {
                out.iter_mut().for_each(|v| *v /= acc);
            }
            cdf[c] = out;
        }
        Ok(Measured {
            radii,
            rd,
            cdf,
            total,
        })
    }

    /// The radii between 2% and 98% of the channel's energy with a positive value.
    fn window(&self, c: usize) -> (Vec<f64>, Vec<f64>) {
        self.window_between(c, 0.02, 0.98)
    }

    fn window_between(&self, c: usize, lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
        self.radii
            .iter()
            .zip(&self.rd[c])
            .zip(&self.cdf[c])
            .filter(|((_, v), f)| **v > 0.0 && (lo..=hi).contains(*f))
            .map(|((r, v), _)| (*r, *v))
            .unzip()
    }
}

/// The profile a fit compares with.
pub enum Forward<'a> {
    Analytic(Model, f64),
    Table(&'a WhiteTable),
}

impl Forward<'_> {
    /// Rd(r) at each radius for σs′ = s, σa = a.
    fn rd(&self, s: f64, a: f64, r: &[f64]) -> Vec<f64> {
        match *self {
            Forward::Analytic(model, eta) => r
                .iter()
                .map(|&r| match model {
                    Model::Dipole | Model::Montecarlo => Dipole::new(s, a, eta).rd(r),
                    Model::BetterDipole => Medium::new(s, a, 0.0, eta).better_dipole(r),
                    Model::Pbd => Medium::new(s, a, 0.0, eta).pbd(r),
                    Model::PbdMultiple => Medium::new(s, a, 0.0, eta).pbd_multiple(r),
                })
                .collect(),
            Forward::Table(t) => {
                let st = s + a;
                let rho: Vec<f64> = r.iter().map(|r| r * st).collect();
                t.profile(s / st, &rho)
                    .into_iter()
                    .map(|v| st * st * v)
                    .collect()
            }
        }
    }

    fn total(&self, alpha: f64) -> f64 {
        match *self {
            Forward::Analytic(model, eta) => total_at(model, alpha, eta, 0.0),
            Forward::Table(t) => t.total(alpha),
        }
    }
}

fn cost(fwd: &Forward, x: [f64; 2], r: &[f64], rd: &[f64]) -> (Vec<f64>, f64) {
    let (s, a) = (x[0].exp(), x[1].exp());
    let res: Vec<f64> = fwd
        .rd(s, a, r)
        .iter()
        .zip(rd)
        .map(|(&model, &m)| model.max(1e-300).ln() - m.ln())
        .collect();
    let c = res.iter().map(|v| v * v).sum();
    (res, c)
}

/// The albedo whose total reflectance is `total` (bisection; totals rise with albedo).
fn albedo_for_total(fwd: &Forward, total: f64) -> f64 {
    let top = fwd.total(1.0);
    let want = total.clamp(1e-6, top * 0.999_999);
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if fwd.total(mid) < want {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)).clamp(1e-6, 1.0 - 1e-9)
}

/// (σs′, σa, RMS log residual) for one channel.
pub fn fit(fwd: &Forward, r: &[f64], rd: &[f64], total: f64) -> (f64, f64, f64) {
    // Start: the albedo whose total matches, then the best σt′ on a log grid.
    let alpha = albedo_for_total(fwd, total);
    let mut x = [0.0, 0.0];
    let mut best = f64::INFINITY;
    for k in 0..61 {
        let st = 10f64.powf(-3.0 + 0.1 * k as f64);
        let cand = [(alpha * st).ln(), ((1.0 - alpha) * st).ln()];
        let (_, c) = cost(fwd, cand, r, rd);
        if c < best {
            best = c;
            x = cand;
        }
    }
    // Levenberg–Marquardt with a central-difference Jacobian (two parameters).
    let mut lambda = 1e-3;
    for _ in 0..200 {
        let (res, c) = cost(fwd, x, r, rd);
        let h = 1e-5;
        let jac: Vec<[f64; 2]> = {
            let mut cols = [Vec::new(), Vec::new()];
            for (k, col) in cols.iter_mut().enumerate() {
                let mut xp = x;
                let mut xm = x;
                xp[k] += h;
                xm[k] -= h;
                let (rp, _) = cost(fwd, xp, r, rd);
                let (rm, _) = cost(fwd, xm, r, rd);
                *col = rp
                    .iter()
                    .zip(&rm)
                    .map(|(p, m)| (p - m) / (2.0 * h))
                    .collect();
            }
            (0..res.len()).map(|i| [cols[0][i], cols[1][i]]).collect()
        };
        let mut jtj = [[0.0; 2]; 2];
        let mut jtr = [0.0; 2];
        for (j, e) in jac.iter().zip(&res) {
            for a in 0..2 {
                jtr[a] += j[a] * e;
                for b in 0..2 {
                    jtj[a][b] += j[a] * j[b];
                }
            }
        }
        let mut improved = false;
        for _ in 0..20 {
            let m = [
                [jtj[0][0] * (1.0 + lambda), jtj[0][1]],
                [jtj[1][0], jtj[1][1] * (1.0 + lambda)],
            ];
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            if det.abs() < 1e-300 {
                lambda *= 10.0;
                continue;
            }
            let step = [
                -(m[1][1] * jtr[0] - m[0][1] * jtr[1]) / det,
                -(-m[1][0] * jtr[0] + m[0][0] * jtr[1]) / det,
            ];
            let cand = [x[0] + step[0], x[1] + step[1]];
            let (_, cc) = cost(fwd, cand, r, rd);
            if cc < c {
                x = cand;
                lambda = (lambda * 0.3).max(1e-12);
                improved = c - cc > 1e-14 * c.max(1e-300);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let (_, c) = cost(fwd, x, r, rd);
    (x[0].exp(), x[1].exp(), (c / r.len() as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sss::profile;

    fn measured(s: f64, a: f64, model: Model, photons: u64) -> DiffusionProfile {
        let m = ScatteringMaterial {
            sigma_s_prime: [s, 2.0 * s, 0.5 * s],
            sigma_a: [a, 2.0 * a, 0.5 * a],
            eta: 1.3,
            g: 0.0,
        };
        profile::tabulate(
            &m,
            &profile::Params {
                model,
                photons,
                points: 96,
                ..Default::default()
            },
            &crate::support::progress::Counter::none(),
        )
        .profile
    }

    #[test]
    fn a_noise_free_model_profile_is_recovered_exactly() {
        // Fitting a model to its own profile: the fit's own accuracy (1e-4).
        let prof = measured(1.0, 0.05, Model::Dipole, 0);
        let m = Measured::from_profile(&prof);
        for c in 0..3 {
            let (r, rd) = m.window(c);
            let (s, a, res) = fit(
                &Forward::Analytic(Model::Dipole, 1.3),
                &r,
                &rd,
                prof.total[c],
            );
            let k = [1.0, 2.0, 0.5][c];
            assert!(
                (s / k - 1.0).abs() < 1e-4 && (a / (0.05 * k) - 1.0).abs() < 1e-4,
                "{c}: {s} {a}"
            );
            assert!(res < 1e-6);
        }
    }

    #[test]
    #[ignore = "slow: Monte Carlo profile then fit, 65 s"]
    fn coefficients_from_a_monte_carlo_profile_within_the_models_bias() {
        // The issue asks for 5% from a Monte Carlo profile. Fitting PBD (the closest of the three
        // models to our Monte Carlo, sss::profile's test) recovers σs′ 5.0–6.9% low and σa
        // 5.9–9.7% high over these media: PBD's total reflectance is ~4% above the reference and the
        // fit pays for it in the albedo. The dipole and better dipole do far worse (their
        // single-depth source cannot follow the near-source profile). Asserted: 10%, and that
        // the fit explains the profile (RMS ln residual < 0.07).
        for (s, a) in [(1.0, 0.02), (0.5, 0.1)] {
            let prof = measured(s, a, Model::Montecarlo, 100_000);
            let m = Measured::from_profile(&prof);
            for c in 0..3 {
                let k = [1.0, 2.0, 0.5][c];
                let (r, rd) = m.window(c);
                let (fs, fa, res) =
                    fit(&Forward::Analytic(Model::Pbd, 1.3), &r, &rd, prof.total[c]);
                let (es, ea) = (fs / (s * k) - 1.0, fa / (a * k) - 1.0);
                eprintln!(
                    "σs′ {} σa {}: {:+.1}% {:+.1}%, residual {res:.3}",
                    s * k,
                    a * k,
                    100.0 * es,
                    100.0 * ea
                );
                assert!(
                    es.abs() < 0.1 && ea.abs() < 0.1 && res < 0.07,
                    "{c}: {es} {ea} {res}"
                );
            }
        }
    }

    #[test]
    #[ignore = "slow: Monte Carlo table, 40 s"]
    fn the_monte_carlo_table_recovers_the_coefficients_within_five_percent() {
        // The bound: σa and σs′ within 5% from a Monte Carlo profile made with known
        // values. The measurement (100 000 photons, sss.profile's own seed) and the table
        // (200 000 photons, another seed) are independent runs of the same physics, so what is
        // left is Monte Carlo noise, not model bias. 5000 events: α′^5000 < 1e-40 at the
        // highest albedo here (0.98). Measured: within 1.7% at 400 000 table photons.
        let table = WhiteTable::build(
            1.3,
            200_000,
            99,
            5_000,
            &crate::support::progress::Counter::none(),
        );
        let fwd = Forward::Table(&table);
        let mut worst: f64 = 0.0;
        for (s, a) in [(1.0, 0.02), (0.5, 0.1)] {
            let prof = measured(s, a, Model::Montecarlo, 100_000);
            let m = Measured::from_profile(&prof);
            for c in 0..3 {
                let k = [1.0, 2.0, 0.5][c];
                let (r, rd) = m.window(c);
                let (fs, fa, res) = fit(&fwd, &r, &rd, prof.total[c]);
                let (es, ea) = (fs / (s * k) - 1.0, fa / (a * k) - 1.0);
                eprintln!(
                    "σs′ {} σa {}: {:+.2}% {:+.2}%, residual {res:.3}",
                    s * k,
                    a * k,
                    100.0 * es,
                    100.0 * ea
                );
                worst = worst.max(es.abs()).max(ea.abs());
            }
        }
        assert!(worst < 0.05, "{worst}");
    }

    /// An analog photon tracer written here, independently of `sss::montecarlo`: absorption by
    /// survival coin (no weights, no roulette), Fresnel by coin on the angle form of the
    /// formula, its own xorshift generator. It measures the profile of a pencil beam refracted
    /// into a semi-infinite isotropic medium — the experiment the white table models.
    fn analog_profile(s: [f64; 3], a: [f64; 3], eta: f64, photons: u64) -> DiffusionProfile {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut unit = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let fresnel = |mu: f64| -> f64 {
            let ti = mu.clamp(0.0, 1.0).acos();
            let st = eta * ti.sin();
            if st >= 1.0 {
                return 1.0;
            }
            if ti < 1e-9 {
                return ((eta - 1.0) / (eta + 1.0)).powi(2);
            }
            let tt = st.asin();
            0.5 * (((ti - tt).sin() / (ti + tt).sin()).powi(2)
                + ((ti - tt).tan() / (ti + tt).tan()).powi(2))
        };
        let edges: Vec<f64> = (0..=120)
            .map(|i| 1e-3 * 10f64.powf(i as f64 / 24.0))
            .collect();
        let radii: Vec<f64> = edges.windows(2).map(|w| (w[0] * w[1]).sqrt()).collect();
        let mut rd: [Vec<f64>; 3] = Default::default();
        let mut total = [0.0; 3];
        for c in 0..3 {
            let (st, albedo) = (s[c] + a[c], s[c] / (s[c] + a[c]));
            let mut bins = vec![0u64; radii.len()];
            let mut out = 0u64;
            for _ in 0..photons {
                let (mut p, mut d) = ([0.0f64; 3], [0.0f64, 0.0, 1.0]);
                for _ in 0..100_000 {
                    let step = -(1.0 - unit()).ln() / st;
                    let z = p[2] + step * d[2];
                    if z < 0.0 {
                        let t = -p[2] / d[2];
                        p = [p[0] + t * d[0], p[1] + t * d[1], 0.0];
                        if unit() < fresnel(-d[2]) {
                            d[2] = -d[2];
                            continue;
                        }
                        out += 1;
                        let r = p[0].hypot(p[1]);
                        let k = edges.partition_point(|&e| e <= r);
                        if (1..edges.len()).contains(&k) {
                            bins[k - 1] += 1;
                        }
                        break;
                    }
                    p = [p[0] + step * d[0], p[1] + step * d[1], z];
                    if unit() >= albedo {
                        break; // absorbed
                    }
                    let cos = 2.0 * unit() - 1.0;
                    let phi = 2.0 * std::f64::consts::PI * unit();
                    let sin = (1.0 - cos * cos).sqrt();
                    d = [sin * phi.cos(), sin * phi.sin(), cos];
                }
            }
            total[c] = out as f64 / photons as f64;
            rd[c] = bins
                .iter()
                .enumerate()
                .map(|(i, &n)| {
                    n as f64 / (photons as f64 * PI * (edges[i + 1].powi(2) - edges[i].powi(2)))
                })
                .collect();
        }
        let cdf = [0, 1, 2].map(|c| {
            let mut acc = 0.0;
            let mut v: Vec<f64> = (0..radii.len())
                .map(|i| {
                    acc += rd[c][i] * PI * (edges[i + 1].powi(2) - edges[i].powi(2));
                    acc
                })
                .collect();
            v.iter_mut().for_each(|x| *x /= acc.max(f64::MIN_POSITIVE));
            v
        });
        DiffusionProfile {
            model: "analog".into(),
            radii,
            rd,
            total,
            mfp: [f64::INFINITY; 3],
            cdf,
        }
    }

    #[test]
    #[ignore = "slow: analog Monte Carlo, 25 s"]
    fn an_independent_analog_monte_carlo_is_fitted_within_five_percent() {
        // A cross-code check, not a solver check: the profile comes from the analog tracer above
        // (no code shared with the white table, another generator, another absorption and
        // Fresnel scheme), so the fit recovers coefficients only if both simulations are right.
        // Bound: the same 5% as the same-code check; measured below.
        let table = WhiteTable::build(
            1.3,
            200_000,
            17,
            5_000,
            &crate::support::progress::Counter::none(),
        );
        let fwd = Forward::Table(&table);
        let (s, a) = ([1.0, 2.0, 0.5], [0.02, 0.04, 0.01]);
        let prof = analog_profile(s, a, 1.3, 100_000);
        let m = Measured::from_profile(&prof);
        let mut worst: f64 = 0.0;
        for c in 0..3 {
            let (r, rd) = m.window(c);
            let (fs, fa, res) = fit(&fwd, &r, &rd, prof.total[c]);
            let (es, ea) = (fs / s[c] - 1.0, fa / a[c] - 1.0);
            eprintln!(
                "analog σs′ {} σa {}: {:+.2}% {:+.2}%, residual {res:.3}",
                s[c],
                a[c],
                100.0 * es,
                100.0 * ea
            );
            worst = worst.max(es.abs()).max(ea.abs());
        }
        assert!(worst < 0.05, "{worst}");
    }

    #[test]
    fn a_spot_lit_image_gives_the_profile_back() {
        // A synthetic photograph of a spot-lit flat sample: each pixel holds power·Rd(r) of the
        // PBD profile at its centre. Ring averaging at integer radii differs from Rd at the ring's
        // radius by the profile's curvature over a pixel: 5% on the coefficients covers it.
        let (s, a) = (1.2, 0.06);
        let medium = Medium::new(s, a, 0.0, 1.3);
        let (n, mmpp, power) = (161usize, 0.1, 4.0);
        let c = (n / 2) as f64;
        let mut data = Vec::with_capacity(n * n * 3);
        for y in 0..n {
            for x in 0..n {
                let r = mmpp * ((x as f64 - c).powi(2) + (y as f64 - c).powi(2)).sqrt();
                let v = (power * medium.pbd(r.max(1e-3))) as f32;
                data.extend([v, v, v]);
            }
        }
        let img = Image {
            width: n,
            height: n,
            channels: 3,
            data,
        };
        let m = Measured::from_image(&img, mmpp, power).unwrap();
        let (r, rd) = m.window(0);
        let (fs, fa, _) = fit(&Forward::Analytic(Model::Pbd, 1.3), &r, &rd, m.total[0]);
        eprintln!("image fit: σs′ {fs:.4} σa {fa:.5}");
        assert!(
            (fs / s - 1.0).abs() < 0.05 && (fa / a - 1.0).abs() < 0.05,
            "{fs} {fa}"
        );
    }
}
