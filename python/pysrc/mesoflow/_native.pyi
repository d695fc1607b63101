"""Type stubs of the extension module ``mesoflow._native`` (Rust, PyO3). Use the package's
public API (``mesoflow.Graph``, ``mesoflow.load``, …); these are its building blocks."""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

__version__: str

class ArrayBuffer:
    """A read-only array exported through the buffer protocol (``numpy.asarray`` wraps it
    without a copy)."""

    type_name: str
    @property
    def shape(self) -> List[int]: ...

class Opaque:
    """A value with no array layout (a mesh, a material): its type and size in bytes."""

    type_name: str
    bytes: int

def catalog() -> str:
    """Every kind's signature, as JSON text."""

def validate(text: str, name: str) -> List[Tuple[Optional[str], Optional[str], str]]:
    """The graph file's errors as (node, field, message); empty when valid."""

def register_node(
    kind: str,
    version: int,
    doc: str,
    inputs: Sequence[Tuple[str, str, bool]],
    outputs: Sequence[Tuple[str, str]],
    schema: str,
    defaults: str,
    source_hash: str,
    func: Callable[[Dict[str, Any], Dict[str, Any]], Tuple[Dict[str, Any], List[str]]],
    disk_cache: bool = True,
) -> None:
    """Registers a Python node kind (see ``mesoflow.node``)."""

def run(
    text: str,
    name: str,
    base_dir: str,
    out_dir: str,
    outputs: Sequence[str],
    sets: Sequence[str],
    device: str = "auto",
    cache_dir: Optional[str] = None,
    use_cache: bool = True,
    verify_cache: bool = False,
    progress: Optional[Callable[[str, str, str, int, int], None]] = None,
) -> Tuple[str, Dict[str, Any]]:
    """Runs a graph file's text; returns the report (JSON text) and the values by "node.port"."""

def plan(
    text: str,
    name: str,
    base_dir: str,
    render: str,
    budget: float,
    sets: Sequence[str],
    ppd: Optional[float] = None,
    split: str = "joint",
    device: str = "auto",
    cache_dir: Optional[str] = None,
    use_cache: bool = True,
    probe_budget: float = 1.0,
    probe_share: float = 0.25,
) -> Tuple[str, str]:
    """Plans a render node of a graph file's text; returns the plan document and the planned
    graph, both as JSON text."""

def plan_truth(
    text: str,
    name: str,
    base_dir: str,
    render: str,
    budget: float,
    sets: Sequence[str],
    device: str = "auto",
    cache_dir: Optional[str] = None,
    use_cache: bool = True,
    probe_share: float = 0.1,
    measure: str = "rmse",
    ppd: Optional[float] = None,
) -> Tuple[str, str]:
    """Plans a render node against the truth the graph makes (relative RMSE, or mean FLIP at
    ``ppd``); returns the plan document and the planned graph, both as JSON text."""

def sweep(
    text: str,
    name: str,
    base_dir: str,
    out_dir: str,
    vary: Sequence[Tuple[str, str]],
    measures: Sequence[str],
    versus: Sequence[str],
    sets: Sequence[str],
    max_runs: int,
    device: str = "auto",
    cache_dir: Optional[str] = None,
    use_cache: bool = True,
    progress: bool = True,
) -> Tuple[
    List[str],
    List[str],
    List[Tuple[str, List[Optional[float]], List[Optional[float]], float, bool]],
    List[str],
]:
    """Runs the command line's sweep (prepare, run, write); returns the varied names, the
    measured nodes, the rows and the charts that could not be drawn. A refusal raises
    ``ValueError(message, problems)``."""

def cli(args: Sequence[str]) -> int:
    """Runs the command line (``mesoflow ARGS…``) in this process; returns its exit code."""
