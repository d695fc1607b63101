"""Graphs from Python: build or load a graph file, check it as ``mesoflow validate`` does, run it
on the engine and get numpy arrays back."""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._catalog import signature
from ._arrays import real_array
from ._errors import GraphError, NodeError

PathLike = Union[str, "os.PathLike[str]"]

#: Where arrays given as parameters are stored, relative to the graph's folder.
ARRAYS_DIR = os.path.join(".mesoflow", "arrays")

_ID = re.compile(r"^[a-z][a-z0-9_]*$")


class Output:
    """One output port of a node (``node["port"]``): connect it to another node's input by
    passing it to :meth:`Graph.add`, or ask for it in :meth:`Graph.run`."""

    __slots__ = ("node", "port")

    def __init__(self, node: str, port: str) -> None:
        self.node = node
        self.port = port

    def __str__(self) -> str:
        return f"{self.node}.{self.port}"

    def __repr__(self) -> str:
        return f"<mesoflow output {self.node}.{self.port}>"


class Node:
    """A node of a :class:`Graph`. ``node["port"]`` is one of its outputs."""

    def __init__(self, graph: "Graph", id: str) -> None:
        self.graph = graph
        self.id = id

    @property
    def kind(self) -> str:
        return self.graph._nodes[self.id]["kind"]

    @property
    def params(self) -> Dict[str, Any]:
        return dict(self.graph._nodes[self.id].get("params", {}))

    def __getitem__(self, port: str) -> Output:
        sig = signature(self.kind)
        names = [o["name"] for o in sig["outputs"]] if sig else []
        if sig is not None and port not in names:
            raise KeyError(
                f"node `{self.id}` ({self.kind}) has no output `{port}`; it has {', '.join(names)}"
            )
        return Output(self.id, port)

    def __repr__(self) -> str:
        return f"<mesoflow node {self.id} ({self.kind})>"


def _array_bytes(a: np.ndarray) -> bytes:
    """The NPY bytes of an array, f32 or f64, C order (what the array kinds read); real numbers
    only (``real_array``)."""
    a = real_array(a, a.dtype if a.dtype in (np.float32, np.float64) else np.float64)
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


