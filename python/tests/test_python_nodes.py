"""Python nodes: typed, cached by version and source, recomputed when the source changes, and
their failures are node errors that name the node."""

import importlib.util
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import mesoflow

UNSHARP = '''
import numpy as np
import mesoflow

@mesoflow.node(kind="user.unsharp", inputs={{"image": "Image"}}, outputs={{"image": "Image"}}, version=1)
def unsharp(image, amount: float = 0.5, radius: int = 1):
    """Unsharp masking: image + amount (image - box blur)."""
    k = 2 * radius + 1
    pad = np.pad(image, ((radius, radius), (radius, radius), (0, 0)), mode="wrap")
    blur = sum(pad[y:y + image.shape[0], x:x + image.shape[1]] for y in range(k) for x in range(k)) / k ** 2
    return image + amount * (image - blur){extra}
'''


def load_module(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def pipeline(tmp_path):
    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", "surface", pattern="weave", size=16)
    u = g.add("user.unsharp", "sharp", image=s["preview"], amount=1.0)
    g.add("image.compare", "diff", reference=s["preview"], image=u["image"])
    return g


def test_a_python_node_mid_graph_is_cached_and_recomputed_when_its_source_changes(tmp_path, cache):
    src = tmp_path / "nodes_v.py"
    src.write_text(UNSHARP.format(extra=""))
    mod = load_module(src, "nodes_v1")
    g = pipeline(tmp_path)
    first = g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert [first.node(n)["status"] for n in ("surface", "sharp", "diff")] == ["computed"] * 3
    # Against an independent computation of the same filter with numpy here.
    img = mesoflow.Graph(base_dir=tmp_path)
    s = img.add("heightfield.procedural", "surface", pattern="weave", size=16)
    u = img.add("user.unsharp", "sharp", image=s["preview"], amount=1.0)
    vals = img.run([s["preview"], u["image"]], out_dir=tmp_path / "o2", cache_dir=cache)
    x = vals["surface.preview"]
    expect = mod.unsharp(np.array(x), amount=1.0)
    assert np.allclose(vals["sharp.image"], expect, atol=1e-6)

    again = g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert again.node("diff")["status"] == "memory" and "sharp" in again.report["skipped"]
    # The same function, edited: its node and what depends on it run again; upstream does not.
    src.write_text(UNSHARP.format(extra=" * 0.5"))
    load_module(src, "nodes_v2")
    edited = g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert edited.node("sharp")["status"] == "computed"
    assert edited.node("sharp")["key"] != first.node("sharp")["key"]
    assert edited.node("diff")["status"] == "computed"
    assert "surface" in edited.report["skipped"] or edited.node("surface")["status"] != "computed"


def test_results_survive_in_the_disk_cache_across_processes(tmp_path, cache):
    src = tmp_path / "nodes_d.py"
    src.write_text(UNSHARP.format(extra=""))
    script = textwrap.dedent(f"""
        import importlib.util, json, sys
        spec = importlib.util.spec_from_file_location("n", {str(src)!r}); m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)
        import mesoflow
        g = mesoflow.Graph(base_dir={str(tmp_path)!r})
        s = g.add("heightfield.procedural", "surface", pattern="weave", size=16)
        u = g.add("user.unsharp", "sharp", image=s["preview"])
        r = g.run([u["image"]], out_dir={str(tmp_path / 'o')!r}, cache_dir={str(cache)!r})
        print(r.node("sharp")["status"])
    """)
    out = [subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
           for _ in range(2)]
    assert out == ["computed", "disk"]


def test_parameters_are_checked_from_type_hints(tmp_path):
    @mesoflow.node(kind="user.gain", inputs={"image": "Image"}, outputs={"image": "Image"})
    def gain(image, factor: float, mode: "str" = "mul"):
        return image * factor

    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=8)
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("user.gain", "gain", image=s["preview"], factor="big")
    assert (e.value.node, e.value.field) == ("gain", "factor")
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("user.gain", "gain", image=s["preview"])
    assert e.value.field == "factor" and "missing" in str(e.value)
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("user.gain", "gain", image=s["height"], factor=2.0)
    assert e.value.field == "image" and "HeightField" in str(e.value)
    g.add("user.gain", "gain", image=s["preview"], factor=2.0)
    assert "user.gain" in mesoflow.kinds()
    assert "factor" in mesoflow.describe("user.gain")


