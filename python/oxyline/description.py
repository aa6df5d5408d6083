"""A model description as the user hands it over (nested dicts, lists and plain values): the
private copy a :class:`~oxyline.Model` owns as its ``source``."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

_ATOMS = frozenset({str, int, float, bool, type(None)})


def copy_description(data: Any) -> Any:
    """Deep copy of a model description: dicts and lists (tuples become lists) are rebuilt,
    plain values shared, anything else (arrays, ...) deep-copied. A quarter of the cost of a JSON
    round trip on 10^5-vessel models and linear in their size."""
    t = type(data)
    # a dict or list of plain values only (a vessel, a waveform table) is copied in C
    if t is dict:
        if _ATOMS.issuperset(map(type, data.values())):
            return data.copy()
        return {k: v if type(v) in _ATOMS else copy_description(v) for k, v in data.items()}
    if t is list or t is tuple:
        if _ATOMS.issuperset(map(type, data)):
            return list(data)
        return [v if type(v) in _ATOMS else copy_description(v) for v in data]
    if t in _ATOMS:
        return data
    if isinstance(data, Mapping):
        return {k: copy_description(v) for k, v in data.items()}
    return copy.deepcopy(data)
