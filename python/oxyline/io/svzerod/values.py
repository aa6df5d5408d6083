"""The checked readers of an svZeroDSolver file's values, shared by the importer's modules: a
number, a list of numbers, a required key and a block's parameters by native key, each error
naming the element and the file's key."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from oxyline.errors import ModelError


def is_comment(key: str) -> bool:
    """A ``_``-prefixed key: a comment, ignored as svZeroDSolver ignores it."""
    return isinstance(key, str) and key.startswith("_")


def required(d: Mapping[str, Any], key: str, element: str) -> Any:
    if key not in d:
        raise ModelError(f"{element}: missing '{key}'")
    return d[key]


def number(v: Any, element: str, key: str) -> float:
    """``v`` as a finite float (a JSON number; not a boolean)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ModelError(f"{element}: '{key}' must be a number, got {v!r}")
    try:
        x = float(v)
    except OverflowError:  # an integer beyond any float
        x = math.inf
    if not math.isfinite(x):
        got = x if isinstance(v, float) else f"an integer of {v.bit_length()} bits"
        raise ModelError(f"{element}: '{key}' must be finite, got {got}")
    return x


def numbers(v: Any, element: str, key: str) -> list[float]:
    if not isinstance(v, (list, tuple)):
        raise ModelError(f"{element}: '{key}' must be a list of numbers (svZeroDSolver reads "
                         f"it as an array), got {v!r}")
    return [number(x, element, f"{key}[{i}]") for i, x in enumerate(v)]


def mapped(vals: Mapping[str, Any], element: str, keys: Mapping[str, str],
           defaults: Mapping[str, float] | None = None, what: str = "") -> dict[str, float]:
    """``{native key: number}`` of the parameters ``keys`` (the file's key -> the native key)
    of ``vals``; one that is absent takes its value from ``defaults`` or is an error naming
    it (``missing <what>'<key>'``)."""
    defaults = defaults or {}
    out = {}
    for key, nat in keys.items():
        if key not in vals and key not in defaults:
            raise ModelError(f"{element}: missing {what}'{key}'")
        out[nat] = number(vals.get(key, defaults.get(key)), element, key)
    return out
