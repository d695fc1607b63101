"""Peer for `cargo bench --bench btf_pca`: scikit-learn's randomized_svd on the same BTF matrix.

Usage (needs numpy and scikit-learn: `pip install numpy scikit-learn`):
    cargo bench --bench btf_pca -- --res 128 --npy /tmp/btf.npy
    python3 benches/peer_randomized_svd.py /tmp/btf.npy --rank 16

The NPY holds the BTF as shape (C, T) float32 (columns = direction pairs x RGB, T texels), so
X = load(...).T is mesoflow's texels x columns matrix. Like `btf.pca` (layout texels), the column
means are removed first (not timed). RMSE is computed the way mesoflow computes it, from the
projection onto the returned basis: sqrt((||X||^2 - ||X V||^2) / N), accumulated in float64.
"""
import argparse
import time

import numpy as np
from sklearn.utils.extmath import randomized_svd
from threadpoolctl import threadpool_info

ap = argparse.ArgumentParser()
ap.add_argument("npy")
ap.add_argument("--rank", type=int, default=16)
ap.add_argument("--oversamples", type=int, default=10)
args = ap.parse_args()

X = np.load(args.npy).T  # (T, C), a Fortran-ordered view: columns contiguous, like mesoflow's
X = X - X.mean(axis=0, dtype=np.float64).astype(np.float32)
N = X.size
energy = float(np.einsum("ij,ij->", X, X, dtype=np.float64))
blas = ", ".join(f"{i['internal_api']} {i.get('version')} ({i['num_threads']} threads)" for i in threadpool_info())
print(f"X: {X.shape} {X.dtype}, {X.nbytes / 1e9:.2f} GB; {blas}")
print("| peer | rank | n_iter | seconds | GB/s | RMSE |")
print("|---|---|---|---|---|---|")
for n_iter in ["auto", 2]:
    t = time.perf_counter()
    U, S, Vt = randomized_svd(X, args.rank, n_oversamples=args.oversamples, n_iter=n_iter, random_state=0)
    s = time.perf_counter() - t
    D = (X @ Vt.T).astype(np.float64)
    rmse = np.sqrt(max(energy - float((D * D).sum()), 0.0) / N)
    label = "auto (=7 here)" if n_iter == "auto" else str(n_iter)
    print(f"| scikit-learn randomized_svd | {args.rank} | {label} | {s:.2f} | {X.nbytes / s / 1e9:.2f} | {rmse:.6f} |")
