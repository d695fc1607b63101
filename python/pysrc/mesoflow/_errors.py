"""The package's exceptions."""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Tuple


class MesoflowError(Exception):
    """Base of mesoflow's exceptions."""


class GraphError(MesoflowError):
    """A graph that ``mesoflow validate`` would refuse. ``errors`` lists ``(node, field,
    message)``; ``node`` and ``field`` (a parameter or port) are those of the first error."""

    def __init__(self, errors: Sequence[Tuple[Optional[str], Optional[str], str]]) -> None:
        self.errors: List[Tuple[Optional[str], Optional[str], str]] = [tuple(e) for e in errors]  # type: ignore[misc]
        first = self.errors[0] if self.errors else (None, None, "invalid graph")
        self.node: Optional[str] = first[0]
        self.field: Optional[str] = first[1]
        super().__init__("\n".join(e[2] for e in self.errors))


class NodeError(MesoflowError):
    """A run in which a node failed. ``node`` is the first failed node's id, ``report`` the run
    report (a dict, as in ``report.json``)."""

    def __init__(self, report: Dict[str, Any]) -> None:
        self.report = report
        failed = [n for n in report.get("nodes", []) if n.get("status") == "failed"]
        self.node: Optional[str] = failed[0]["id"] if failed else None
        lines = [n.get("error", f"node `{n['id']}` failed") for n in failed]
        if not lines:
            lines = ["the run did not complete"]
        super().__init__("\n".join(lines))
