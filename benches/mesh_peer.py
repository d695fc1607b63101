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
"frames_s" (each), "triangles", "peak_rss_mib" (this process's maximum resident set after
those frames, before any truth below) and "variant".

With "instances" (a list of [x, y, z] offsets) the PLY is one tile, stored once in a
`shapegroup` and placed by one `instance` a offset (how brute force keeps a plane of repeated
tiles' memory flat; a curved surface's tiles differ, so it cannot).

With "truth_samples" S (a multiple of "samples") and "compare" ({name: {"image": (H, W, 3)
.npy, "mask": (H, W, 1) .npy}}, other renderers' images of the same view), it also renders
a converged truth (S samples a pixel, in passes of "samples" with seeds of their own, so that
the wavefront stays the size of a frame) and measures, over the pixels either image shows the
object in (the truth's alpha or the image's mask > 0.5), the relative RMSE (RMSE over the
truth's RMS, as `image.compare`) with the truth's own noise taken out:

- "noise": the relative RMSE of one of the timed frames (at "samples") against the truth, its
  share of the truth's noise removed (the two are independent: e² = n² (1 + s/S));
- per compared image: "rel" (its error against the truth, the truth's noise n·√(s/S) removed),
  "flip" (mean FLIP, HDR, against the truth, where flip_evaluator is installed), "equal_spp"
  (the samples a pixel at which Mitsuba's noise equals that error: s (n / rel)², at least 1),
  "equal_s" (the frame at those samples, interpolated between the 1-sample frame and the
  "samples" frame, beyond it in proportion) and "equal_ratio" (the image's own time, if given
  as "seconds", over "equal_s");
- "frame1_s": the median of "repeats" frames at one sample a pixel; "truth_s".
"""
import json
import math
import os
import resource
import sys
import time

import mitsuba as mi
import numpy as np

# The scene is the test peer's (tests/peers/mitsuba_reference.py), written once.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "peers"))
from mitsuba_reference import scene_of  # noqa: E402


def scene_dict(mi, cfg, pixel_format):
    """The test peer's scene (direct light; `path` to "max_depth" where given; an environment
    where the light is one), with the mesh instanced where "instances" asks."""
    d = scene_of(mi, cfg, pixel_format=pixel_format)
    offsets = cfg.get("instances")
    if offsets:
        tile = d.pop("shape")
        d["tile_group"] = {"type": "shapegroup", "tile": tile}
        for k, o in enumerate(offsets):
            d[f"tile_{k}"] = {"type": "instance", "shapegroup": {"type": "ref", "id": "tile_group"},
                              "to_world": mi.ScalarTransform4f().translate(o)}
    return d


def main(scene_path):
    cfg = json.load(open(scene_path))
    mi.set_variant(cfg.get("variant", "llvm_ad_rgb"))
    scene_dict_ = scene_dict(mi, cfg, pixel_format="rgb")
    t = time.perf_counter()
    scene = mi.load_dict(scene_dict_)
    load = time.perf_counter() - t

    last = {}

    def frame(seed, spp=cfg["samples"]):
        t = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=seed)
        # Evaluation is lazy in the LLVM variant: the frame is done once its pixels are read.
        last["image"] = mi.TensorXf(img).numpy()
        return time.perf_counter() - t

    first = frame(0)
    frames = [frame(k + 1) for k in range(cfg.get("repeats", 5))]
    # Instanced, the scene's shapes are the instances: the tile's triangles are counted by the caller.
    triangles = None if cfg.get("instances") else sum(s.face_count() for s in scene.shapes())
    result = {
        "variant": mi.variant(),
        "load_s": load,
        "first_s": first,
        "frame_s": sorted(frames)[len(frames) // 2],
        "frames_s": frames,
        "triangles": triangles,
    }
    # The render's peak, before the truth's passes and the comparisons add their own.
    result["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    if cfg.get("truth_samples") and cfg.get("compare") is not None:
        result.update(against_truth(mi, cfg, scene, frame, last["image"], result["frame_s"]))
    print(json.dumps(result))


def against_truth(mi, cfg, scene, frame, timed, frame_s):
    """The converged truth and every compared image's error and equal-error time (see above)."""
    s = cfg["samples"]
    passes = max(1, cfg["truth_samples"] // s)
    big = s * passes
    ones = sorted(frame(100 + k, spp=1) for k in range(cfg.get("repeats", 5)))
    frame1 = ones[len(ones) // 2]
    # The truth with alpha, for its mask: a scene of its own with an RGBA film.
    truth_dict = scene_dict(mi, cfg, pixel_format="rgba")
    truth_scene = mi.load_dict(truth_dict)
    t = time.perf_counter()
    acc = None
    for k in range(passes):
        img = mi.TensorXf(mi.render(truth_scene, spp=s, seed=10_000 + k)).numpy().astype(np.float64)
        acc = img if acc is None else acc + img
    truth = acc / passes
    truth_s = time.perf_counter() - t
    if cfg.get("truth_out"):
        np.save(cfg["truth_out"], truth.astype(np.float32))
    rgb, alpha = truth[..., :3], truth[..., 3]

    def rel(image, mask):
        m = mask | (alpha > 0.5)
        ref = rgb[m]
        rms = math.sqrt(float(np.mean(ref * ref)))
        if rms == 0.0:
            return None
        d = image.astype(np.float64)[m] - ref
        return math.sqrt(float(np.mean(d * d))) / rms

    e = rel(timed[..., :3], alpha > 0.5)
    noise = e / math.sqrt(1.0 + s / big) if e is not None else None
    truth_noise = noise * math.sqrt(s / big) if noise is not None else None

    def seconds_at(spp):
        if spp <= s:
            return frame1 + (frame_s - frame1) * (spp - 1) / max(s - 1, 1)
        return frame_s * spp / s

    try:
        import flip_evaluator as flip
    except ImportError:
        flip = None
    out = {"frame1_s": frame1, "truth_s": truth_s, "truth_samples": big, "noise": noise, "compared": {}}
    for name, c in cfg["compare"].items():
        image = np.load(c["image"])[..., :3]
        mask = np.load(c["mask"])[..., 0] > 0.5
        r = rel(image, mask)
        row = {}
        if r is not None and truth_noise is not None:
            r = math.sqrt(max(r * r - truth_noise * truth_noise, 0.0))
            row["rel"] = r
            if r > 0.0:
                spp = max(1.0, s * (noise / r) ** 2)
                row["equal_spp"] = spp
                row["equal_s"] = seconds_at(spp)
                if c.get("seconds") is not None:
                    row["equal_ratio"] = c["seconds"] / row["equal_s"]
        if flip is not None:
            _, mean, _ = flip.evaluate(rgb.astype(np.float32), image.astype(np.float32), "HDR",
                                       applyMagma=False)
            row["flip"] = float(mean)
        out["compared"][name] = row
    return out


if __name__ == "__main__":
    main(sys.argv[1])
