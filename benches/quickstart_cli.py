#!/usr/bin/env python3
"""The quickstart as a whole process, cold and cached (BENCHMARKS.md, "Command line").

Usage: python3 benches/quickstart_cli.py [path/to/mesoflow]   (default target/release/mesoflow)

Runs in a scratch copy of graphs/quickstart.json with its cache beside it. Cold: the cache
folder (values and the remembered GPU probe) removed before each of 10 runs, after one warm-up.
Cached: 30 runs after two warm-ups. Means and standard deviations of the wall time.
"""
import os, shutil, statistics, subprocess, sys, tempfile, time

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
exe = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "target/release/mesoflow"))
work = tempfile.mkdtemp(prefix="qsb-")
shutil.copy(os.path.join(root, "graphs/quickstart.json"), work)


def timed(args, cold, runs, warmup):
    xs = []
    for i in range(warmup + runs):
        if cold:
            shutil.rmtree(os.path.join(work, ".mesoflow"), ignore_errors=True)
        t = time.perf_counter()
        subprocess.run([exe, "run", "quickstart.json", "--quiet"] + args, cwd=work, check=True)
        if i >= warmup:
            xs.append(time.perf_counter() - t)
    return statistics.mean(xs) * 1e3, statistics.stdev(xs) * 1e3


for extra in [[], ["--device", "cpu"], ["--device", "cpu", "--set", "surface.size=1024"]]:
    c, w = timed(extra, True, 10, 1), timed(extra, False, 30, 2)
    name = " ".join(extra) or "default device"
    print(f"{name}: cold {c[0]:.1f} ± {c[1]:.1f} ms, cached {w[0]:.1f} ± {w[1]:.1f} ms, {100 * w[0] / c[0]:.1f}%")
shutil.rmtree(work)
