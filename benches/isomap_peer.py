#!/usr/bin/env python3
"""scikit-learn's Isomap on an NPY point set, the peer of `manifold.isomap` in BENCHMARKS.md.

    python3 benches/isomap_peer.py points.npy --k 10 --components 2 --out sklearn_embedding.npy

Times `Isomap(n_neighbors=k, n_components=c).fit_transform(X)` (best of --repeat runs, after
one warm-up) and writes the embedding as (n, c) f64 so the bench can compare it by Procrustes.
"""

import argparse
import time

import numpy as np
from sklearn.manifold import Isomap


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("points")
    ap.add_argument("--k", type=int, default=10)
    ap.add_argument("--components", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    x = np.load(a.points)
    best = float("inf")
    y = None
    for _ in range(a.repeat):
        start = time.perf_counter()
        model = Isomap(n_neighbors=a.k, n_components=a.components)
        y = model.fit_transform(x)
        best = min(best, time.perf_counter() - start)
    if a.out:
        np.save(a.out, np.ascontiguousarray(y, dtype=np.float64))
    print(f"sklearn: {x.shape[0]} points in {best:.3f} s; reconstruction_error {model.reconstruction_error():.6e}")


if __name__ == "__main__":
    main()
