#!/usr/bin/env python3
"""The numpy peer of sss.profile's Monte Carlo reference, for BENCHMARKS.md.

The same experiment, written independently and vectorised over photons: a pencil beam already
refracted at normal incidence into a semi-infinite medium (Rd per unit transmitted flux),
Henyey-Greenstein scattering, the exact Fresnel reflectance of a smooth boundary seen from
inside, absorption carried as weight with Russian roulette below 1e-4 (survival 0.1), photons
given up after 10^6 events. Prints photons per second and the total diffuse reflectance with its
standard error, so the two implementations can be checked against each other (same answer within
Monte Carlo error) as well as timed.

    python3 benches/sss_montecarlo.py --sigma-s 2.19 --sigma-a 0.0021 --eta 1.3 --photons 200000
"""

import argparse
import time

import numpy as np


def fresnel_inside(cos_i, eta):
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin_t2 = eta * eta * (1.0 - cos_i * cos_i)
    tir = sin_t2 >= 1.0
    cos_t = np.sqrt(np.clip(1.0 - sin_t2, 0.0, 1.0))
    rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp))


def sample_hg(g, u):
    if abs(g) < 1e-6:
        return 2.0 * u - 1.0
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


def rotate(d, cos, phi):
    """Turns unit vectors d (n, 3) by polar cosine `cos` and azimuth `phi`."""
    sin = np.sqrt(np.clip(1.0 - cos * cos, 0.0, 1.0))
    sign = np.where(d[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + d[:, 2])
    b = d[:, 0] * d[:, 1] * a
    t = np.stack([1.0 + sign * d[:, 0] ** 2 * a, sign * b, -sign * d[:, 0]], axis=1)
    s = np.stack([b, sign + d[:, 1] ** 2 * a, -d[:, 1]], axis=1)
    c, si = (np.cos(phi) * sin)[:, None], (np.sin(phi) * sin)[:, None]
    return c * t + si * s + cos[:, None] * d


def trace(sigma_s, sigma_a, g, eta, photons, seed):
    rng = np.random.default_rng(seed)
    sigma_t = sigma_s + sigma_a
    albedo = sigma_s / sigma_t
    p = np.zeros((photons, 3))
    d = np.tile([0.0, 0.0, 1.0], (photons, 1))
    w = np.ones(photons)
    events = np.zeros(photons, dtype=np.int64)
    alive = np.arange(photons)
    reflected = np.zeros(photons)
    total_events = 0
    while alive.size:
        s = -np.log1p(-rng.random(alive.size)) / sigma_t
        z_new = p[alive, 2] + s * d[alive, 2]
        cross = z_new < 0.0
        # Photons reaching the boundary: Fresnel test, then reflect or leave.
        idx = alive[cross]
        if idx.size:
            to = -p[idx, 2] / d[idx, 2]
            p[idx, 0] += to * d[idx, 0]
            p[idx, 1] += to * d[idx, 1]
            p[idx, 2] = 0.0
            refl = rng.random(idx.size) < fresnel_inside(-d[idx, 2], eta)
            d[idx[refl], 2] *= -1.0
            out = idx[~refl]
            reflected[out] = w[out]
        # The others scatter.
        sc = alive[~cross]
        p[sc] += s[~cross, None] * d[sc]
        events[sc] += 1
        total_events += sc.size
        w[sc] *= albedo
        low = sc[w[sc] < 1e-4]
        survive = rng.random(low.size) < 0.1
        w[low[survive]] /= 0.1
        dead = np.zeros(photons, dtype=bool)
        dead[low[~survive]] = True
        dead[sc[events[sc] >= 1_000_000]] = True
        keep = sc[~dead[sc]]
        if keep.size:
            cos = sample_hg(g, rng.random(keep.size))
            d[keep] = rotate(d[keep], cos, 2.0 * np.pi * rng.random(keep.size))
        left = idx[refl] if idx.size else idx
        alive = np.concatenate([left, keep])
    mean = reflected.mean()
    se = reflected.std(ddof=1) / np.sqrt(photons)
    return mean, se, total_events


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sigma-s", type=float, default=2.19)
    ap.add_argument("--sigma-a", type=float, default=0.0021)
    ap.add_argument("--g", type=float, default=0.0)
    ap.add_argument("--eta", type=float, default=1.3)
    ap.add_argument("--photons", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    start = time.perf_counter()
    total, se, events = trace(a.sigma_s, a.sigma_a, a.g, a.eta, a.photons, a.seed)
    seconds = time.perf_counter() - start
    print(
        f"numpy: {a.photons} photons in {seconds:.3f} s = {a.photons / seconds:.0f} photons/s "
        f"({events / seconds:.3g} events/s); total Rd {total:.5f} ± {se:.5f}"
    )


if __name__ == "__main__":
    main()
