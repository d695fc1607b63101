"""What the Python package costs over the command line, on this machine:

1. a whole run of graphs/quickstart.json, from Python and from the `mesoflow` binary (no cache);
2. getting a large value back: the zero-copy view against a copy of it;
3. a Python node against a built-in node doing the same (scaling a height field), per call.

Run: target/py-venv/bin/python python/benches/overhead.py   (after scripts/test built the package)
"""

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import mesoflow

REPO = Path(__file__).resolve().parents[2]
CLI = REPO / "target" / "release" / "mesoflow"


def best(f, n=5):
    times = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times), statistics.median(times)


def main():
    tmp = Path(tempfile.mkdtemp())
    graph = REPO / "graphs" / "quickstart.json"
    g = mesoflow.load(graph)
    py = best(lambda: g.run(out_dir=tmp / "py", use_cache=False, device="cpu"))
    cli = best(lambda: subprocess.run([str(CLI), "run", str(graph), "--quiet", "--no-cache", "--device", "cpu",
                                       "--out-dir", str(tmp / "cli")], check=True))
    print(f"quickstart, no cache, CPU: python {py[0]*1e3:.1f} ms (median {py[1]*1e3:.1f}), "
          f"command line {cli[0]*1e3:.1f} ms (median {cli[1]*1e3:.1f})")

    b = mesoflow.Graph(base_dir=tmp)
    s = b.add("heightfield.procedural", "s", pattern="weave", size=64)
    c = b.add("btf.capture", "c", height=s["height"], views="ubo81")
    r = b.run([c["btf"]], out_dir=tmp / "b", cache_dir=tmp / "cache")
    mb = r["c.btf"].nbytes / 2**20
    view = best(lambda: b.run([c["btf"]], out_dir=tmp / "b", cache_dir=tmp / "cache")["c.btf"], n=7)
    copy = best(lambda: np.array(b.run([c["btf"]], out_dir=tmp / "b", cache_dir=tmp / "cache")["c.btf"]), n=7)
    print(f"a {mb:.0f} MiB BTF from the memory cache: view {view[0]*1e3:.2f} ms, with a copy {copy[0]*1e3:.2f} ms")

    @mesoflow.node(kind="bench.scale", inputs={"height": "HeightField"}, outputs={"height": "HeightField"})
    def scale(height, factor: float = 2.0):
        return height * factor

    def chain(kind, n, **kw):
        h = mesoflow.Graph(base_dir=tmp)
        prev = h.add("heightfield.procedural", "s", pattern="weave", size=16)["height"]
        for i in range(n):
            prev = h.add(kind, f"n{i}", height=prev, **kw)["height"]
        return h

    n = 50
    pyc = chain("bench.scale", n, factor=2.0)
    rs = chain("heightfield.edit", n, operation="scale", amount=2.0)
    tp = best(lambda: pyc.run(out_dir=tmp / "c1", use_cache=False))
    tr = best(lambda: rs.run(out_dir=tmp / "c2", use_cache=False))
    print(f"a chain of {n} scalings of a 16² height field: Python nodes {tp[0]/n*1e6:.0f} µs/node, "
          f"heightfield.edit {tr[0]/n*1e6:.0f} µs/node")


if __name__ == "__main__":
    sys.exit(main())
