//! The Monte Carlo reference for diffusion profiles: photons of a pencil beam, already refracted
//! at normal incidence (Rd is per unit of transmitted flux, as the dipole's is), walk through a
//! homogeneous semi-infinite medium with Henyey–Greenstein scattering; at the smooth dielectric
//! boundary they are reflected with the exact Fresnel probability or leave, and the radius
//! where they leave is tallied with the photon's weight.
//!
//! Absorption is carried as weight (w ← α·w at each event) with Russian roulette below 1e-4, so
//! every photon contributes. Deterministic: photons run in chunks of `CHUNK`, chunk c draws from
//! SplitMix64 seeded by hash(seed, channel, c), and chunk tallies are added in chunk order.

use crate::support::geometry::rotate;
use crate::support::optics::fresnel;
use crate::support::optics::phase::sample_hg;
use crate::support::progress::Counter;
use crate::support::rng;
use crate::support::rng::Stream;
use rayon::prelude::*;
use std::f64::consts::PI;

const CHUNK: u64 = 4096;
/// Weight below which Russian roulette plays (survivors carry weight / SURVIVE).
const ROULETTE: f64 = 1e-4;
const SURVIVE: f64 = 0.1;
/// Scattering events after which a photon is given up and counted as `lost`: without absorption
/// the return time to the boundary is heavy-tailed (P(T > n) ∝ n^−½), so a few photons would
/// otherwise walk for ever.
pub const MAX_EVENTS: u32 = 1_000_000;

/// The medium of one channel.
#[derive(Clone, Copy, Debug)]
pub struct Medium {
    pub sigma_s: f64,
    pub sigma_a: f64,
    pub g: f64,
    pub eta: f64,
}

/// What the photons did. `bins[i]` is the weight that left with radius in [edges[i], edges[i+1]).
#[derive(Clone, Debug, PartialEq)]
pub struct Tally {
    pub photons: u64,
    pub bins: Vec<f64>,
    /// Weight that left beyond the last edge.
    pub beyond: f64,
    /// Σw and Σw² of each photon's escaped weight (for the standard error).
    pub reflected: f64,
    pub reflected_sq: f64,
    /// Weight that left after exactly one scattering event.
    pub single: f64,
    pub absorbed: f64,
    /// Weight of photons given up after `MAX_EVENTS`.
    pub lost: f64,
    /// Scattering events simulated.
    pub events: u64,
}

impl Tally {
    fn new(n: usize) -> Tally {
        Tally {
            photons: 0,
            bins: vec![0.0; n],
            beyond: 0.0,
            reflected: 0.0,
            reflected_sq: 0.0,
            single: 0.0,
            absorbed: 0.0,
            lost: 0.0,
            events: 0,
        }
    }

    fn add(mut self, o: &Tally) -> Tally {
        self.photons += o.photons;
        for (a, b) in self.bins.iter_mut().zip(&o.bins) {
            *a += b;
        }
        self.beyond += o.beyond;
        self.reflected += o.reflected;
        self.reflected_sq += o.reflected_sq;
        self.single += o.single;
        self.absorbed += o.absorbed;
        self.lost += o.lost;
        self.events += o.events;
        self
    }

    /// Total diffuse reflectance per photon.
    pub fn total(&self) -> f64 {
        self.reflected / self.photons.max(1) as f64
    }

    /// Standard error of `total`.
    pub fn stderr(&self) -> f64 {
        let n = self.photons.max(2) as f64;
        let mean = self.reflected / n;
        ((self.reflected_sq / n - mean * mean).max(0.0) / (n - 1.0)).sqrt()
    }
}

/// Bin of radius r among increasing `edges` (edges[0] = 0); None beyond the last.
fn bin(edges: &[f64], r: f64) -> Option<usize> {
    let i = edges.partition_point(|&e| e <= r);
    (i < edges.len()).then(|| i.saturating_sub(1))
}

