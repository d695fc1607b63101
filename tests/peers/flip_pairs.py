"""Image pairs and NVIDIA's FLIP results for them, for tests/flip_peer.rs.

Usage: python flip_pairs.py OUT_DIR RENDER.npy [RENDER.npy ...]

Builds LDR pairs from scikit-image's photographs (blur, noise, a shift, colour changes, banding,
brightness, two viewing conditions) and HDR pairs from mesoflow renders (the linear (H, W, 3)
float32 arrays given) and from a photograph lifted to HDR with a bright source. Each pair is
written as OUT_DIR/NN_reference.npy and NN_test.npy (LDR ones sRGB-encoded in [0, 1], HDR ones
linear) and scored with the `flip-evaluator` package (NVIDIA's implementation); OUT_DIR/pairs.json
lists the pairs with their mode, pixels per degree, mean and 95th percentile.
"""

import json
import sys
from pathlib import Path

import flip_evaluator as flip
import numpy as np
from scipy.ndimage import gaussian_filter
from skimage import data

out = Path(sys.argv[1])
renders = [np.load(p).astype(np.float32) for p in sys.argv[2:]]
out.mkdir(parents=True, exist_ok=True)
rng = np.random.default_rng(20261130)


def crop(img, size=192):
    """A centred square, RGB float in [0, 1] (grey photographs are replicated)."""
    img = np.asarray(img, dtype=np.float32) / 255.0
    if img.ndim == 2:
        img = np.stack([img] * 3, axis=-1)
    h, w = img.shape[:2]
    y, x = (h - size) // 2, (w - size) // 2
    return np.ascontiguousarray(img[y : y + size, x : x + size, :3])


def blur(img, sigma):
    return gaussian_filter(img, sigma=(sigma, sigma, 0), mode="nearest")


astronaut = crop(data.astronaut())
coffee = crop(data.coffee())
chelsea = crop(data.chelsea())
rocket = crop(data.rocket())
camera = crop(data.camera())
cells = crop(data.immunohistochemistry())

ldr = [
    ("astronaut_blur", astronaut, blur(astronaut, 1.5), {}),
    ("coffee_noise", coffee, np.clip(coffee + rng.normal(0, 0.03, coffee.shape), 0, 1), {}),
    ("chelsea_shift", chelsea, np.roll(chelsea, 1, axis=1), {}),
    ("rocket_tint", rocket, np.clip(rocket * np.array([1.12, 1.0, 0.9]), 0, 1), {}),
    ("camera_banding", camera, np.round(camera * 15) / 15, {}),
    ("cells_brighter", cells, np.clip(cells + 0.05, 0, 1), {}),
    ("coffee_blur_far", coffee, blur(coffee, 1.0), {"ppd": 30.0}),
    ("chelsea_noise_viewer", chelsea, np.clip(chelsea + rng.normal(0, 0.05, chelsea.shape), 0, 1),
     {"vc": [0.6, 192, 0.05]}),
]

# HDR: a photograph in linear light with a bright window and a small very bright source.
lin = np.where(astronaut <= 0.04045, astronaut / 12.92, ((astronaut + 0.055) / 1.055) ** 2.4)
bright = lin * 2.0
bright[20:40, 130:170] *= 8.0
bright[60:64, 60:64] = 200.0
dimmer = bright.copy()
dimmer[60:64, 60:64] = 150.0
hdr = [
    ("hdr_bright_source", bright, blur(dimmer, 0.7), {}),
    ("hdr_exposure", bright, bright * 1.25, {}),
]
for i, r in enumerate(renders):
    hdr.append((f"render{i}_blur", r, blur(r, 1.0), {}))
    hdr.append((f"render{i}_noise", r, np.clip(r + rng.normal(0, 0.02, r.shape) * r.mean(), 0, None), {}))
for i in range(len(renders) - 1):
    hdr.append((f"render{i}_vs_render{i + 1}", renders[i], renders[i + 1], {}))

listing = []
pairs = [(*x, "LDR") for x in ldr] + [(*x, "HDR") for x in hdr]
for k, (name, ref, test, params, mode) in enumerate(pairs):
    ref = np.ascontiguousarray(ref, dtype=np.float32)
    test = np.ascontiguousarray(test, dtype=np.float32)
    error_map, mean, used = flip.evaluate(ref, test, mode, applyMagma=False, parameters=dict(params))
    error_map = np.asarray(error_map, dtype=np.float64).reshape(ref.shape[:2])
    np.save(out / f"{k:02}_reference.npy", ref)
    np.save(out / f"{k:02}_test.npy", test)
    listing.append(
        {
            "name": name,
            "mode": mode.lower(),
            "ppd": float(used["ppd"]),
            "mean": float(mean),
            "p95": float(np.percentile(error_map, 95)),
            "exposures": [float(used["startExposure"]), float(used["stopExposure"]), int(used["numExposures"])]
            if mode == "HDR"
            else None,
        }
    )
(out / "pairs.json").write_text(json.dumps(listing, indent=1))
print(f"{len(listing)} pairs written to {out}")
