"""The diffusion problem of the README's back-lit sphere, solved exactly, against the volumetric
truth and against `sss.render`, per band of n·l (the angle to the light).

A ball of radius 14 mm lit by a plane wave (intensity 5) from `l`: the fluence of the diffusion
approximation solves -D lap(phi) + sigma_a phi = Q inside, phi = 0 on the sphere z_b = 2D outside
(A = 1 at eta = 1). Axially symmetric about l, phi = sum_l f_l(r) P_l(cos theta): one radial
equation per Legendre order, finite volumes in r. The camera sees P1's radiance,
(phi + 3 J.w)/(4 pi), plus single scattering, taken from our render (its `single_scattering`
on minus off: traced through the mesh, exact at first order). Two source models:

  jensen  alpha' E per unit area one reduced mean free path under each entry point
          (`sss.render`'s `sources: point`; `geometry: body` solves its diffusion problem, see
          body.rs's tests)
  beam    where the light first scatters: sigma_s I exp(-sigma_t d) at depth d along the rays
          (`sources: beam` keeps only what collides again, moved to where it does: beam.rs)

    python sphere_diffusion.py PRESET TRUTH.npy OURS.npy OURS_WITHOUT_SINGLE.npy {jensen,beam}

The images come from (P = marble or skin1; the truth is `marble_truth.npy`, 2048 samples a
pixel: at 256 the ball's far side is black in a tenth of its pixels and its band sums move by
30% between seeds):

    mesoflow run graphs/sss_truth.json --device cpu --set torus.shape=sphere --set torus.size=0.7 \
        --set torus.segments=[96,48] --set marble_material.preset=P --set marble_truth.samples=2048 \
        --set marble_truth.seed=3 --output marble_npy.files --output marble_truth_npy.files \
        --out-dir OUT
    # and again with --set marble.single_scattering=false
"""
import sys

import numpy as np
from numpy.polynomial.legendre import leggauss
from scipy.linalg import solve_banded

