"""numpy arrays enter graphs as typed values, round-trip exactly, and are keyed by content."""

import numpy as np
import pytest

import mesoflow


def test_arrays_round_trip_through_each_array_kind(tmp_path, cache):
    rng = np.random.default_rng(1)
    img = rng.random((5, 7, 3), dtype=np.float32)
    height = rng.random((6, 4)) * 3  # f64 in, f32 inside
    btf = rng.random((2, 3, 4, 4), dtype=np.float32)
    pts = rng.random((9, 3))
    g = mesoflow.Graph(base_dir=tmp_path)
    i = g.add("image.array", data=img)
    h = g.add("heightfield.array", data=height)
    b = g.add("btf.array", data=btf, pairs=[[0, 0, 30, 0], [30, 90, 45, 180]])
    p = g.add("points.array", data=pts)
    r = g.run([i["image"], h["height"], b["btf"], p["points"]], out_dir=tmp_path / "o", cache_dir=cache)
    assert np.array_equal(r["array.image"], img)
    assert np.array_equal(r["array_2.height"], height.astype(np.float32))
    assert np.array_equal(r["array_3.btf"], btf)
    assert np.array_equal(r["array_4.points"], pts)  # point sets stay f64


def test_the_same_array_gives_the_same_key_in_another_graph(tmp_path, cache):
    x = np.linspace(0, 1, 64, dtype=np.float32).reshape(8, 8)

    def run(data):
        g = mesoflow.Graph(base_dir=tmp_path)
        h = g.add("heightfield.array", "h", data=data)
        n = g.add("heightfield.normals", "n", height=h["height"])
        return g.run([n["normals"]], out_dir=tmp_path / "o", cache_dir=cache)

    first = run(x)
    again = run(x.copy())
    assert first.node("n")["status"] == "computed"
    assert again.node("n")["status"] in ("memory", "disk")
    assert again.node("n")["key"] == first.node("n")["key"]
    changed = run(x * 2)
    assert changed.node("n")["status"] == "computed"
    assert changed.node("n")["key"] != first.node("n")["key"]


def test_a_saved_graph_with_arrays_runs_from_another_folder(tmp_path, cli):
    import subprocess
    x = np.ones((4, 4, 1), dtype=np.float32) * 0.25
    g = mesoflow.Graph(base_dir=tmp_path / "work")
    i = g.add("image.array", "img", data=x)
    g.add("image.write", "png", image=i["image"], path="x.png")
    path = g.save(tmp_path / "elsewhere" / "g.json")
    subprocess.run([str(cli), "run", str(path), "--quiet", "--out-dir", str(tmp_path / "out"),
                    "--no-cache"], check=True)
    assert (tmp_path / "out" / "x.png").exists()


def test_bad_arrays_are_node_errors(tmp_path, cache):
    g = mesoflow.Graph(base_dir=tmp_path)
    g.add("image.array", "img", data=np.full((2, 2, 2), 0.5))
    with pytest.raises(mesoflow.NodeError) as e:
        g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert e.value.node == "img" and "1, 3 or 4 channels" in str(e.value)
    g = mesoflow.Graph(base_dir=tmp_path)
    g.add("heightfield.array", "h", data=np.array([[1.0, np.nan]]))
    with pytest.raises(mesoflow.NodeError, match="not finite"):
        g.run(out_dir=tmp_path / "o", cache_dir=cache)


def test_complex_and_datetime_arrays_are_refused_not_converted(tmp_path):
    g = mesoflow.Graph(base_dir=tmp_path)
    for bad in (np.ones((4, 4), dtype=complex), np.zeros((4, 4), dtype="datetime64[s]")):
        with pytest.raises(TypeError, match="not one of real numbers"):
            g.add("heightfield.array", "h", data=bad)
    assert "h" not in g


def test_the_memory_budget_holds_for_array_inputs_and_python_nodes_outputs(tmp_path, monkeypatch):
    # 10 kB: a 64 x 64 height field is 49 kB read (f64) and kept (f32); the budget is read when
    # the array is, so setting it here reaches the engine in this process.
    monkeypatch.setenv("MESOFLOW_MEMORY_BUDGET_GB", "0.00001")
    cache = tmp_path / "cache"
    g = mesoflow.Graph(base_dir=tmp_path)
    g.add("heightfield.array", "h", data=np.zeros((64, 64)))
    with pytest.raises(mesoflow.NodeError) as e:
        g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert e.value.node == "h" and "over the memory budget" in str(e.value)

    @mesoflow.node(kind="user.huge", inputs={"height": "HeightField"}, outputs={"image": "Image"})
    def huge(height):
        return np.zeros((64, 64, 3), dtype=np.float32)

    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=8)
    g.add("user.huge", "big", height=s["height"])
    with pytest.raises(mesoflow.NodeError) as e:
        g.run(out_dir=tmp_path / "o2", cache_dir=cache)
    assert e.value.node == "big" and "over the memory budget" in str(e.value)
