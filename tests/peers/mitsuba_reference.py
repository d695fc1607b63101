"""Renders a mesh with Mitsuba 3 (scalar_rgb) as mesoflow's `render.reference` does: a pinhole
camera (vertical fov), one directional light, a diffuse BSDF, direct illumination only, a box
pixel filter; writes the RGBA image (alpha: the fraction of each pixel's samples that hit) as a
float32 .npy of shape (height, width, 4).

    python mitsuba_reference.py SCENE.json OUT.npy

SCENE.json: {"mesh": PLY path, "camera": {eye, target, up, fov, resolution: [w, h]},
"light": {direction (towards the light), intensity}, "albedo": [r, g, b], "samples": N}.
"""
import json
import sys

import mitsuba as mi
import numpy as np


def main(scene_path, out_path):
    mi.set_variant("scalar_rgb")
    cfg = json.load(open(scene_path))
    cam, light = cfg["camera"], cfg["light"]
    width, height = cam["resolution"]
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "perspective",
            "fov": cam["fov"],
            "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=cam["eye"], target=cam["target"], up=cam["up"]),
            "film": {
                "type": "hdrfilm", "width": width, "height": height,
                "pixel_format": "rgba", "rfilter": {"type": "box"},
            },
            "sampler": {"type": "independent", "sample_count": cfg["samples"], "seed": 7},
        },
        # Mitsuba's direction is the one the light travels in.
        "light": {
            "type": "directional",
            "direction": [-d for d in light["direction"]],
            "irradiance": {"type": "rgb", "value": [light["intensity"]] * 3},
        },
        "shape": {
            "type": "ply", "filename": cfg["mesh"],
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": cfg["albedo"]}},
        },
    })
    image = np.array(mi.render(scene), dtype=np.float32)
    np.save(out_path, image)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
