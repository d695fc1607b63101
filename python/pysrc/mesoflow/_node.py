"""``@mesoflow.node``: a function of numpy arrays as a node kind for graphs run from Python."""

from __future__ import annotations

import hashlib
import inspect
import json
import typing
import warnings
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

import numpy as np

from ._arrays import real_array
from . import _native
from ._catalog import _invalidate

_PY_TYPES = {int: "integer", float: "number", bool: "boolean", str: "string"}


def _schema_of(annotation: Any, default: Any, fn_name: str, name: str) -> Dict[str, Any]:
    """A JSON Schema for one parameter from its type hint (or, without one, its default)."""
    if annotation is inspect.Parameter.empty:
        if default is inspect.Parameter.empty:
            raise TypeError(
                f"{fn_name}: parameter `{name}` needs a type hint or a default "
                "(or declare params={...} in @mesoflow.node)"
            )
        annotation = type(default)
    origin = typing.get_origin(annotation)
    if origin is typing.Literal:
        return {"enum": list(typing.get_args(annotation))}
    if origin in (list, tuple, typing.List, typing.Tuple):
        args = [a for a in typing.get_args(annotation) if a is not Ellipsis]
        item = _schema_of(args[0], inspect.Parameter.empty, fn_name, name) if args else {}
        return {"type": "array", "items": item}
    if origin is typing.Union:
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            s = _schema_of(args[0], inspect.Parameter.empty, fn_name, name)
            return {"anyOf": [s, {"type": "null"}]}
    if annotation in _PY_TYPES:
        return {"type": _PY_TYPES[annotation]}
    if isinstance(annotation, str):
        # `from __future__ import annotations`: the hint is text.
        text = {"int": int, "float": float, "bool": bool, "str": str}.get(annotation)
        if text is not None:
            return {"type": _PY_TYPES[text]}
    raise TypeError(
        f"{fn_name}: parameter `{name}` has type {annotation!r}; parameters are int, float, "
        "bool, str, Literal[...], list[...] or Optional[...] (or declare params={...})"
    )


def _source_hash(fn: Callable[..., Any]) -> str:
    """What identifies the function's behaviour: its source text when Python can find it, else
    its byte code and constants."""
    try:
        text = inspect.getsource(fn).encode()
    except (OSError, TypeError):
        code = fn.__code__
        text = code.co_code + repr(code.co_consts).encode()
    return hashlib.sha256(text).hexdigest()


def _to_output(value: Any, ty: str) -> Any:
    if ty == "Scalar":
        return float(value)
    if ty == "PointSet":
        return real_array(value, np.float64)
    return real_array(value, np.float32)


def node(
    kind: str,
    *,
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    version: int = 1,
    params: Optional[Mapping[str, Any]] = None,
    doc: Optional[str] = None,
    cache: bool = True,
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Registers a function as node kind ``kind`` for graphs run from this Python process.

    ``inputs`` and ``outputs`` map port names to port types (``"Image"``, ``"HeightField"``,
    ``"Scalar"``, …). The function is called with each connected input as a read-only numpy
    array (in ``npy.write``'s layout; scalars as floats) and each parameter as a keyword; an
    input whose function argument has a default is optional. It returns the output's value, or a
    dict of them for several outputs: Scalar (a float), Image ((H, W) or (H, W, C)),
    HeightField ((H, W)), NormalMap ((H, W, 3)) or PointSet ((n, D)).

    Parameters are the function's other arguments, checked from their type hints (int, float,
    bool, str, ``Literal[...]``, ``list[...]``, ``Optional[...]``) or from ``params``, a JSON
    Schema object of ``properties``. The cache key holds ``version`` and a hash of the function's
    source, so editing the function recomputes its node; ``cache=False`` keeps its results out of
    the disk cache. A warning the function issues (``warnings.warn``) goes into the run report;
    an exception fails the node with a message naming it.
    """

    def register(fn: Callable[..., Any]) -> Callable[..., Any]:
        sig = inspect.signature(fn)
        hints: Dict[str, Any] = {}
        try:
            hints = typing.get_type_hints(fn)
        except Exception:  # unresolvable hints: fall back to the raw annotations
            hints = {}
        ports: List[Tuple[str, str, bool]] = []
        for name, ty in inputs.items():
            p = sig.parameters.get(name)
            if p is None:
                raise TypeError(f"{kind}: input `{name}` is not an argument of {fn.__name__}")
            ports.append((name, ty, p.default is inspect.Parameter.empty))
        if params is not None:
            schema = {"type": "object", "properties": dict(params), "additionalProperties": False}
            defaults = {k: v["default"] for k, v in params.items() if isinstance(v, dict) and "default" in v}
            required = [k for k in params if k not in defaults]
        else:
            props: Dict[str, Any] = {}
            defaults = {}
            required = []
            for name, p in sig.parameters.items():
                if name in inputs:
                    continue
                if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                    continue
                props[name] = _schema_of(hints.get(name, p.annotation), p.default, fn.__name__, name)
                if p.default is inspect.Parameter.empty:
                    required.append(name)
                else:
                    defaults[name] = p.default
            schema = {"type": "object", "properties": props, "additionalProperties": False}
        if required:
            schema["required"] = required
        out_types = dict(outputs)
        single = next(iter(out_types)) if len(out_types) == 1 else None

        def call(args: Dict[str, Any], values: Dict[str, Any]) -> Tuple[Dict[str, Any], List[str]]:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = fn(**args, **values)
            if single is not None and not (isinstance(result, dict) and single in result):
                result = {single: result}
            if not isinstance(result, dict):
                raise TypeError(
                    f"{fn.__name__} returned a {type(result).__name__}; with several outputs it "
                    f"returns a dict with keys {', '.join(out_types)}"
                )
            converted = {k: _to_output(result[k], t) for k, t in out_types.items() if k in result}
            return converted, [str(w.message) for w in caught]

        _native.register_node(
            kind,
            int(version),
            doc or inspect.getdoc(fn) or "",
            ports,
            [(n, t) for n, t in out_types.items()],
            json.dumps(schema),
            json.dumps(defaults),
            _source_hash(fn),
            call,
            cache,
        )
        _invalidate()
        fn.kind = kind  # type: ignore[attr-defined]
        return fn

    return register
