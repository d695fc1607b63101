"""``mesoflow.plan``: the planner on a graph, from Python, as ``mesoflow plan`` does it."""

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Union

from . import _native
from ._errors import GraphError
from ._graph import Graph, load

PathLike = Union[str, Path]


def plan_file(planned: Path) -> Path:
    """Where the plan of the planned graph at ``planned`` goes: beside it, named after it, as the
    command line names it (``src/commands/plan.rs``, ``plan_file``)."""
    stem = planned.name[:-5] if planned.name.endswith(".json") else planned.name
    stem = stem[: -len(".planned")] if stem.endswith(".planned") else stem
    return planned.with_name(stem + ".plan.json")


@dataclass(frozen=True)
class Decision:
    """One stage's choice: ``stage`` (``btf``, ``mdf``, ``sss``, ``shadows``, ``synthesis``…),
    ``choice`` (what was chosen, as ``<graph>.plan.json`` holds it), ``reason``, and the error and cost
    the measured model predicts (``None`` where it has nothing to say: unknown, never 0)."""

    stage: str
    choice: Any
    reason: str
    predicted_error: Optional[float]
    predicted_cost: Optional[Dict[str, Any]]


class Plan:
    """A planned view: :attr:`graph` (the graph with the decisions applied, ready to
    :meth:`Graph.run`), :attr:`decisions`, :attr:`predicted_error` (the stages' sum, ``None``
    when one is unknown), :attr:`scene` (what the probe measured), :attr:`budget`, :attr:`ppd`,
    and :attr:`doc`, the whole ``<graph>.plan.json`` document."""

    def __init__(self, doc: Dict[str, Any], graph: Graph) -> None:
        self.doc = doc
        self.graph = graph
        self.decisions: List[Decision] = [
            Decision(
                d["stage"],
                d["choice"],
                d["reason"],
                d.get("predicted_error"),
                d.get("predicted_cost"),
            )
            for d in doc["decisions"]
        ]
        self.predicted_error: Optional[float] = doc.get("predicted_error")
        self.scene: Dict[str, Any] = doc["scene"]
        self.budget: float = doc["budget"]["flip"]
        self.ppd: float = doc["budget"]["ppd"]
        #: What the probes of the view measured (``None`` with ``probe_budget=0``): each
        #: candidate's probed FLIP and frame beside the graph's, which was kept, and why.
        self.probe: Optional[Dict[str, Any]] = doc.get("probe")
        #: The kept plan's FLIP against the graph on the probe (0 for the graph itself).
        self.probed_error: Optional[float] = doc.get("probed_error")
        #: Wall time of the whole plan, s.
        self.plan_seconds: Optional[float] = (self.probe or {}).get("plan_seconds")

    def save(self, path: PathLike) -> Path:
        """Writes the planned graph to ``path`` and its plan beside it, named after it
        (``near.json`` → ``near.plan.json``, ``torus.planned.json`` → ``torus.plan.json``), as
        ``mesoflow plan -o path`` does."""
        path = self.graph.save(path)
        doc = dict(self.doc, planned=str(path))
        plan_file(path).write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
        return path

    def __repr__(self) -> str:
        e = "unknown" if self.predicted_error is None else f"{self.predicted_error:.4f}"
        stages = ", ".join(f"{d.stage}: {json.dumps(d.choice)}" for d in self.decisions)
        probed = "" if self.probed_error is None else f", probed {self.probed_error:.4f}"
        return f"<mesoflow plan at FLIP {self.budget} (predicted {e}{probed}): {stages}>"


class TruthPlan:
    """A plan judged against the truth (``against="truth"``): :attr:`graph` (the render node
    replaced by the chosen candidate, ready to :meth:`Graph.run`), :attr:`candidates` (each
    ``candidate``, ``family`` — ``model`` or ``brute force`` —, ``kind``, ``params``,
    ``relative_rmse`` (or ``flip``) against the truth probe, ``probe_seconds``, ``full_seconds_estimate``,
    ``within_budget``, and where so ``note`` and ``warnings``), :attr:`chosen` (its name),
    :attr:`why`, :attr:`judge_why` (what the truth is), :attr:`truth` (its samples a pixel and
    noise), :attr:`budget` (relative RMSE), :attr:`plan_seconds` and :attr:`doc`, the whole
    ``<graph>.plan.json`` document."""

    def __init__(self, doc: Dict[str, Any], graph: Graph) -> None:
        self.doc = doc
        self.graph = graph
        self.candidates: List[Dict[str, Any]] = doc["candidates"]
        self.chosen: Optional[str] = doc.get("chosen")
        self.why: str = doc["why"]
        self.judge_why: str = doc["judge_why"]
        self.truth: Dict[str, Any] = doc["truth"]
        #: The budget and its measure: ``relative_rmse``, or ``flip`` (with ``ppd``).
        self.measure: str = "flip" if "flip" in doc["budget"] else "relative_rmse"
        self.budget: float = doc["budget"][self.measure]
        self.plan_seconds: float = doc["plan_seconds"]

    def save(self, path: PathLike) -> Path:
        """Writes the planned graph to ``path`` and its plan beside it, as :meth:`Plan.save`."""
        path = self.graph.save(path)
        doc = dict(self.doc, planned=str(path))
        plan_file(path).write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
        return path

    def __repr__(self) -> str:
        what = "mean FLIP" if self.measure == "flip" else "relative RMSE"
        return f"<mesoflow plan against the truth at {what} {self.budget}: {self.chosen}>"


