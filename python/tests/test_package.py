"""The installed package: its version, stubs and documentation."""

import io
import re
from contextlib import redirect_stdout
from pathlib import Path

import mesoflow


def test_version_is_the_workspace_version(repo):
    cargo = (repo / "Cargo.toml").read_text()
    version = re.search(r'\[workspace\.package\][^\[]*?version = "([^"]+)"', cargo).group(1)
    assert mesoflow.__version__ == version


def test_stubs_and_marker_ship_with_the_package():
    here = Path(mesoflow.__file__).parent
    assert (here / "py.typed").exists()
    stub = (here / "_native.pyi").read_text()
    for name in ("def run(", "def validate(", "def register_node(", "def cli(", "class ArrayBuffer"):
        assert name in stub, name


def test_help_explains_the_api():
    out = io.StringIO()
    with redirect_stdout(out):
        help(mesoflow.Graph.run)
    text = out.getvalue()
    assert "GIL" in text and "Ctrl-C" in text and "out_dir" in text
    assert "HeightField" in (mesoflow.node.__doc__ or "")
    assert mesoflow.describe("btf.pca").startswith("btf.pca (version")
