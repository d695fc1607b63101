"""``mesoflow.sweep``: one run per combination of parameter values, on one engine, writing the
same ``sweep.csv`` and charts as ``mesoflow sweep`` (through the same Rust code)."""

from __future__ import annotations

import itertools
import json
import os
import sys
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

from . import _native
from ._catalog import signature
from ._errors import GraphError
from ._graph import Graph, Output, PathLike


def _cell(v: Any) -> str:
    return v if isinstance(v, str) else json.dumps(v)


def sweep(
    graph: Graph,
    vary: Mapping[str, Sequence[Any]],
    measure: Sequence[Union[str, Output]],
    *,
    versus: Sequence[Union[str, Output]] = (),
    out_dir: Optional[PathLike] = None,
    device: str = "auto",
    cache_dir: Optional[PathLike] = None,
    use_cache: bool = True,
    set: Optional[Mapping[str, Any]] = None,
    progress: bool = True,
    max_runs: int = 10_000,
) -> Any:
    """Runs ``graph`` for every combination of ``vary`` (``{"node.param": [values]}``), in
    order, and measures scalar outputs or timings (``"node.port"``; ``"node.seconds"`` is the
    node's compute time). Writes ``sweep.csv``, the charts (each measure against each varied
    parameter and against its node's time; against each ``versus`` measure) and each run's
    ``runs/NNN/report.json`` under ``out_dir`` (default ``out/<name>-sweep``).

    Returns the rows, the columns of ``sweep.csv`` (a list of dicts; a pandas DataFrame when
    pandas is installed). Every combination is checked before any runs (GraphError); a grid of
    more than ``max_runs`` runs is refused before any is made (ValueError).
    """
    measures = [str(m) for m in measure]
    versus_ = [str(x) for x in versus]
    for x in versus_:
        if x not in measures:
            raise ValueError(f"versus {x}: measure it too (measure=[..., {x!r}])")
    names = list(vary)
    values = [list(vary[n]) for n in names]
    if any(not v for v in values):
        raise ValueError("vary: every parameter needs at least one value")
    runs = 1
    for v in values:
        runs *= len(v)
    if runs > max_runs:
        sizes = " × ".join(str(len(v)) for v in values)
        raise ValueError(
            f"vary: the values make {runs} runs ({sizes}), more than max_runs={max_runs}: "
            "vary fewer values, or raise max_runs"
        )
    combos = list(itertools.product(*values))

    graphs: List[Graph] = []
    for combo in combos:
        g = Graph(graph.description, base_dir=graph.base_dir, name=graph.name)
        g._nodes = json.loads(json.dumps(graph._nodes))
        g._extra = dict(graph._extra)
        for k, v in (set or {}).items():
            g.set(k, v)
        for n, v in zip(names, combo):
            g.set(n, v)
        graphs.append(g)

    # Measured outputs and the sinks' first outputs are asked for; a timing's node is asked for
    # through its first output (as the command line does).
    base = graphs[0]
    measured_nodes: List[str] = []
    outputs: List[str] = []
    for m in measures:
        node, _, port = m.partition(".")
        if node not in base._nodes:
            raise GraphError([(node, None, f"measure {m}: no node `{node}` in the graph")])
        if node not in measured_nodes:
            measured_nodes.append(node)
        sig = signature(base._nodes[node]["kind"]) or {"outputs": [], "timings": []}
        out = {o["name"]: o["type"] for o in sig["outputs"]}
        timing = port == "seconds" or any(t["name"] == port for t in sig.get("timings", []))
        if out.get(port) == "Scalar":
            outputs.append(m)
        elif timing:
            if sig["outputs"]:
                outputs.append(f"{node}.{sig['outputs'][0]['name']}")
        elif port in out:
            raise GraphError([(node, port, f"measure {m}: `{port}` is a {out[port]}; a measure must be a scalar output")])
        else:
            have = [o for o, t in out.items() if t == "Scalar"] + [t["name"] for t in sig.get("timings", [])] + ["seconds"]
            raise GraphError([(node, port, f"measure {m}: `{node}` has no scalar output or timing `{port}`; it has {', '.join(have)}")])
    consumed = {v.split(".")[0] for d in base._nodes.values() for v in d.get("inputs", {}).values()}
    for node, decl in base._nodes.items():
        if node not in consumed:
            sig = signature(decl["kind"])
            if sig and sig["outputs"]:
                outputs.append(f"{node}.{sig['outputs'][0]['name']}")

    out = Path(out_dir) if out_dir is not None else Path("out") / f"{Path(graph.name).stem}-sweep"
    rows = []
    native_rows = []
    for i, (combo, g) in enumerate(zip(combos, graphs)):
        r = g.run(
            outputs,
            device=device,
            cache_dir=cache_dir,
            out_dir=out / "runs" / f"{i:03}",
            use_cache=use_cache,
            check=False,
        )
        nodes = {n["id"]: n for n in r.report["nodes"]}

        def measured(m: str) -> Optional[float]:
            node, _, port = m.partition(".")
            n = nodes.get(node)
            if n is None:
                return None
            v = n.get("metrics", {}).get(port, n.get("timings", {}).get(port))
            return None if v is None else float(v)

        ms = [measured(m) for m in measures]
        secs = [nodes.get(n, {}).get("timings", {}).get("seconds") for n in measured_nodes]
        row: Dict[str, Any] = dict(zip(names, combo))
        row.update(zip(measures, ms))
        for n, s in zip(measured_nodes, secs):
            if f"{n}.seconds" not in measures:
                row[f"{n}.seconds"] = s
        row["run_seconds"] = r.report["seconds"]
        row["ok"] = r.ok
        rows.append(row)
        native_rows.append((json.dumps(list(combo)), ms, secs, float(r.report["seconds"]), r.ok))
        if progress:
            label = " ".join(f"{n}={_cell(v)}" for n, v in zip(names, combo))
            shown = " ".join(f"{m}={v:.4e}" if v is not None else f"{m}=—" for m, v in zip(measures, ms))
            print(f"[{i + 1}/{len(combos)}] {label}: {'ok' if r.ok else 'FAILED'} in "
                  f"{r.report['seconds']:.2f} s; {shown}", file=sys.stderr)
    problems = _native.write_sweep(
        str(out),
        [(n, json.dumps(v)) for n, v in zip(names, values)],
        measures,
        measured_nodes,
        versus_,
        native_rows,
    )
    for p in problems:
        print(f"warning: charts not written: {p}", file=sys.stderr)
    try:
        import pandas  # noqa: F401
    except ImportError:
        return rows
    return pandas.DataFrame(rows)