def plan(
    graph: Union[Graph, PathLike],
    render: str,
    budget: float = 0.05,
    *,
    against: Optional[str] = None,
    measure: str = "rmse",
    ppd: Optional[float] = None,
    split: str = "joint",
    device: str = "auto",
    cache_dir: Optional[PathLike] = None,
    use_cache: bool = True,
    set: Optional[Mapping[str, Any]] = None,
    probe_budget: float = 1.0,
    probe_share: Optional[float] = None,
) -> Plan:
    """Plans node ``render`` of ``graph`` (a :class:`Graph` or a graph file's path) for a FLIP
    ``budget`` (mean FLIP over the object's pixels) at ``ppd`` pixels per degree (FLIP's default
    67 when ``None``): measures the view with the render's own camera and data on the engine and
    cache that :meth:`Graph.run` uses, then picks each stage's cheapest model predicted within
    its share, then proves the plan on a probe of the view (the frame's centre ``probe_share``,
    at the same pixels per degree): each candidate rendered beside the graph, kept only within
    the budget and no slower, stepped up until one is, else the graph itself; the probes may
    spend ``probe_budget`` renders of the full view (0: no probe, the measured model alone).
    Raises :class:`GraphError` for an invalid graph or render node, ``ValueError`` for
    a plan that cannot be made (camera inside the mesh, a bad budget), ``RuntimeError`` when the
    view cannot be measured.

    With ``against="truth"`` (``mesoflow plan --against truth``) ``budget`` is a relative RMSE
    against the truth the graph makes (an ``sss.render``'s mesh filled with its medium, a
    ``render.mesh``'s captured height field displaced), every candidate — the render as given,
    its model switches, brute force — is measured against it on a probe of the view, and the
    fastest within the budget is planned: a :class:`TruthPlan`; with ``measure="flip"`` the
    budget is a mean FLIP against the truth at ``ppd`` (FLIP's 67 when ``None``). ``split`` and
    ``probe_budget`` do not apply there. ``probe_share`` is 0.25 by default, 0.1 against the
    truth (its truth probe costs about 7.3 times that share of a brute-force frame)."""
    if against not in (None, "truth"):
        raise ValueError(f"against={against!r}: None (the graph's own model) or \"truth\"")
    if measure not in ("rmse", "flip"):
        raise ValueError(f"measure={measure!r}: \"rmse\" or \"flip\"")
    if measure == "flip" and against != "truth":
        raise ValueError("measure=\"flip\" goes with against=\"truth\" (against the graph's own model the budget is FLIP already)")
    g = graph if isinstance(graph, Graph) else load(graph)
    sets = [f"{k}={json.dumps(v)}" for k, v in (set or {}).items()]
    errors = _native.validate(g.to_json(), g.name)
    if errors:
        raise GraphError(errors)
    if use_cache:
        import os

        cache = cache_dir if cache_dir is not None else os.environ.get("MESOFLOW_CACHE")
        cache = str(cache) if cache else str(g.base_dir / ".mesoflow" / "cache")
    else:
        cache = None
    if against == "truth":
        doc_text, planned_text = _native.plan_truth(
            g.to_json(),
            g.name,
            str(g.base_dir),
            render,
            float(budget),
            sets,
            device=device,
            cache_dir=cache,
            use_cache=use_cache,
            probe_share=0.1 if probe_share is None else float(probe_share),
            measure=measure,
            ppd=None if ppd is None else float(ppd),
        )
        return TruthPlan(json.loads(doc_text), _planned_graph(planned_text, g))
    doc_text, planned_text = _native.plan(
        g.to_json(),
        g.name,
        str(g.base_dir),
        render,
        float(budget),
        sets,
        ppd=ppd,
        split=split,
        device=device,
        cache_dir=cache,
        use_cache=use_cache,
        probe_budget=float(probe_budget),
        probe_share=0.25 if probe_share is None else float(probe_share),
    )
    return Plan(json.loads(doc_text), _planned_graph(planned_text, g))


def _planned_graph(planned_text: str, g: Graph) -> Graph:
    """The planned graph's text as a :class:`Graph` beside ``g`` (its folder and name)."""
    d = json.loads(planned_text)
    planned = Graph(d.get("description", ""), base_dir=g.base_dir, name=g.name)
    planned._nodes = d.get("nodes", {})
    planned._extra = {k: v for k, v in d.items() if k not in ("mesoflow", "description", "nodes")}
    return planned
