"""Times Mitsuba 3 path-tracing a mesh's true geometry as a user would run it: its LLVM variant
(`llvm_ad_rgb`, which needs Debian's `libllvm19`), a pinhole camera (vertical fov), one
directional light, a diffuse BSDF, direct illumination only (`direct`: one emitter sample a
sample, as `btf.capture` captures light), a box filter. The scene as `render.mesh` draws it, in
brute force: the cost of a frame does not depend on the reflectance model much, so a diffuse
BSDF stands in for the capture's lobe (the times compare; the images are not compared here).

    python mesh_peer.py SCENE.json

SCENE.json: {"mesh": PLY path, "camera": {eye, target, up, fov, resolution: [w, h]},
"light": {direction (towards the light), intensity}, "albedo": [r, g, b], "samples": N,
"repeats": R, "variant": "llvm_ad_rgb"}.

Prints one JSON line: "load_s" (reading the PLY and building the scene, its BVH included),
"first_s" (the first render: the JIT's compilation and one frame), "frame_s" (the median of
`repeats` renders after it: the frame a user waits for when the scene is loaded),
"frames_s" (each), "triangles", "peak_rss_mib" (this process's maximum resident set) and
"variant".
"""
import json
import os
import resource
import sys
import time

import mitsuba as mi

# The scene is the test peer's (tests/peers/mitsuba_reference.py), written once.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "peers"))
from mitsuba_reference import direct_scene  # noqa: E402


def main(scene_path):
    cfg = json.load(open(scene_path))
    mi.set_variant(cfg.get("variant", "llvm_ad_rgb"))
    scene_dict = direct_scene(mi, cfg, pixel_format="rgb")
    t = time.perf_counter()
    scene = mi.load_dict(scene_dict)
    load = time.perf_counter() - t

    def frame(seed):
        t = time.perf_counter()
        img = mi.render(scene, spp=cfg["samples"], seed=seed)
        # Evaluation is lazy in the LLVM variant: the frame is done once its pixels are read.
        mi.TensorXf(img).numpy()
        return time.perf_counter() - t

    first = frame(0)
    frames = [frame(k + 1) for k in range(cfg.get("repeats", 5))]
    triangles = sum(s.face_count() for s in scene.shapes())
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps({
        "variant": mi.variant(),
        "load_s": load,
        "first_s": first,
        "frame_s": sorted(frames)[len(frames) // 2],
        "frames_s": frames,
        "triangles": triangles,
        "peak_rss_mib": rss,
    }))


if __name__ == "__main__":
    main(sys.argv[1])
