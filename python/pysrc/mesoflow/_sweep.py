"""``mesoflow.sweep``: one run per combination of parameter values, on one engine, writing the
same ``sweep.csv`` and charts as ``mesoflow sweep``: the command line's own sweep prepares,
checks, runs and writes it (``_native.sweep``); this module turns its rows into dicts."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence, Union

from . import _native
from ._errors import GraphError
from ._graph import Graph, Output, PathLike


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
    ``runs/NNN/report.json`` under ``out_dir`` (default ``out/<name>/sweep``, as the command line and the studio).

    Returns the rows, the columns of ``sweep.csv`` (a list of dicts; a pandas DataFrame when
    pandas is installed). Every combination is checked before any runs (GraphError); a grid of
    more than ``max_runs`` runs is refused before any is made (ValueError).
    """
    measures = [str(m) for m in measure]
    names = list(vary)
    sets, cache = graph._run_settings(set, cache_dir, use_cache)
    out = Path(out_dir) if out_dir is not None else Path("out") / Path(graph.name).stem / "sweep"
    try:
        names, measured_nodes, native_rows, problems = _native.sweep(
            graph.to_json(),
            graph.name,
            str(graph.base_dir),
            str(out),
            [(n, json.dumps(list(vary[n]))) for n in names],
            measures,
            [str(x) for x in versus],
            sets,
            max_runs,
            device=device,
            cache_dir=cache,
            use_cache=use_cache,
            progress=progress,
        )
    except ValueError as e:
        if len(e.args) == 2 and e.args[1]:
            raise GraphError(e.args[1]) from None
        raise ValueError(e.args[0]) from None
    for p in problems:
        print(f"warning: charts not written: {p}", file=sys.stderr)
    rows = []
    for values, ms, secs, run_seconds, ok in native_rows:
        row: Dict[str, Any] = dict(zip(names, json.loads(values)))
        row.update(zip(measures, ms))
        for n, s in zip(measured_nodes, secs):
            if f"{n}.seconds" not in measures:
                row[f"{n}.seconds"] = s
        row["run_seconds"] = run_seconds
        row["ok"] = ok
        rows.append(row)
    try:
        import pandas  # noqa: F401
    except ImportError:
        return rows
    return pandas.DataFrame(rows)
