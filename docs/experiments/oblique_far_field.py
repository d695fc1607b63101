"""How far light entering a half-space at an angle travels, by Monte Carlo transport (independent
of mesoflow): isotropic scattering, sigma_t = 1 (lengths in mean free paths), index-matched
boundary, a thin beam entering at the origin with direction cosine mu0. Prints the scattered power
leaving through each annulus around the entry point, per unit incident power, and its ratio to
normal incidence.

A diffusion source at a fixed depth under the entry point (Jensen et al. 2001; `sss.render`'s
`sources: point`) gives every mu0 the same far field per unit power: ratio 1 in the outer
annuli. Transport says otherwise (by reciprocity the far field goes as Chandrasekhar's H(mu0)).
The last table is what `sources: beam` is held to (`nodes/src/sss/render/beam.rs`'s tests):
how the multiply scattered light alone (two events or more) spreads, as a share of its own
total, over normal incidence's.

    python oblique_far_field.py [ALBEDO] [PHOTONS]     # 0.99 and 200000: about 25 s
"""
import sys

import numpy as np

EDGES = np.array([0, 0.5, 1, 2, 3, 5, 8, 12, 20])
INCIDENCES = [1.0, 0.7, 0.4, 0.2, 0.1, 0.05]


def exitance(mu0, albedo, photons, rng):
    pos = np.zeros((photons, 3))
    dirs = np.tile([np.sqrt(1 - mu0 * mu0), 0.0, -mu0], (photons, 1))
    weight = np.ones(photons)
    alive = np.ones(photons, bool)
    tally = np.zeros(EDGES.size - 1)
    multiple = np.zeros(EDGES.size - 1)
    for event in range(5000):
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        step = -np.log(rng.random(idx.size))
        moved = pos[idx] + step[:, None] * dirs[idx]
        out = moved[:, 2] > 0
        left = idx[out]
        t = -pos[left, 2] / dirs[left, 2]
        at = pos[left] + t[:, None] * dirs[left]
        if event > 0:  # scattered light only: the unscattered beam does not leave
            counts = np.histogram(np.hypot(at[:, 0], at[:, 1]), EDGES, weights=weight[left])[0]
            tally += counts
            if event > 1:
                multiple += counts
        alive[left] = False
        stay = idx[~out]
        pos[stay] = moved[~out]
        weight[stay] *= albedo
        u = 2 * rng.random(stay.size) - 1
        phi = 2 * np.pi * rng.random(stay.size)
        s = np.sqrt(1 - u * u)
        dirs[stay] = np.stack([s * np.cos(phi), s * np.sin(phi), u], 1)
        # Russian roulette on faint photons keeps the estimate unbiased.
        faint = alive & (weight < 1e-3)
        killed = faint & (rng.random(photons) < 0.9)
        alive[killed] = False
        weight[faint & ~killed] *= 10
    return tally / photons, multiple / photons


def main(albedo=0.99, photons=200000):
    rng = np.random.default_rng(1)
    both = {mu0: exitance(mu0, albedo, photons, rng) for mu0 in INCIDENCES}
    results = {mu0: b[0] for mu0, b in both.items()}
    bands = " ".join(f"{a:g}-{b:g}" for a, b in zip(EDGES[:-1], EDGES[1:]))
    print(f"albedo {albedo}, {photons} photons; annuli (mean free paths): {bands}")
    for mu0, r in results.items():
        print(f"mu0 {mu0:4}: " + " ".join(f"{x:.4f}" for x in r) + f"  total {r.sum():.4f}")
    print("over normal incidence:")
    for mu0, r in results.items():
        print(f"mu0 {mu0:4}: " + " ".join(f"{x:.3f}" for x in r / results[1.0]))
    # What `sources: beam` models: where the multiply scattered light leaves (the profile sets
    # how much; single scattering is rendered apart).
    share = {mu0: b[1] / b[1].sum() for mu0, b in both.items()}
    print("multiply scattered light (two events or more), each annulus's share of it, "
          "over normal incidence's share:")
    for mu0, r in share.items():
        print(f"mu0 {mu0:4}: " + " ".join(f"{x:.3f}" for x in r / share[1.0])
              + f"  total {both[mu0][1].sum():.4f}")


if __name__ == "__main__":
    main(*(float(a) if i == 0 else int(a) for i, a in enumerate(sys.argv[1:3])))
