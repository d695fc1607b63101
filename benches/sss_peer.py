"""Times Mitsuba 3's volumetric path tracer on a translucent scene as a user would run it: its
LLVM variant (`llvm_ad_rgb`, which needs Debian's `libllvm19`), the scene of
`tests/peers/mitsuba_reference.py` with a "medium" (index-matched boundary, homogeneous medium,
HG phase, `volpathmis` unless the medium names another integrator, no Russian roulette), and
measures its noise: two renders at `samples` a pixel with different seeds, the relative RMS of
their difference over √2 (over every pixel and channel, relative to their mean image's RMS), as
`render.reference` reports its own from two halves.

    python sss_peer.py SCENE.json

SCENE.json: as `mitsuba_reference.py`'s, plus "repeats" (renders timed after the first, default
2, each with its own seed) and "variant".

Prints one JSON line: "load_s", "first_s" (the first render: the JIT's compilation and one
frame), "frame_s" (the median of the timed renders), "noise" (of one render at `samples`),
"variant".
"""
import json
import os
import sys
import time

import mitsuba as mi
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "peers"))
from mitsuba_reference import scene_of  # noqa: E402


def main(scene_path):
    cfg = json.load(open(scene_path))
    mi.set_variant(cfg.get("variant", "llvm_ad_rgb"))
    t = time.perf_counter()
    scene = mi.load_dict(scene_of(mi, cfg, pixel_format="rgb"))
    load = time.perf_counter() - t

    def frame(seed):
        t = time.perf_counter()
        img = mi.render(scene, spp=cfg["samples"], seed=seed)
        # Evaluation is lazy in the LLVM variant: the frame is done once its pixels are read.
        values = np.array(mi.TensorXf(img).numpy(), dtype=np.float64)
        return time.perf_counter() - t, values

    first, _ = frame(0)
    runs = [frame(k + 1) for k in range(max(2, cfg.get("repeats", 2)))]
    a, b = runs[0][1], runs[1][1]
    mean = 0.5 * (a + b)
    noise = float(np.sqrt(np.sum((a - b) ** 2) / 4.0 / np.sum(mean ** 2)))
    times = sorted(r[0] for r in runs)
    print(json.dumps({
        "variant": mi.variant(),
        "load_s": load,
        "first_s": first,
        "frame_s": times[len(times) // 2],
        "noise": noise,
    }))


if __name__ == "__main__":
    main(sys.argv[1])
