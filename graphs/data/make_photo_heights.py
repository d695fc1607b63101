"""Makes the photo-derived height fields in graphs/data: gravel.png (graphs/btf_edit.json's, and
the mesostructure scene family's), brick.png and grass.png (the family's).

Source: scikit-image's `data.gravel()` (CC0Textures' Gravel04), `data.brick()` and `data.grass()`
(both from CC0Textures too; Creative Commons CC0). Each 512² photograph is box-averaged 2× to
256² and blurred (Gaussian, σ = 1.5 texels: brightness noise is not relief), its top-left 32²
is mirrored into a 64² tile (so opposite edges match, as a tiled mesostructure must) and
brightness is taken as height: a 16-bit grey PNG, 0 to 1, that `heightfield.read` scales by its
`depth`. Run with the peer venv:
target/peer-venv/bin/python graphs/data/make_photo_heights.py
"""
import numpy as np
import imageio.v3 as iio
from skimage import data, filters

for name in ["gravel", "brick", "grass"]:
    photo = getattr(data, name)().astype(np.float64) / 255.0
    small = photo.reshape(256, 2, 256, 2).mean(axis=(1, 3))
    crop = filters.gaussian(small, sigma=1.5)[:32, :32]
    tile = np.block([[crop, crop[:, ::-1]], [crop[::-1, :], crop[::-1, ::-1]]])
    tile = (tile - tile.min()) / (tile.max() - tile.min())
    iio.imwrite(f"graphs/data/{name}.png", np.round(tile * 65535).astype(np.uint16))