/// One chunk of photons. `exits`, when given, also receives every escaping photon's (radius,
/// scattering events) — the record white Monte Carlo reweights (`white`).
#[allow(clippy::too_many_arguments)]
fn chunk(
    m: &Medium,
    edges: &[f64],
    seed: u64,
    channel: u64,
    c: u64,
    count: u64,
    max_events: u32,
    mut exits: Option<&mut Vec<(f64, u32)>>,
    watch: &Counter,
) -> Tally {
    let mut t = Tally::new(edges.len() - 1);
    if watch.stopped() {
        return t; // the caller sees the cancellation and drops the partial tally
    }
    let mut rnd = Stream(rng::hash(seed, &[channel, c]));
    let sigma_t = m.sigma_s + m.sigma_a;
    let albedo = m.sigma_s / sigma_t;
    for _ in 0..count {
        t.photons += 1;
        let (mut p, mut d, mut w) = ([0.0f64; 3], [0.0, 0.0, 1.0f64], 1.0f64);
        let mut events = 0u32;
        loop {
            let s = -(1.0 - rnd.unit()).ln() / sigma_t;
            if p[2] + s * d[2] < 0.0 {
                // Reaches the boundary; the free path restarts there (exponential: memoryless).
                let to = -p[2] / d[2];
                p = [p[0] + to * d[0], p[1] + to * d[1], 0.0];
                if rnd.unit() < fresnel::reflectance_inside(-d[2], m.eta) {
                    d[2] = -d[2];
                    continue;
                }
                let r = p[0].hypot(p[1]);
                match bin(edges, r) {
                    Some(i) => t.bins[i] += w,
                    None => t.beyond += w,
                }
                if let Some(e) = exits.as_deref_mut() {
                    e.push((r, events));
                }
                t.reflected += w;
                t.reflected_sq += w * w;
                if events == 1 {
                    t.single += w;
                }
                break;
            }
            p = [p[0] + s * d[0], p[1] + s * d[1], p[2] + s * d[2]];
            events += 1;
            t.absorbed += w * (1.0 - albedo);
            w *= albedo;
            if w < ROULETTE {
                if rnd.unit() >= SURVIVE {
                    break;
                }
                w /= SURVIVE;
            }
            if events >= max_events {
                t.lost += w;
                break;
            }
            let cos = sample_hg(m.g, rnd.unit());
            d = rotate(d, cos, 2.0 * PI * rnd.unit());
        }
        t.events += events as u64;
    }
    t
}

/// Chunks of photons `photons` makes: the unit of progress that `watch` counts.
pub fn chunks(photons: u64) -> u64 {
    photons.div_ceil(CHUNK)
}

/// Traces `photons` photons; `edges` are the tally's bin edges in mm, from 0, increasing. Each
/// finished chunk is counted on `watch`; once it is stopped, the rest of the chunks are skipped
/// (the tally is then partial: callers check for cancellation).
pub fn trace(
    m: &Medium,
    edges: &[f64],
    photons: u64,
    seed: u64,
    channel: u64,
    watch: &Counter,
) -> Tally {
    let chunks = chunks(photons);
    let parts: Vec<Tally> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let count = CHUNK.min(photons - c * CHUNK);
            let t = chunk(m, edges, seed, channel, c, count, MAX_EVENTS, None, watch);
            watch.add(1);
            t
        })
        .collect();
    parts
        .iter()
        .fold(Tally::new(edges.len() - 1), |acc, p| acc.add(p))
}

