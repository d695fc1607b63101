"""Errors as the command line reports them, Ctrl-C, and runs from two threads."""

import json
import os
import signal
import threading
import time

import numpy as np
import pytest

import mesoflow


def test_graph_errors_name_node_and_field(tmp_path):
    g = mesoflow.Graph(base_dir=tmp_path)
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("heightfield.procedual", "s")
    assert e.value.node == "s" and "did you mean `heightfield.procedural`" in str(e.value)
    s = g.add("heightfield.procedural", "s", size=8)
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("btf.pca", "pca", btf=s["height"])
    assert (e.value.node, e.value.field) == ("pca", "btf")
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("heightfield.procedural", "t", sise=8)
    assert e.value.field == "sise" and "did you mean `size`" in str(e.value)
    with pytest.raises(KeyError, match="has no output `heigth`"):
        s["heigth"]
    assert "pca" not in g and len(g) == 1  # refused nodes are not kept
    with pytest.raises(mesoflow.GraphError):
        g.set("s.size", -1)
    assert g["s"].params["size"] == 8
    # `run(set=...)` checks its values as `set` does (it once raised a bare ValueError).
    with pytest.raises(mesoflow.GraphError) as e:
        g.run(set={"s.size": -1}, out_dir=tmp_path / "out", use_cache=False)
    assert e.value.node == "s" and g["s"].params["size"] == 8
    with pytest.raises(mesoflow.GraphError):
        g.run(set={"nope.size": 4}, out_dir=tmp_path / "out", use_cache=False)


def test_load_reports_every_error_of_a_file(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"mesoflow": 1, "nodes": {
        "a": {"kind": "heightfield.procedural", "params": {"size": "x"}},
        "b": {"kind": "heightfield.normals", "inputs": {"height": "zz.height"}}}}))
    with pytest.raises(mesoflow.GraphError) as e:
        mesoflow.load(bad)
    assert len(e.value.errors) == 2


def sleeper(tmp_path, ms):
    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("scalar.constant", "c", value=1.0)
    g.add("debug.sleep", "wait", x=s["value"], ms=ms)
    return g


def test_ctrl_c_cancels_the_run(tmp_path, cache, ctrl_c):
    g = sleeper(tmp_path, 20_000)
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    t0 = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert time.monotonic() - t0 < 10  # far less than the node's 20 s
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["cancelled"] is True
    assert {n["id"]: n["status"] for n in report["nodes"]}["wait"] == "cancelled"


def test_two_threads_run_at_once_and_python_goes_on(tmp_path, cache):
    results = {}

    def work(name, size):
        g = mesoflow.Graph(base_dir=tmp_path)
        s = g.add("heightfield.procedural", "s", pattern="weave", size=size)
        g.add("heightfield.normals", "n", height=s["height"])
        c = g.add("scalar.constant", "c", value=float(size))
        g.add("debug.sleep", "wait", x=c["value"], ms=300)
        results[name] = g.run(["n.normals", "wait.y"], out_dir=tmp_path / name, cache_dir=cache, device="cpu")

    ticks = []
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.01)

    tick = threading.Thread(target=ticker)
    tick.start()
    threads = [threading.Thread(target=work, args=(f"t{i}", 16 * (i + 1))) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    stop.set()
    tick.join()
    assert set(results) == {"t0", "t1"} and all(r.ok for r in results.values())
    # The GIL was free while the engines slept: the ticker kept ticking.
    assert len(ticks) > 15
    # Each thread's values equal a run of the same graph alone.
    for name, size in (("t0", 16), ("t1", 32)):
        g = mesoflow.Graph(base_dir=tmp_path)
        s = g.add("heightfield.procedural", "s", pattern="weave", size=size)
        g.add("heightfield.normals", "n", height=s["height"])
        alone = g.run(["n.normals"], out_dir=tmp_path / "alone", use_cache=False, device="cpu")
        assert np.array_equal(alone["n.normals"], results[name]["n.normals"])


def test_the_command_line_runs_in_process(repo, tmp_path, capfd):
    graph = repo / "graphs" / "quickstart.json"
    assert mesoflow.cli("validate", graph) == 0
    code = mesoflow.cli("run", graph, "--quiet", "--set", "surface.size=32",
                        "--out-dir", tmp_path / "o", "--cache-dir", tmp_path / "c")
    assert code == 0 and (tmp_path / "o" / "normals.png").exists()
    assert mesoflow.cli("run", graph, "--no-such-flag") == 2
    assert "--no-such-flag" in capfd.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text('{"mesoflow": 1, "nodes": {"a": {"kind": "heightfield.procedural", "params": {"size": -4}}}}')
    assert mesoflow.cli("validate", bad) == 2
    assert "size" in capfd.readouterr().err


def test_ctrl_c_stops_an_in_process_watch(repo, tmp_path, ctrl_c):
    graph = repo / "graphs" / "quickstart.json"
    timer = threading.Timer(1.5, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        mesoflow.cli("watch", graph, "--quiet", "--set", "surface.size=16",
                     "--out-dir", tmp_path / "o", "--cache-dir", tmp_path / "c")
    # The next command is not born cancelled.
    assert mesoflow.cli("validate", graph) == 0


def test_progress_events_reach_a_callback(tmp_path, cache):
    events = []
    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", "s", pattern="weave", size=32)
    g.add("btf.capture", "cap", height=s["height"], views="ubo81", lights={"thetas": [30], "phis": [0]})
    g.run(out_dir=tmp_path / "o", cache_dir=cache, progress=lambda *e: events.append(e))
    assert ("started", "cap") in [(e[0], e[1]) for e in events]
    assert ("finished", "cap", "computed") in [e[:3] for e in events]
    steps = [e for e in events if e[0] == "progress" and e[1] == "cap"]
    # 81 views report as they go; forwarded in 5% steps, so at most 21 of them reach Python.
    assert 1 <= len(steps) <= 21 and steps[-1][3] <= steps[-1][4]


def test_ctrl_c_reaches_a_python_node_that_never_returns(tmp_path, cache, ctrl_c):
    # It once ignored two Ctrl-Cs and the process had to be killed: the cancel now raises a
    # KeyboardInterrupt in the node's thread, and the run ends cancelled.
    @mesoflow.node(kind="user.forever", inputs={"x": "Scalar"}, outputs={"y": "Scalar"})
    def forever(x):
        while True:
            pass

    g = mesoflow.Graph(base_dir=tmp_path)
    c = g.add("scalar.constant", "c", value=1.0)
    g.add("user.forever", "spin", x=c["value"])
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    t0 = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert time.monotonic() - t0 < 20
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["cancelled"] is True
    assert {n["id"]: n["status"] for n in report["nodes"]}["spin"] == "cancelled"
    # The thread is left clean: the next run of a Python node is not interrupted.
    @mesoflow.node(kind="user.quick", inputs={"x": "Scalar"}, outputs={"y": "Scalar"})
    def quick(x):
        return x + 1.0

    g = mesoflow.Graph(base_dir=tmp_path)
    c = g.add("scalar.constant", "c", value=1.0)
    g.add("user.quick", "q", x=c["value"])
    assert g.run(["q.y"], out_dir=tmp_path / "o2", cache_dir=cache)["q.y"] == 2.0
