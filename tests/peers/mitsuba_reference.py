"""Renders a mesh with Mitsuba 3 (scalar_rgb) as mesoflow's `render.reference` does: a pinhole
camera (vertical fov), one directional light, a diffuse BSDF, direct illumination only, a box
pixel filter; writes the RGBA image (alpha: the fraction of each pixel's samples that hit) as a
float32 .npy of shape (height, width, 4).

With a "medium" ({"sigma_t": [r, g, b], "albedo": [r, g, b], "g": g}, world units) the mesh is
instead the index-matched boundary (a `null` BSDF) of that homogeneous medium with a
Henyey-Greenstein phase function, rendered by `volpath` (or the medium's "integrator", e.g.
`volpathmis`: spectral MIS, far less colour noise) with no depth limit: mesoflow's
volumetric reference. With "eta" and "alpha" in the medium the boundary is instead a rough
dielectric (`roughdielectric`, GGX, interior index eta, exterior 1) on the triangles' own
normals (`face_normals`), as mesoflow's reference refracts.

    python mitsuba_reference.py SCENE.json OUT.npy

SCENE.json: {"mesh": PLY path, "camera": {eye, target, up, fov, resolution: [w, h]}, "seed" (7),
"light": {direction (towards the light), intensity}, "albedo": [r, g, b], "samples": N}, and
optionally "max_depth" (path tracing with interreflections instead of direct light) and
"orthographic" in the camera (half the view's height; a square image). A light of
{"envmap": EXR path, "rotation": degrees} is instead an environment in mesoflow's lat-long
convention (its intensity already in the texels, as `export.mitsuba` writes them), hidden from
the camera as mesoflow's background is not the environment.
"""
import math
import json
import sys

import mitsuba as mi
import numpy as np


def direct_scene(mi, cfg, pixel_format="rgba"):
    """The scene dict both peers start from: pinhole camera (vertical fov), one directional
    light, the PLY with a diffuse BSDF, direct illumination only, a box filter. `mi` has its
    variant set; `benches/mesh_peer.py` times the same scene."""
    cam, light = cfg["camera"], cfg["light"]
    width, height = cam["resolution"]
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "perspective",
            "fov": cam.get("fov", 40.0),
            "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=cam["eye"], target=cam["target"], up=cam.get("up", [0, 1, 0])),
            "film": {
                "type": "hdrfilm", "width": width, "height": height,
                "pixel_format": pixel_format, "rfilter": {"type": "box"},
            },
            "sampler": {"type": "independent", "sample_count": cfg["samples"], "seed": cfg.get("seed", 7)},
        },
        # Mitsuba's direction is the one the light travels in.
        "light": emitter(mi, light),
        "shape": {
            "type": "ply", "filename": cfg["mesh"],
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": cfg["albedo"]}},
        },
    }


def emitter(mi, light):
    """A directional light, or an environment turned onto mesoflow's convention as
    `export.mitsuba` turns it: Mitsuba's local (x, y, z) is mesoflow's (-z, x, y), then the
    light's rotation about +z."""
    if "envmap" not in light:
        return {
            "type": "directional",
            "direction": [-d for d in light["direction"]],
            "irradiance": {"type": "rgb", "value": [light["intensity"]] * 3},
        }
    r = math.radians(light.get("rotation", 0.0))
    c, s = math.cos(r), math.sin(r)
    m = [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    rz = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    t = [[sum(rz[a][k] * m[k][b] for k in range(3)) for b in range(3)] for a in range(3)]
    matrix = [t[0] + [0.0], t[1] + [0.0], t[2] + [0.0], [0.0, 0.0, 0.0, 1.0]]
    return {"type": "envmap", "filename": light["envmap"], "to_world": mi.ScalarTransform4f(matrix)}


def scene_of(mi, cfg, pixel_format="rgba"):
    """The scene dict of `cfg`: `direct_scene`, or with a "medium" the volumetric one.
    `benches/sss_peer.py` times the same scene."""
    scene_dict = direct_scene(mi, cfg, pixel_format)
    if "max_depth" in cfg:
        # Interreflections: path tracing to that depth (Mitsuba counts the camera segment and
        # the direct bounce: N bounces after the direct one are max_depth N + 2), no Russian
        # roulette, so each path runs to its depth as mesoflow's do.
        scene_dict["integrator"] = {"type": "path", "max_depth": cfg["max_depth"],
                                    "rr_depth": 1 << 30}
    if cam_ortho := cfg["camera"].get("orthographic"):
        # Mitsuba's orthographic view spans [-1, 1] on both axes of a square image before its
        # to_world: scaled to mesoflow's half-height.
        cam = cfg["camera"]
        sensor = scene_dict["sensor"]
        sensor["type"] = "orthographic"
        del sensor["fov"], sensor["fov_axis"]
        sensor["to_world"] = mi.ScalarTransform4f().look_at(
            origin=cam["eye"], target=cam["target"], up=cam.get("up", [0, 1, 0])) \
            @ mi.ScalarTransform4f().scale([cam_ortho, cam_ortho, 1.0])
    medium = cfg.get("medium")
    if medium is not None:
        # Russian roulette past the fifth event, volpath's default, stops a path with
        # probability 5% per event even where nothing is absorbed (its survival probability is
        # capped at 0.95): paths of hundreds of events through marble then carry weights of 10⁹,
        # the image is fireflies. Without it, paths end when they leave or are absorbed.
        scene_dict["integrator"] = {"type": medium.get("integrator", "volpath"), "max_depth": -1,
                                    "rr_depth": 1 << 30}
        if "eta" in medium:
            scene_dict["shape"]["bsdf"] = {"type": "roughdielectric", "distribution": "ggx",
                                           "alpha": medium["alpha"], "int_ior": medium["eta"],
                                           "ext_ior": 1.0}
            scene_dict["shape"]["face_normals"] = True
        else:
            scene_dict["shape"]["bsdf"] = {"type": "null"}
        # An RGB value must lie in [0, 1]: the extinction is given as a colour times a scale.
        scale = max(medium["sigma_t"])
        scene_dict["shape"]["interior"] = {
            "type": "homogeneous",
            "scale": scale,
            "sigma_t": {"type": "rgb", "value": [s / scale for s in medium["sigma_t"]]},
            "albedo": {"type": "rgb", "value": medium["albedo"]},
            "phase": {"type": "hg", "g": medium["g"]},
        }
    if "envmap" in cfg["light"]:
        # As mesoflow's reference: the environment lights the scene and is not seen.
        scene_dict["integrator"]["hide_emitters"] = True
    return scene_dict


def main(scene_path, out_path):
    mi.set_variant("scalar_rgb")
    cfg = json.load(open(scene_path))
    scene_dict = scene_of(mi, cfg)
    scene = mi.load_dict(scene_dict)
    image = np.array(mi.render(scene), dtype=np.float32)
    np.save(out_path, image)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