/// White Monte Carlo (Alerstam et al. 2008's idea for weight-carried absorption): photons walk
/// a non-absorbing medium of unit σt with isotropic scattering; each escaping photon's radius
/// (in mean free paths) and scattering count are kept. Since absorption only multiplies the
/// weight by α′ per event, the same walks give every albedo: Rd(ρ; α′) = Σ α′^events over the
/// photons escaping at ρ. Photons still walking after `max_events` are dropped (their weight
/// is at most α′^max_events for any albedo the caller will ask). Returns the exits in photon
/// order (chunk by chunk, so independent of the thread count) and the number dropped.
pub fn white(
    eta: f64,
    photons: u64,
    seed: u64,
    max_events: u32,
    watch: &Counter,
) -> (Vec<(f64, u32)>, u64) {
    let m = Medium {
        sigma_s: 1.0,
        sigma_a: 0.0,
        g: 0.0,
        eta,
    };
    let chunks = photons.div_ceil(CHUNK);
    let parts: Vec<(Vec<(f64, u32)>, u64)> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let count = CHUNK.min(photons - c * CHUNK);
            let mut exits = Vec::new();
            let t = chunk(
                &m,
                &[0.0, f64::INFINITY],
                seed,
                0,
                c,
                count,
                max_events,
                Some(&mut exits),
                watch,
            );
            watch.add(1);
            let dropped = count - exits.len() as u64;
            debug_assert!(t.lost <= dropped as f64 + 1e-9);
            (exits, dropped)
        })
        .collect();
    let dropped = parts.iter().map(|p| p.1).sum();
    (parts.into_iter().flat_map(|p| p.0).collect(), dropped)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(s: f64, a: f64, g: f64, eta: f64, photons: u64) -> Tally {
        let m = Medium {
            sigma_s: s,
            sigma_a: a,
            g,
            eta,
        };
        trace(&m, &[0.0, 1.0, 10.0], photons, 7, 0, &Counter::none())
    }

    /// Asserts |got − want| within `k` standard errors, printing both.
    fn within(got: f64, want: f64, se: f64, k: f64, what: &str) {
        println!("{what}: {got:.5} ± {se:.5} (want {want:.5})");
        assert!(
            (got - want).abs() <= k * se,
            "{what}: {got} ± {se} vs {want}"
        );
    }

    #[test]
    fn energy_is_conserved_with_a_matched_boundary() {
        // η = 1: every photon is eventually reflected or absorbed; roulette conserves energy
        // in expectation only, so the sum is 1 within Monte Carlo error (the per-photon
        // outcome is bounded by 1/SURVIVE·ROULETTE-scale weights; 5 standard errors).
        let t = run(0.9, 0.1, 0.5, 1.0, 40_000);
        let n = t.photons as f64;
        let sum = (t.reflected + t.absorbed + t.lost) / n;
        within(sum, 1.0, t.stderr().max(1e-4), 5.0, "reflected + absorbed");
    }

    #[test]
    fn without_absorption_everything_comes_back() {
        // α′ = 1, η = 1: a random walk in a half space returns with probability 1; the photons
        // still walking after MAX_EVENTS are counted as lost (P ∝ n^−½ ≈ 1e-3).
        let t = run(1.0, 0.0, 0.0, 1.0, 4_000);
        let total = t.total();
        assert!(total > 0.99 && total <= 1.0 + 1e-12, "{total}");
        assert!((t.reflected + t.lost - t.photons as f64).abs() < 1e-6);
    }

    #[test]
    #[ignore = "slow: Monte Carlo single scattering, 100 000 photons a medium, 100 s"]
    fn single_scattering_matches_the_closed_form() {
        single_scattering_against_the_closed_form(100_000);
    }

    /// The same claim in the default tier with a tenth of the photons: the bound is four
    /// standard errors, which widen by √10 with them.
    #[test]
    fn single_scattering_matches_the_closed_form_at_small_size() {
        single_scattering_against_the_closed_form(10_000);
    }

    fn single_scattering_against_the_closed_form(n: u64) {
        // Isotropic, η = 1: the weight leaving after one event is (α/2)(1 − ln 2) per photon
        // (derived in diffusion.rs). The per-photon single-scatter weight is 0 or α, so its
        // standard error is α·√(p(1 − p)/n) with p the escape probability.
        for (s, a) in [(1.0, 0.0), (0.6, 0.4)] {
            let alpha = s / (s + a);
            let t = run(s, a, 0.0, 1.0, n);
            let p = 0.5 * (1.0 - 2f64.ln());
            let se = alpha * (p * (1.0 - p) / n as f64).sqrt();
            within(t.single / n as f64, alpha * p, se, 4.0, "single scattering");
        }
    }

    #[test]
    fn single_scattering_through_a_dielectric_boundary_matches_quadrature() {
        // η ≠ 1, isotropic, the beam already refracted at normal incidence: a photon scatters
        // first at depth z ~ Exp(1) (σt = 1), turns up with cosine μ with density ½, reaches the
        // boundary with probability e^(−z/μ), and leaves with 1 − F(μ); what Fresnel reflects
        // goes down again and must scatter a second time. Integrated over z:
        //   single = (α/2) ∫₀¹ (1 − F(μ)) μ/(1 + μ) dμ.
        // F here is Fresnel in its angle form (Born & Wolf: rs = −sin(θi−θt)/sin(θi+θt),
        // rp = tan(θi−θt)/tan(θi+θt)), written independently of `fresnel.rs`; the integral is
        // a fine midpoint sum (10⁵ points, far below the Monte Carlo error).
        fn fresnel_angles(mu: f64, eta: f64) -> f64 {
            let ti = mu.clamp(0.0, 1.0).acos();
            let st = eta * ti.sin();
            if st >= 1.0 {
                return 1.0;
            }
            let tt = st.asin();
            if ti < 1e-9 {
                let r = (eta - 1.0) / (eta + 1.0);
                return r * r;
            }
            let rs = (ti - tt).sin() / (ti + tt).sin();
            let rp = (ti - tt).tan() / (ti + tt).tan();
            0.5 * (rs * rs + rp * rp)
        }
        for eta in [1.3, 1.5, 0.8] {
            let (s, a) = (0.7, 0.3);
            let alpha = s / (s + a);
            let m = 100_000;
            let integral: f64 = (0..m)
                .map(|i| {
                    let mu = (i as f64 + 0.5) / m as f64;
                    (1.0 - fresnel_angles(mu, eta)) * mu / (1.0 + mu)
                })
                .sum::<f64>()
                / m as f64;
            let want = 0.5 * alpha * integral;
            let n = 200_000;
            let t = run(s, a, 0.0, eta, n);
            // Per photon the single-scatter weight is 0 or α: standard error α·√(p(1−p)/n).
            let p = want / alpha;
            let se = alpha * (p * (1.0 - p) / n as f64).sqrt();
            within(
                t.single / n as f64,
                want,
                se,
                4.0,
                &format!("single scattering, η = {eta}"),
            );
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_bits_whatever_the_threads() {
        let a = run(0.8, 0.2, 0.3, 1.3, 9_000);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = pool.install(|| run(0.8, 0.2, 0.3, 1.3, 9_000));
        assert_eq!(a, b);
    }

    #[test]
    fn white_walks_reweighted_give_the_absorbing_total() {
        // The white record reweighted by α′^events must agree with a direct absorbing run of
        // the same medium (independent photons): totals within 4 combined standard errors.
        // 5000 events: α′^5000 < 1e-40 for the albedos asked, so dropping walkers is harmless;
        // the heavy tail P(T > n) ∝ n^−½ drops a few % of them.
        let (exits, dropped) = white(1.3, 20_000, 3, 5_000, &Counter::none());
        assert!(dropped < 1_000, "{dropped}");
        for alpha in [0.5f64, 0.9, 0.98] {
            let w: Vec<f64> = exits.iter().map(|e| alpha.powi(e.1 as i32)).collect();
            let n = 20_000.0;
            let mean = w.iter().sum::<f64>() / n;
            let se_white = ((w.iter().map(|v| v * v).sum::<f64>() / n - mean * mean) / n).sqrt();
            let direct = trace(
                &Medium {
                    sigma_s: alpha,
                    sigma_a: 1.0 - alpha,
                    g: 0.0,
                    eta: 1.3,
                },
                &[0.0, 1.0],
                20_000,
                11,
                0,
                &Counter::none(),
            );
            let se = (se_white.powi(2) + direct.stderr().powi(2)).sqrt();
            within(mean, direct.total(), se, 4.0, "white vs direct");
        }
    }

    #[test]
    fn hg_sampling_has_mean_cosine_g() {
        // The mean cosine of Henyey–Greenstein is g; 1e5 stratified draws give it to ~1e-4.
        for g in [-0.7, 0.0, 0.3, 0.9] {
            let n = 100_000;
            let mean = (0..n)
                .map(|i| sample_hg(g, (i as f64 + 0.5) / n as f64))
                .sum::<f64>()
                / n as f64;
            assert!((mean - g).abs() < 1e-3, "g {g}: {mean}");
        }
        let d = rotate([0.0, 0.0, -1.0], 0.3, 1.0);
        assert!((d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - 1.0).abs() < 1e-12);
        assert!((-d[2] - 0.3).abs() < 1e-12);
    }
}
