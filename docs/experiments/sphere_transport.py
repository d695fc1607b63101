"""Transport against diffusion on a back-lit ball, in exitance: no camera, no exit shape.

Monte Carlo transport written apart from mesoflow (isotropic scattering, index-matched boundary,
a plane wave of unit irradiance; lengths in mean free paths, sigma_t = 1) tallies the scattered
power leaving per unit area in bands of n.l. The diffusion problem of `sphere_diffusion.py` is
solved for the same medium with Jensen's sources and with the beam's, and P1's radiance leaving
its far pole face-on is printed too.

    python sphere_transport.py [RADIUS_MFP] [ALBEDO] [PHOTONS]
    # marble's red channel on the README's sphere: 30.66 0.99904 1000000 (about 30 s)

mesoflow's own reference at the far pole, face-on (multiply the P1 figures by the light's 5):

    mesoflow run docs/experiments/far_pole.json --output m_npy.files
"""
import importlib.util
import pathlib
import sys

import numpy as np

spec = importlib.util.spec_from_file_location(
    "sphere_diffusion", pathlib.Path(__file__).with_name("sphere_diffusion.py"))
series = importlib.util.module_from_spec(spec)
spec.loader.exec_module(series)

EDGES = np.linspace(-1, 1, 21)


def transport(radius, albedo, photons, rng):
    r = radius * np.sqrt(rng.random(photons))
    phi = 2 * np.pi * rng.random(photons)
    pos = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(radius ** 2 - r ** 2)], 1)
    dirs = np.tile([0.0, 0.0, -1.0], (photons, 1))  # the light comes from +z
    weight = np.ones(photons)
    alive = np.ones(photons, bool)
    scattered = np.zeros(photons, bool)
    bands = np.zeros(EDGES.size - 1)
    while alive.any():
        idx = np.flatnonzero(alive)
        step = -np.log(rng.random(idx.size))
        p, d = pos[idx], dirs[idx]
        b = (p * d).sum(1)
        to_exit = -b + np.sqrt(np.maximum(b * b - ((p * p).sum(1) - radius ** 2), 0))
        out = step >= to_exit
        left = idx[out]
        at = p[out] + to_exit[out, None] * d[out]
        nl = at[:, 2] / radius
        counted = scattered[left]
        w = weight[left] * counted
        bands += np.histogram(nl, EDGES, weights=w)[0]
        alive[left] = False
        stay = idx[~out]
        pos[stay] = p[~out] + step[~out, None] * d[~out]
        weight[stay] *= albedo
        scattered[stay] = True
        u = 2 * rng.random(stay.size) - 1
        a = 2 * np.pi * rng.random(stay.size)
        s = np.sqrt(1 - u * u)
        dirs[stay] = np.stack([s * np.cos(a), s * np.sin(a), u], 1)
        faint = alive & (weight < 1e-3)  # Russian roulette, unbiased
        killed = faint & (rng.random(photons) < 0.9)
        alive[killed] = False
        weight[faint & ~killed] *= 10
    per_photon = np.pi * radius ** 2 / photons  # incident power per photon
    return bands * per_photon / (2 * np.pi * radius ** 2 * np.diff(EDGES))


def main(radius=30.66, albedo=0.99904, photons=1000000):
    mc = transport(radius, albedo, photons, np.random.default_rng(2))
    centres = 0.5 * (EDGES[1:] + EDGES[:-1])
    series.RADIUS_MM, series.INTENSITY = radius, 1.0
    legendre = series.legendre(centres, series.ORDERS)
    at_pole = series.legendre(np.array([-1.0]), series.ORDERS)
    print(f"radius {radius} mean free paths, albedo {albedo}, {photons} photons")
    print("n.l     " + " ".join(f"{c:+.2f}" for c in centres))
    print("MC      " + " ".join(f"{v:.4f}" for v in mc))
    for sources in ("jensen", "beam"):
        f, df, d = series.solve(albedo, 1 - albedo, sources)
        j = -d * np.tensordot(df, legendre, 1)
        phi_pole = np.tensordot(f, at_pole, 1)[0]
        j_pole = -d * np.tensordot(df, at_pole, 1)[0]
        p1 = (phi_pole + 3 * j_pole) / (4 * np.pi)
        print(f"{sources:7s} " + " ".join(f"{v:.2f}  " for v in j / mc)
              + f"  (over MC); far pole face-on, P1: {p1:.6f} per unit irradiance")


if __name__ == "__main__":
    args = sys.argv[1:4]
    main(*(t(a) for t, a in zip((float, float, int), args)))