class Graph:
    """A pipeline: nodes of built-in (or ``@mesoflow.node``) kinds, connected output to input.

    ``Graph()`` starts an empty one whose relative paths resolve against ``base_dir`` (default:
    the current folder); :func:`load` reads a graph file. Every :meth:`add` is checked at once.
    """

    def __init__(
        self,
        description: str = "",
        *,
        base_dir: Optional[PathLike] = None,
        name: str = "graph",
    ) -> None:
        self.description = description
        self.base_dir = Path(base_dir) if base_dir is not None else Path(".")
        self.name = name
        self._nodes: Dict[str, Dict[str, Any]] = {}
        self._extra: Dict[str, Any] = {}

    # -- building ---------------------------------------------------------------------------

    def _fresh_id(self, kind: str) -> str:
        stem = re.sub(r"[^a-z0-9_]", "_", kind.rsplit(".", 1)[-1].lower()) or "node"
        if not stem[0].isalpha():
            stem = "n" + stem
        if stem not in self._nodes:
            return stem
        i = 2
        while f"{stem}_{i}" in self._nodes:
            i += 1
        return f"{stem}_{i}"

    def _store_array(self, a: np.ndarray) -> str:
        data = _array_bytes(np.asarray(a))
        digest = hashlib.sha256(data).hexdigest()[:32]
        rel = os.path.join(ARRAYS_DIR, f"{digest}.npy")
        path = self.base_dir / rel
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(data)
            os.replace(tmp, path)
        return rel.replace(os.sep, "/")

    def add(self, kind: str, id: Optional[str] = None, /, **arguments: Any) -> Node:
        """Adds a node of ``kind`` and checks it (raises :class:`GraphError` naming the node and
        the parameter or port). Each keyword is an input port when given an :class:`Output`
        (``other["port"]``), else a parameter; a numpy array as a parameter (``data=X``) is
        stored by content under ``.mesoflow/arrays`` and the parameter names that file, so the
        same array gives the same cache key in every run."""
        if id is None:
            id = self._fresh_id(kind)
        if not isinstance(id, str) or not _ID.match(id):
            raise GraphError(
                [(id if isinstance(id, str) else None, None,
                  f"node id `{id}` is invalid: ids match [a-z][a-z0-9_]*")]
            )
        if id in self._nodes:
            raise GraphError([(id, None, f"node id `{id}` is defined more than once")])
        sig = signature(kind)
        input_names = {i["name"] for i in sig["inputs"]} if sig else set()
        inputs: Dict[str, str] = {}
        params: Dict[str, Any] = {}
        for key, value in arguments.items():
            if isinstance(value, Output):
                inputs[key] = str(value)
            elif isinstance(value, Node):
                raise GraphError(
                    [(id, key, f"`{key}` is given node `{value.id}`; connect one of its "
                      f"outputs, e.g. {value.id}[\"{_first_output(value.kind)}\"]")]
                )
            elif key in input_names and isinstance(value, str) and "." in value:
                inputs[key] = value
            elif isinstance(value, np.ndarray):
                params[key] = self._store_array(value)
            else:
                params[key] = _jsonable(value, id, key)
        decl: Dict[str, Any] = {"kind": kind}
        if inputs:
            decl["inputs"] = inputs
        if params:
            decl["params"] = params
        self._nodes[id] = decl
        try:
            self.validate()
        except GraphError:
            del self._nodes[id]
            raise
        return Node(self, id)

    def remove(self, id: str) -> None:
        """Removes a node (and nothing else: inputs that named it become errors on run)."""
        del self._nodes[id]

    def set(self, target: str, value: Any) -> None:
        """Sets ``"node.param"`` (or ``"node.param.field"`` inside an object parameter), checked
        like ``--set``."""
        node, _, path = target.partition(".")
        head, slash, inner = node.partition("/")
        if slash and path and self._nodes.get(head, {}).get("kind") == "graph":
            # `sub/inner.param`: a parameter inside the subgraph `sub`, kept in its `set`.
            old = json.loads(json.dumps(self._nodes[head]))
            sets = self._nodes[head].setdefault("params", {}).setdefault("set", {})
            sets[f"{inner}.{path}"] = _jsonable(value, node, path)
            try:
                self.validate()
            except GraphError:
                self._nodes[head] = old
                raise
            return
        if node not in self._nodes or not path:
            raise GraphError([(node or None, None, f"set {target}: no node `{node}`")])
        old = json.loads(json.dumps(self._nodes[node]))
        params = self._nodes[node].setdefault("params", {})
        keys = path.split(".")
        here = params
        for k in keys[:-1]:
            here = here.setdefault(k, {})
        here[keys[-1]] = self._store_array(value) if isinstance(value, np.ndarray) else _jsonable(value, node, path)
        try:
            self.validate()
        except GraphError:
            self._nodes[node] = old
            raise

    def _run_settings(
        self, set: Optional[Mapping[str, Any]], cache_dir: Optional[PathLike], use_cache: bool
    ) -> Tuple[List[str], Optional[str]]:
        """The ``--set``s of a run (checked) and its cache folder, as the command line chooses it:
        ``cache_dir``, else ``MESOFLOW_CACHE``, else ``.mesoflow/cache`` beside the graph; none
        without the cache."""
        if set:
            self._check_sets(set)
        sets = [f"{k}={json.dumps(v)}" for k, v in (set or {}).items()]
        if not use_cache:
            return sets, None
        cache = cache_dir if cache_dir is not None else os.environ.get("MESOFLOW_CACHE")
        return sets, str(cache) if cache else str(self.base_dir / ".mesoflow" / "cache")

    def _check_sets(self, sets: Mapping[str, Any]) -> None:
        """Checks ``run``'s ``set`` on a copy as :meth:`set` checks one value: an invalid one
        raises :class:`GraphError` naming the node and parameter, and this graph is unchanged."""
        trial = Graph(self.description, base_dir=self.base_dir, name=self.name)
        trial._nodes = json.loads(json.dumps(self._nodes))
        trial._extra = dict(self._extra)
        for target, value in sets.items():
            trial.set(target, value)

    def __getitem__(self, id: str) -> Node:
        if id not in self._nodes:
            raise KeyError(f"no node `{id}`; nodes are {', '.join(self._nodes)}")
        return Node(self, id)

    def __contains__(self, id: object) -> bool:
        return id in self._nodes

    def __iter__(self) -> Iterator[Node]:
        return (Node(self, i) for i in list(self._nodes))

    def __len__(self) -> int:
        return len(self._nodes)

    def __repr__(self) -> str:
        return f"<mesoflow graph {self.name}: {len(self._nodes)} nodes>"

    # -- the graph file ------------------------------------------------------------------------

    def to_dict(self) -> Dict[str, Any]:
        # Version 2 only where it is needed (an `interface`), so files stay readable by older
        # mesoflow otherwise.
        d: Dict[str, Any] = {"mesoflow": 2 if "interface" in self._extra else 1}
        if self.description:
            d["description"] = self.description
        d.update(self._extra)
        d["nodes"] = json.loads(json.dumps(self._nodes))
        return d

    def to_json(self) -> str:
        """The graph file's text (format version 1, or 2 with an ``interface``), as ``mesoflow
        run`` reads it."""
        return json.dumps(self.to_dict(), indent=2, ensure_ascii=False) + "\n"

    def save(self, path: PathLike) -> Path:
        """Writes the graph file. Arrays given as parameters are copied beside it (under
        ``.mesoflow/arrays``) when it goes to another folder, so the file runs as it is."""
        path = Path(path)
        folder = path.parent if str(path.parent) else Path(".")
        folder.mkdir(parents=True, exist_ok=True)
        if folder.resolve() != self.base_dir.resolve():
            for rel in self._array_files():
                src = self.base_dir / rel
                dst = folder / rel
                if src.exists() and not dst.exists():
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(src, dst)
        path.write_text(self.to_json(), encoding="utf-8")
        return path

    def _array_files(self) -> List[str]:
        prefix = ARRAYS_DIR.replace(os.sep, "/") + "/"
        out = []
        for decl in self._nodes.values():
            for v in _leaves(decl.get("params", {})):
                if isinstance(v, str) and v.startswith(prefix):
                    out.append(v)
        return out

    def validate(self) -> None:
        """Checks the whole graph as ``mesoflow validate`` does; raises :class:`GraphError`."""
        errors = _native.validate(self.to_json(), self.name, str(self.base_dir))
        if errors:
            raise GraphError(errors)

    # -- running -------------------------------------------------------------------------------

    def run(
        self,
        outputs: Optional[Sequence[Union[str, Output]]] = None,
        *,
        device: str = "auto",
        cache_dir: Optional[PathLike] = None,
        set: Optional[Mapping[str, Any]] = None,
        out_dir: Optional[PathLike] = None,
        use_cache: bool = True,
        verify_cache: bool = False,
        check: bool = True,
        progress: Union[bool, Callable[[str, str, str, int, int], None], None] = None,
    ) -> "Result":
        """Runs the graph on the engine, as ``mesoflow run`` does, and returns the values.

        ``outputs``: ``"node.port"`` strings or :class:`Output` s; by default every output of
        the sinks. ``device``: ``"auto"``, ``"cpu"`` or ``"gpu"``. ``cache_dir``: the disk cache
        (default ``$MESOFLOW_CACHE``, else ``.mesoflow/cache`` in the graph's folder).
        ``set``: ``{"node.param": value}`` for this run only. ``out_dir``: where files and
        ``report.json`` go (default ``out/<name>``, as the command line). With ``check`` a
        failed node raises :class:`NodeError`; the report is on the exception. ``progress``:
        ``True`` prints each node's start, progress (in 5% steps) and end to stderr; a callable
        receives ``(event, node, detail, done, total)`` with event ``"started"`` (detail: the
        device), ``"progress"`` or ``"finished"`` (detail: the status).

        The GIL is released while the engine runs; Ctrl-C cancels the run and raises
        ``KeyboardInterrupt`` once it has stopped (``report.json`` is still written).
        """
        outs = [str(o) for o in (outputs or [])]
        sets, cache = self._run_settings(set, cache_dir, use_cache)
        out = Path(out_dir) if out_dir is not None else Path("out") / Path(self.name).stem
        report_text, values = _native.run(
            self.to_json(),
            self.name,
            str(self.base_dir),
            str(out),
            outs,
            sets,
            device=device,
            cache_dir=cache,
            use_cache=use_cache,
            verify_cache=verify_cache,
            progress=_printer if progress is True else (progress or None),
        )
        result = Result(json.loads(report_text), values, out)
        if check and not result.ok:
            raise NodeError(result.report)
        return result


