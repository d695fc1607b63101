"""Results from Python equal the command line's, bit for bit: the same files, and arrays equal
to what `npy.write` writes."""

import filecmp
import json
import subprocess
from pathlib import Path

import numpy as np

import mesoflow


def files_under(folder: Path):
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file() and p.name != "report.json")


def test_a_shipped_graph_writes_the_same_files_as_the_command_line(repo, cli, tmp_path):
    graph = repo / "graphs" / "btf_compress.json"
    sets = {"surface.size": 32}
    subprocess.run(
        [str(cli), "run", str(graph), "--quiet", "--set", "surface.size=32",
         "--out-dir", str(tmp_path / "cli"), "--cache-dir", str(tmp_path / "cli-cache")],
        check=True,
    )
    r = mesoflow.load(graph).run(set=sets, out_dir=tmp_path / "py", cache_dir=tmp_path / "py-cache")
    assert r.ok
    cli_files = files_under(tmp_path / "cli")
    assert cli_files == files_under(tmp_path / "py") and cli_files
    for f in cli_files:
        assert filecmp.cmp(tmp_path / "cli" / f, tmp_path / "py" / f, shallow=False), f
    # The same cache keys: the engine, the graph and the parameters are the same.
    cli_report = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert {n["id"]: n["key"] for n in cli_report["nodes"]} == {n["id"]: n["key"] for n in r.report["nodes"]}
    assert json.loads((tmp_path / "py" / "report.json").read_text())["ok"] is True


def test_values_are_npy_write_arrays_and_scalars_are_floats(repo, cli, tmp_path, cache):
    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=16)
    cap = g.add("btf.capture", height=s["height"], views="ubo81", lights={"thetas": [30], "phis": [0, 180]})
    pca = g.add("btf.pca", btf=cap["btf"], rank=2)
    g.add("npy.write", "height_npy", value=s["height"], path="height.npy")
    g.add("npy.write", "btf_npy", value=cap["btf"], path="btf.npy")
    path = g.save(tmp_path / "g.json")
    subprocess.run([str(cli), "run", str(path), "--quiet", "--out-dir", str(tmp_path / "cli"),
                    "--cache-dir", str(tmp_path / "cli-cache")], check=True)
    r = g.run([s["height"], cap["btf"], pca["rmse"]], out_dir=tmp_path / "py", cache_dir=cache)
    h = r["procedural.height"]
    assert h.dtype == np.float32 and h.shape == (16, 16)
    assert np.array_equal(h, np.load(tmp_path / "cli" / "height.npy"))
    btf = r["capture.btf"]
    assert btf.shape[1:] == (3, 16, 16)
    assert np.array_equal(btf, np.load(tmp_path / "cli" / "btf.npy"))
    assert isinstance(r["pca.rmse"], float) and r["pca.rmse"] == r.metrics("pca")["rmse"]


def test_large_arrays_come_back_without_a_copy(tmp_path, cache):
    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=64)
    r = g.run([s["height"]], out_dir=tmp_path / "out", cache_dir=cache)
    h = r["procedural.height"]
    # A view of the engine's memory: numpy does not own it, and it is read-only.
    assert not h.flags.owndata and not h.flags.writeable
    assert h.base is not None
    copy = np.array(h)
    copy[0, 0] += 1  # a copy can be changed
