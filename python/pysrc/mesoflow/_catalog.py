"""The kinds the engine knows (built-in and ``@mesoflow.node``), with their ports and parameter
schemas, for checks in Python and for :func:`describe`."""

from __future__ import annotations

import json
from typing import Any, Dict, List, Optional

from . import _native

_cache: Dict[str, Any] = {}


def _invalidate() -> None:
    _cache.clear()


def _signatures() -> Dict[str, Dict[str, Any]]:
    if "sigs" not in _cache:
        _cache["sigs"] = {s["kind"]: s for s in json.loads(_native.catalog())}
    return _cache["sigs"]


def kinds() -> List[str]:
    """Every kind a graph run from this process can use."""
    return sorted(_signatures())


def signature(kind: str) -> Optional[Dict[str, Any]]:
    """A kind's signature (``kind``, ``version``, ``doc``, ``inputs``, ``outputs``, ``params``
    as JSON Schema), or ``None`` for an unknown kind."""
    return _signatures().get(kind)


def describe(kind: str) -> str:
    """A kind's documentation: what it does, its ports and its parameters."""
    sig = signature(kind)
    if sig is None:
        raise KeyError(f"unknown kind `{kind}`")
    lines = [f"{kind} (version {sig['version']}, {sig['device']})", "", sig["doc"], ""]
    if sig["inputs"]:
        lines.append("inputs:")
        for i in sig["inputs"]:
            opt = "" if i["required"] else ", optional"
            lines.append(f"  {i['name']}: {i['type']}{opt}  {i['doc']}")
    lines.append("outputs:")
    for o in sig["outputs"]:
        lines.append(f"  {o['name']}: {o['type']}  {o['doc']}")
    props = sig["params"].get("properties", {})
    if props:
        lines.append("parameters:")
        for name, p in props.items():
            default = f" = {json.dumps(p['default'])}" if "default" in p else ""
            lines.append(f"  {name}{default}  {p.get('description', '')}".rstrip())
    return "\n".join(lines)
