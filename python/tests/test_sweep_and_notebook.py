"""`mesoflow.sweep` writes what `mesoflow sweep` writes; the example notebook runs."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import mesoflow

TIMING = ("seconds", "run_seconds")


def rows_without_timings(path: Path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    keep = [i for i, h in enumerate(rows[0]) if not h.endswith(TIMING)]
    return [[r[i] for i in keep] for r in rows]


def test_the_sweep_matches_the_command_line(repo, cli, tmp_path):
    graph = repo / "graphs" / "btf_compress.json"
    subprocess.run(
        [str(cli), "sweep", str(graph), "--quiet", "--set", "surface.size=32",
         "--vary", "pca.rank=1,2,4", "--measure", "pca.rmse", "--measure", "pca.seconds",
         "--measure", "pca.compression_ratio", "--versus", "pca.compression_ratio",
         "--out-dir", str(tmp_path / "cli"), "--cache-dir", str(tmp_path / "cli-cache")],
        check=True,
    )
    rows = mesoflow.sweep(
        mesoflow.load(graph), vary={"pca.rank": [1, 2, 4]},
        measure=["pca.rmse", "pca.seconds", "pca.compression_ratio"],
        versus=["pca.compression_ratio"], set={"surface.size": 32},
        out_dir=tmp_path / "py", cache_dir=tmp_path / "py-cache", progress=False,
    )
    cli_csv = tmp_path / "cli" / "sweep.csv"
    py_csv = tmp_path / "py" / "sweep.csv"
    assert rows_without_timings(cli_csv) == rows_without_timings(py_csv)
    assert next(csv.reader(open(cli_csv))) == next(csv.reader(open(py_csv)))
    cli_charts = sorted(p.name for p in (tmp_path / "cli").iterdir() if p.suffix in (".png", ".svg"))
    py_charts = sorted(p.name for p in (tmp_path / "py").iterdir() if p.suffix in (".png", ".svg"))
    assert cli_charts == py_charts and len(cli_charts) >= 6
    # A chart with no timing in it is the same drawing, byte for byte.
    name = "pca.rmse_vs_pca.rank.svg"
    assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "py" / name).read_bytes()
    assert sorted(os.listdir(tmp_path / "py" / "runs")) == ["000", "001", "002"]
    # Rows come back as a DataFrame when pandas is there, a list of dicts otherwise.
    records = rows.to_dict("records") if hasattr(rows, "to_dict") else rows
    assert [r["pca.rank"] for r in records] == [1, 2, 4]
    assert records[0]["pca.rmse"] > records[2]["pca.rmse"]


def test_sweep_rows_are_dicts_without_pandas(repo, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    g = mesoflow.Graph(base_dir=tmp_path)
    g.add("scalar.constant", "c", value=1.0)
    g.add("scalar.affine", "a", x="c.value", scale=2.0)
    rows = mesoflow.sweep(g, vary={"c.value": [1.0, 3.0]}, measure=["a.y"],
                          out_dir=tmp_path / "s", cache_dir=tmp_path / "cache", progress=False)
    assert isinstance(rows, list) and [r["a.y"] for r in rows] == [2.0, 6.0]


def test_the_example_notebook_runs(repo, tmp_path):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(repo / "examples" / "python_experiment.ipynb", as_version=4)
    os.environ["MESOFLOW_EXAMPLE_OUT"] = str(tmp_path / "out")
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    assert (tmp_path / "out" / "rank_sweep.png").stat().st_size > 10_000
    assert (tmp_path / "out" / "sweep" / "sweep.csv").exists()


def test_a_sweep_is_refused_before_any_run(tmp_path):
    # The command line's own checks: a measure that is not a scalar names its node and port,
    # a combination that does not check names its node, an oversized grid is a ValueError.
    import pytest

    g = mesoflow.Graph(base_dir=tmp_path)
    g.add("scalar.constant", "c", value=1.0)
    g.add("scalar.affine", "a", x="c.value", scale=2.0)
    common = dict(out_dir=tmp_path / "s", cache_dir=tmp_path / "cache", progress=False)
    with pytest.raises(mesoflow.GraphError) as e:
        mesoflow.sweep(g, vary={"c.value": [1.0]}, measure=["a.nosuch"], **common)
    assert (e.value.node, e.value.field) == ("a", "nosuch")
    assert "measure a.nosuch" in str(e.value) and "--measure" not in str(e.value)
    with pytest.raises(mesoflow.GraphError) as e:
        mesoflow.sweep(g, vary={"c.value": [1.0, "x"]}, measure=["a.y"], **common)
    assert e.value.node == "c"
    with pytest.raises(ValueError, match="more than"):
        mesoflow.sweep(g, vary={"c.value": [1.0, 2.0, 3.0]}, measure=["a.y"], max_runs=2, **common)
    assert not (tmp_path / "s").exists()
