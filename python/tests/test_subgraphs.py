"""A graph file used as a node from Python: `g.add("graph", path=…)`, its exposed parameters and
inner ones by path, and `mesoflow.load` of a graph that uses one."""

import json

import mesoflow

INNER = {
    "mesoflow": 2,
    "interface": {"inputs": {"x": "a.x"}, "outputs": {"y": "b.y"}, "params": {"scale": "a.scale"}},
    "nodes": {
        "c": {"kind": "scalar.constant", "params": {"value": 1.0}},
        "a": {"kind": "scalar.affine", "inputs": {"x": "c.value"}, "params": {"scale": 2.0}},
        "b": {"kind": "scalar.affine", "inputs": {"x": "a.y"}, "params": {"scale": 3.0}},
    },
}


def test_a_subgraph_from_python(tmp_path):
    (tmp_path / "inner.json").write_text(json.dumps(INNER))
    g = mesoflow.Graph(base_dir=tmp_path)
    one = g.add("scalar.constant", "one", value=0.5)
    p = g.add("graph", "p", path="inner.json", scale=4.0, x=one["value"])
    g.add("scalar.affine", "twice", x=p["y"], scale=2.0)
    r = g.run(out_dir=tmp_path / "out", cache_dir=tmp_path / "cache", progress=False)
    assert r.report["ok"]
    ids = [n["id"] for n in r.report["nodes"]]
    assert "p/a" in ids and "p/c" not in ids  # c fed only the input given from outside
    twice = next(n for n in r.report["nodes"] if n["id"] == "twice")
    assert twice["metrics"]["y"] == 0.5 * 4.0 * 3.0 * 2.0
    # An inner parameter by its path, kept in the graph node's `set`.
    g.set("p/b.scale", 10.0)
    r = g.run(out_dir=tmp_path / "out", cache_dir=tmp_path / "cache", progress=False)
    twice = next(n for n in r.report["nodes"] if n["id"] == "twice")
    assert twice["metrics"]["y"] == 0.5 * 4.0 * 10.0 * 2.0
    assert next(n for n in r.report["nodes"] if n["id"] == "p/b")["reason"] == "parameter `scale` 3.0 → 10.0"
    # Saved and loaded again, it is the same graph; a mistake names the path.
    g.save(tmp_path / "outer.json")
    again = mesoflow.load(tmp_path / "outer.json")
    assert again._nodes["p"]["params"]["set"] == {"b.scale": 10.0}
    try:
        g.set("p.scael", 1.0)
    except mesoflow.GraphError as e:
        assert "did you mean `scale`" in str(e)
    else:
        raise AssertionError("an unknown exposed parameter was accepted")


def test_a_sweep_over_a_subgraphs_exposed_parameter(tmp_path):
    (tmp_path / "inner.json").write_text(json.dumps(INNER))
    g = mesoflow.Graph(base_dir=tmp_path)
    g.add("graph", "p", path="inner.json")
    rows = mesoflow.sweep(g, vary={"p.scale": [1.0, 2.0]}, measure=["p.y"],
                          out_dir=tmp_path / "s", cache_dir=tmp_path / "cache", progress=False)
    records = rows.to_dict("records") if hasattr(rows, "to_dict") else rows
    # p.y is b's output inside: 1 × scale × 3.
    assert [r["p.y"] for r in records] == [3.0, 6.0]