def test_an_exception_is_a_node_error_naming_the_node(tmp_path, cache):
    @mesoflow.node(kind="user.broken", inputs={"height": "HeightField"}, outputs={"value": "Scalar"})
    def broken(height):
        raise ValueError("the height field is too flat")

    @mesoflow.node(kind="user.badshape", inputs={"height": "HeightField"}, outputs={"image": "Image"})
    def badshape(height):
        return np.zeros((2, 2, 2))

    # A complex image was once cast to its real part without a word.
    @mesoflow.node(kind="user.complex", inputs={"height": "HeightField"}, outputs={"image": "Image"})
    def complex_image(height):
        return np.zeros((2, 2), dtype=complex)

    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=8)
    g.add("user.broken", "metric", height=s["height"])
    g.add("user.badshape", "shape", height=s["height"])
    g.add("user.complex", "cplx", height=s["height"])
    g.add("heightfield.normals", "fine", height=s["height"])
    with pytest.raises(mesoflow.NodeError) as e:
        g.run(out_dir=tmp_path / "o", cache_dir=cache)
    text = str(e.value)
    assert "node `metric`" in text and "ValueError: the height field is too flat" in text
    assert "node `shape`" in text and "output `image`" in text and "(2, 2, 2)" in text
    assert "node `cplx`" in text and "complex128 is not one of real numbers" in text, text
    # An independent branch still finished.
    statuses = {n["id"]: n["status"] for n in e.value.report["nodes"]}
    assert statuses["fine"] == "computed"


def test_warnings_go_into_the_report(tmp_path, cache):
    import warnings

    @mesoflow.node(kind="user.warns", inputs={"height": "HeightField"}, outputs={"value": "Scalar"})
    def warns(height):
        warnings.warn("clipped 3 texels")
        return float(height.max())

    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=8)
    g.add("user.warns", "w", height=s["height"])
    r = g.run(out_dir=tmp_path / "o", cache_dir=cache)
    assert {"node": "w", "message": "clipped 3 texels"} in r.report["warnings"]
    assert isinstance(r["w.value"], float)


def test_the_command_line_refuses_a_graph_with_a_python_node_clearly(tmp_path, cli):
    @mesoflow.node(kind="user.only_here", inputs={"height": "HeightField"}, outputs={"value": "Scalar"})
    def only_here(height):
        return 1.0

    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", pattern="weave", size=8)
    g.add("user.only_here", "mine", height=s["height"])
    path = g.save(tmp_path / "g.json")
    p = subprocess.run([str(cli), "run", str(path), "--no-cache"], capture_output=True, text=True)
    assert p.returncode == 2
    assert "unknown kind `user.only_here`" in p.stderr and "@mesoflow.node" in p.stderr


def test_a_python_node_cannot_shadow_a_built_in_kind():
    with pytest.raises(ValueError, match="built-in"):
        @mesoflow.node(kind="btf.pca", inputs={}, outputs={"value": "Scalar"})
        def pca():
            return 1.0


def test_a_declared_schema_checks_parameters(tmp_path, cache):
    @mesoflow.node(kind="user.clip", inputs={"height": "HeightField"}, outputs={"height": "HeightField"},
                   params={"low": {"type": "number", "default": 0.0},
                           "high": {"type": "number", "minimum": 0, "maximum": 100}})
    def clip(height, **limits):
        return np.clip(height, limits["low"], limits["high"])

    g = mesoflow.Graph(base_dir=tmp_path)
    s = g.add("heightfield.procedural", "s", pattern="weave", size=8)
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("user.clip", "c", height=s["height"], high=500)
    assert e.value.field == "high" and "out of range" in str(e.value)
    with pytest.raises(mesoflow.GraphError) as e:
        g.add("user.clip", "c", height=s["height"], high=1, hihg=2)
    assert e.value.field == "hihg" and "did you mean `high`" in str(e.value)
    c = g.add("user.clip", "c", height=s["height"], high=1.0)
    r = g.run([s["height"], c["height"]], out_dir=tmp_path / "o", cache_dir=cache)
    # The default `low` applied: the clip of the heights to [0, 1], computed here with numpy.
    assert np.array_equal(r["c.height"], np.clip(r["s.height"], 0.0, 1.0))
