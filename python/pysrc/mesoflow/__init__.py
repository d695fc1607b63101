"""mesoflow from Python: build, run and extend appearance-modeling graphs, with numpy in and out.

>>> import mesoflow
>>> g = mesoflow.Graph()
>>> s = g.add("heightfield.procedural", pattern="weave", size=32)
>>> cap = g.add("btf.capture", height=s["height"], views="ubo81")
>>> r = g.run([cap["btf"]])
>>> r["capture.btf"].shape   # (pairs, 3, H, W), as npy.write writes it

The same engine, cache keys and files as the ``mesoflow`` command line: :func:`load` reads a
graph file, :meth:`Graph.save` writes one, :func:`sweep` writes the command line's ``sweep.csv``
and charts, and :func:`node` adds a kind written in Python.
"""

import os as _os

# Mesa's Vulkan device-select layer looks for a display and prints `XDG_RUNTIME_DIR is invalid` on
# headless machines; mesoflow picks its adapter itself (the command line does the same).
_os.environ.setdefault("NODEVICE_SELECT", "1")

from ._native import __version__  # noqa: E402
from ._catalog import describe, kinds, signature  # noqa: E402
from ._errors import GraphError, MesoflowError, NodeError  # noqa: E402
from ._graph import Graph, Node, Output, Result, load  # noqa: E402
from ._node import node  # noqa: E402
from ._plan import Decision, Plan, TruthPlan, plan  # noqa: E402
from ._sweep import sweep  # noqa: E402


def cli(*args: str) -> int:
    """Runs the command line in this process: ``mesoflow.cli("plan", "graphs/mdf_render.json",
    "--render", "torus_mdf", "--budget", "flip=0.05")`` does what ``mesoflow plan …`` does, and
    returns its exit code (0 ok, 1 run failed, 2 invalid, 130 cancelled). Its output goes to the
    process's stdout and stderr (in Jupyter, the kernel's console). Kinds defined with
    :func:`node` are not seen by it, as they are not by the ``mesoflow`` binary."""
    from ._native import cli as _cli

    return _cli([str(a) for a in args])

__all__ = [
    "Decision",
    "Graph",
    "GraphError",
    "MesoflowError",
    "Node",
    "NodeError",
    "Output",
    "Plan",
    "TruthPlan",
    "Result",
    "__version__",
    "cli",
    "describe",
    "kinds",
    "load",
    "node",
    "plan",
    "signature",
    "sweep",
]
