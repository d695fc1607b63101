"""Renders Mitsuba 3 scene files as a user would open them (`mi.load_file`), for the tests of
mesoflow's `export.mitsuba`: each job's scene with its `spp` and `seed` defaults overridden,
the RGBA image saved as a float32 .npy of shape (height, width, 4).

    python mitsuba_file.py JOBS.json

JOBS.json: [{"scene": XML path, "out": .npy path, "spp": N, "seed": S, "variant": "scalar_rgb"}].
"""
import json
import sys

import mitsuba as mi
import numpy as np


def main(jobs_path):
    for job in json.load(open(jobs_path)):
        mi.set_variant(job.get("variant", "scalar_rgb"))
        scene = mi.load_file(job["scene"], spp=job["spp"], seed=job["seed"])
        np.save(job["out"], np.array(mi.render(scene), dtype=np.float32))


if __name__ == "__main__":
    main(sys.argv[1])