def _printer(event: str, node: str, detail: str, done: int, total: int) -> None:
    if event == "started":
        print(f"  {node}: started ({detail})", file=sys.stderr)
    elif event == "progress":
        print(f"  {node}: {100 * done / max(total, 1):.0f}%", file=sys.stderr)
    else:
        print(f"  {node}: {detail}", file=sys.stderr)


def _first_output(kind: str) -> str:
    sig = signature(kind)
    return sig["outputs"][0]["name"] if sig and sig["outputs"] else "port"


def _leaves(v: Any) -> Iterable[Any]:
    if isinstance(v, dict):
        for x in v.values():
            yield from _leaves(x)
    elif isinstance(v, list):
        for x in v:
            yield from _leaves(x)
    else:
        yield v


def _jsonable(v: Any, node: str, param: str) -> Any:
    """A parameter value as JSON (numpy scalars and tuples included)."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_jsonable(x, node, param) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x, node, param) for k, x in v.items()}
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    raise GraphError([(node, param, f"node `{node}`: parameter `{param}`: a {type(v).__name__} "
                       "is not a JSON value (numbers, strings, lists, dicts, numpy arrays)")])


class Result(Mapping):
    """What :meth:`Graph.run` returns: ``result["node.port"]`` is a value (a numpy array in
    ``npy.write``'s layout, read-only and without a copy; a float for scalars; ``{path: bytes}``
    for files), ``result.report`` the run report as a dict (``report.json``)."""

    def __init__(self, report: Dict[str, Any], values: Dict[str, Any], out_dir: Path) -> None:
        self.report = report
        self._values = values
        self.out_dir = out_dir

    @property
    def ok(self) -> bool:
        return bool(self.report.get("ok"))

    def node(self, id: str) -> Dict[str, Any]:
        """The report's entry for one node (status, seconds, key, metrics, timings)."""
        for n in self.report.get("nodes", []):
            if n["id"] == id:
                return n
        raise KeyError(f"node `{id}` is not in the report (not needed, or not in the graph)")

    def metrics(self, id: str) -> Dict[str, float]:
        return dict(self.node(id).get("metrics", {}))

    def __getitem__(self, key: Union[str, Output]) -> Any:
        key = str(key)
        if key not in self._values:
            raise KeyError(
                f"{key}: not among this run's values ({', '.join(self._values) or 'none'}); "
                "ask for it with run(outputs=[...])"
            )
        return self._values[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        status = "ok" if self.ok else "failed"
        return f"<mesoflow result {status}, {self.report.get('seconds', 0):.2f} s: {', '.join(self._values)}>"


def load(path: PathLike) -> Graph:
    """Reads a graph file; its relative paths keep resolving against its folder."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    errors = _native.validate(text, str(path), str(Path(path).parent))
    try:
        d = json.loads(text)
    except json.JSONDecodeError:
        raise GraphError(errors) from None
    g = Graph(d.get("description", ""), base_dir=path.parent if str(path.parent) else ".", name=str(path))
    g._nodes = d.get("nodes", {}) if isinstance(d.get("nodes"), dict) else {}
    g._extra = {k: v for k, v in d.items() if k not in ("mesoflow", "description", "nodes")}
    if errors:
        raise GraphError(errors)
    return g