PRESETS = {"marble": ([2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
           "skin1": ([0.74, 0.88, 1.01], [0.032, 0.17, 0.48])}
INTENSITY, RADIUS_MM, ORDERS, CELLS = 5.0, 14.0, 160, 3000
TO_LIGHT = np.array([0.5, 0.5, -1.0]) / np.linalg.norm([0.5, 0.5, -1.0])
EYE, TARGET, FOV, RADIUS_UNITS = np.array([0, 1.6, 2.9]), np.array([0, -0.1, 0]), 40.0, 0.7


def legendre(x, orders):
    p = np.zeros((orders + 1,) + np.shape(x))
    p[0] = 1
    p[1] = x
    for l in range(1, orders):
        p[l + 1] = ((2 * l + 1) * x * p[l] - l * p[l - 1]) / (l + 1)
    return p


def solve(sigma_s, sigma_a, sources):
    """f_l(R) and f_l'(R) for one channel."""
    sigma_t = sigma_s + sigma_a
    d = 1 / (3 * sigma_t)
    outer = RADIUS_MM + 2 * d
    dr = outer / CELLS
    r = (np.arange(CELLS) + 0.5) * dr
    mu, w = leggauss(600)
    weights = (2 * np.arange(ORDERS + 1) + 1) / 2
    if sources == "beam":
        rr, mm = r[:, None], mu[None, :]
        depth = -rr * mm + np.sqrt(np.maximum(rr * rr * (mm * mm - 1) + RADIUS_MM ** 2, 0))
        q = np.where(rr <= RADIUS_MM, sigma_s * INTENSITY * np.exp(-sigma_t * depth), 0.0)
    else:
        r0 = RADIUS_MM - 1 / sigma_t
        q = np.zeros((CELLS, mu.size))
        q[int(r0 / dr)] = (sigma_s / sigma_t) * INTENSITY * np.maximum(mu, 0) * (RADIUS_MM / r0) ** 2 / dr
    q_l = (q * w) @ legendre(mu, ORDERS).T * weights
    inner_face, outer_face = np.arange(CELLS) * dr, (np.arange(CELLS) + 1) * dr
    f = np.zeros((CELLS, ORDERS + 1))
    for l in range(ORDERS + 1):
        up, down = d * outer_face ** 2 / dr, d * inner_face ** 2 / dr
        diag = up + down + (d * l * (l + 1) / r ** 2 + sigma_a) * r * r * dr
        diag[-1] += d * outer ** 2 / (dr / 2) - up[-1]  # phi = 0 half a cell out
        bands = np.zeros((3, CELLS))
        bands[0, 1:], bands[1], bands[2, :-1] = -up[:-1], diag, -down[1:]
        f[:, l] = solve_banded((1, 1), bands, q_l[:, l] * r * r * dr)
    i = int(RADIUS_MM / dr - 0.5)
    t = (RADIUS_MM - r[i]) / dr
    return f[i] * (1 - t) + f[i + 1] * t, (f[i + 1] - f[i]) / dr, d


def main(preset, truth_path, ours_path, without_single_path, sources):
    truth = np.load(truth_path)[..., :3]
    ours, without = np.load(ours_path), np.load(without_single_path)
    h, w = truth.shape[:2]
    forward = (TARGET - EYE) / np.linalg.norm(TARGET - EYE)
    right = np.cross(forward, [0, 1, 0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan = np.tan(np.radians(FOV) / 2)
    ys, xs = np.mgrid[0:h, 0:w]
    ray = (forward + ((2 * (xs + 0.5) / w - 1) * tan * w / h)[..., None] * right
           + ((1 - 2 * (ys + 0.5) / h) * tan)[..., None] * up)
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    b = (ray * EYE).sum(-1)
    disc = b * b - (EYE @ EYE - RADIUS_UNITS ** 2)
    hit = disc > 0
    n = (EYE + (-b - np.sqrt(np.maximum(disc, 0)))[..., None] * ray) / RADIUS_UNITS
    view, nl = -ray, np.clip((n * TO_LIGHT).sum(-1), -1, 1)
    mu_o = (n * view).sum(-1)
    sin = np.sqrt(np.maximum(1 - nl * nl, 1e-12))
    tangent = (n * nl[..., None] - TO_LIGHT) / sin[..., None]  # towards increasing theta
    p = legendre(nl, ORDERS)
    dp = np.zeros_like(p)
    for l in range(1, ORDERS + 1):
        dp[l] = l * (nl * p[l] - p[l - 1]) / np.minimum(nl * nl - 1, -1e-12)
    diffusion = np.zeros(truth.shape)
    for c in range(3):
        f, df, d = solve(PRESETS[preset][0][c], PRESETS[preset][1][c], sources)
        phi = np.tensordot(f, p, 1)
        j_n = -d * np.tensordot(df, p, 1)
        j_t = -d * np.tensordot(f, dp, 1) * -sin / RADIUS_MM
        diffusion[..., c] = (phi + 3 * (j_n * mu_o + j_t * (view * tangent).sum(-1))) / (4 * np.pi)
    predicted = diffusion + (ours - without)
    # Pixels of the ball seen not too obliquely (the series is evaluated at the pixel's centre);
    # the object is where ours is lit, not where the truth is, whose black pixels are noise.
    mask = hit & (ours.sum(-1) > 0) & (mu_o > 0.25)
    print(f"{preset}, {sources} sources: the band's sum over the truth's, R G B")
    print("n·l band       pixels  exact diffusion       sss.render")
    edges = [-1, -0.8, -0.6, -0.4, -0.2, -0.1, 0, 0.1, 0.2, 0.4, 0.6, 0.8, 1]
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = mask & (nl >= lo) & (nl < hi)
        if m.sum() < 5:
            continue
        t = truth[m].sum(0)
        print(f"[{lo:+.1f}, {hi:+.1f})  {m.sum():5d}   "
              + " ".join(f"{x:.2f}" for x in predicted[m].sum(0) / t) + "    "
              + " ".join(f"{x:.2f}" for x in ours[m].sum(0) / t))


if __name__ == "__main__":
    main(*sys.argv[1:6])
