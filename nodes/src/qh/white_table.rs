//! A scale-free Monte Carlo reflectance table, the forward model `qh.fit_dipole` uses with
//! `model: montecarlo`: one white Monte Carlo run (`sss::montecarlo::white`, unit σt, no
//! absorption, isotropic) tabulated by exit radius ρ in mean free paths and scattering count.
//! Any medium (σs′, σa) of the same η follows by similarity: with σt = σs′ + σa and
//! α′ = σs′/σt, Rd(r) = σt² R̂(σt r; α′) with R̂ = Σ α′^events per unit area — so the fit
//! compares like with like when the measurement itself comes from Monte Carlo or from a real
//! sample, instead of inheriting an analytic model's bias.

use crate::sss::montecarlo;
use std::f64::consts::PI;

/// Radius bins: [0, 1e-3) then log-spaced to 1e3 mean free paths.
const DECADES: (i32, i32) = (-3, 3);
const PER_DECADE: usize = 30;

pub struct WhiteTable {
    edges: Vec<f64>,
    /// ln of each bin's representative radius.
    ln_centres: Vec<f64>,
    /// Per bin: (events, photons) sorted by events.
    bins: Vec<Vec<(u32, u32)>>,
    /// All exits, for totals: (events, photons).
    all: Vec<(u32, u32)>,
    photons: u64,
    max_events: u32,
    /// Photons still walking after `max_events`, left out: at albedo α′ each would have
    /// carried at most α′^max_events.
    pub dropped: u64,
}

fn histogram(mut events: Vec<u32>) -> Vec<(u32, u32)> {
    events.sort_unstable();
    let mut out: Vec<(u32, u32)> = Vec::new();
    for e in events {
        match out.last_mut() {
            Some(last) if last.0 == e => last.1 += 1,
            _ => out.push((e, 1)),
        }
    }
    out
}

impl WhiteTable {
    /// One white Monte Carlo run; chunks are counted on `watch`, and a stopped watch leaves a
    /// partial table (the caller checks cancellation).
    pub fn build(
        eta: f64,
        photons: u64,
        seed: u64,
        max_events: u32,
        watch: &crate::support::progress::Counter,
    ) -> WhiteTable {
        let (exits, dropped) = montecarlo::white(eta, photons, seed, max_events, watch);
        let mut edges = vec![0.0];
        let steps = (DECADES.1 - DECADES.0) as usize * PER_DECADE;
        for k in 0..=steps {
            edges.push(10f64.powf(DECADES.0 as f64 + k as f64 / PER_DECADE as f64));
        }
        let nb = edges.len() - 1;
        let mut per_bin: Vec<Vec<u32>> = vec![Vec::new(); nb];
        for &(r, e) in &exits {
            let i = edges
                .partition_point(|&x| x <= r)
                .saturating_sub(1)
                .min(nb - 1);
            per_bin[i].push(e);
        }
        let ln_centres = (0..nb)
            .map(|i| {
                if i == 0 {
                    (0.5 * edges[1]).ln()
                } else {
                    (edges[i] * edges[i + 1]).sqrt().ln()
                }
            })
            .collect();
        WhiteTable {
            ln_centres,
            bins: per_bin.into_iter().map(histogram).collect(),
            all: histogram(exits.iter().map(|e| e.1).collect()),
            edges,
            photons,
            max_events,
            dropped,
        }
    }

    fn powers(&self, alpha: f64) -> Vec<f64> {
        let mut p = Vec::with_capacity(self.max_events as usize + 1);
        let mut v = 1.0;
        for _ in 0..=self.max_events {
            p.push(v);
            v *= alpha;
        }
        p
    }

    /// Total diffuse reflectance at albedo α′.
    pub fn total(&self, alpha: f64) -> f64 {
        let p = self.powers(alpha);
        self.all
            .iter()
            .map(|&(e, n)| n as f64 * p[e as usize])
            .sum::<f64>()
            / self.photons as f64
    }

    /// R̂(ρ) at albedo α′ for each ρ (mean free paths): per-bin estimates, interpolated
    /// linearly in (ln ρ, ln R̂) between the bins that received light, held at the ends.
    pub fn profile(&self, alpha: f64, rho: &[f64]) -> Vec<f64> {
        let p = self.powers(alpha);
        let known: Vec<(f64, f64)> = self
            .bins
            .iter()
            .enumerate()
            .filter_map(|(i, b)| {
                let w: f64 = b.iter().map(|&(e, n)| n as f64 * p[e as usize]).sum();
                let area = PI * (self.edges[i + 1].powi(2) - self.edges[i].powi(2));
                // Tiny weights can underflow to 0 per unit area: keep finite logarithms only.
                let v = (w / (self.photons as f64 * area)).ln();
                v.is_finite().then_some((self.ln_centres[i], v))
            })
            .collect();
        rho.iter()
            .map(|&r| {
                let x = r.max(1e-300).ln();
                let k = known.partition_point(|e| e.0 <= x);
                let v = match k {
                    0 => known.first().map_or(f64::NEG_INFINITY, |e| e.1),
                    k if k == known.len() => known[k - 1].1,
                    k => {
                        let (a, b) = (known[k - 1], known[k]);
                        a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
                    }
                };
                v.exp()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_integrates_to_its_total() {
        // ∫ R̂ 2πρ dρ over the bins equals the total up to the interpolation's error between
        // bin centres (the bins are 8% wide; 2% bound), at two albedos.
        let t = WhiteTable::build(
            1.3,
            20_000,
            5,
            4_000,
            &crate::support::progress::Counter::none(),
        );
        for alpha in [0.8, 0.97] {
            let mut integral = 0.0;
            let n = 4000;
            let (lo, hi) = (1e-3f64.ln(), 1e3f64.ln());
            let rho: Vec<f64> = (0..n)
                .map(|i| (lo + (hi - lo) * (i as f64 + 0.5) / n as f64).exp())
                .collect();
            let v = t.profile(alpha, &rho);
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                panic!("ρ {} gives {}", rho[i], v[i]);
            }
            for (r, f) in rho.iter().zip(&v) {
                integral += f * 2.0 * PI * r * r * (hi - lo) / n as f64;
            }
            let total = t.total(alpha);
            assert!(
                (integral / total - 1.0).abs() < 0.02,
                "α′ {alpha}: {integral} vs {total}"
            );
        }
    }
}
