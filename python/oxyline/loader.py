"""``oxyline.load_model``: one entry point for every model source. It recognises the source
(a :class:`Model`, a dict, a file, a built-in name) and hands it on: a file to the format
registry :mod:`oxyline.io.formats` (which returns a native model dict), a name to
:mod:`oxyline.catalogue`, a mapping in another format (svZeroDSolver) to its converter;
:mod:`oxyline.model` itself only validates native dicts and imports no reader."""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from oxyline import catalogue
from oxyline.errors import ModelError, PlausibilityWarning
from oxyline.io import formats
from oxyline.io.native import read_mapping
from oxyline.memory import gc_paused
from oxyline.model import Model, _build, build_model


def load_model(source: str | os.PathLike[str] | Mapping[str, Any] | Model, *,
               check_plausibility: bool = True) -> Model:
    """Load and validate a network from a model file (any format of :mod:`oxyline.io.formats`),
    a built-in model name, or a dict. ``check_plausibility=False``: no
    :class:`~oxyline.errors.PlausibilityWarning` for values outside physiological ranges.

    >>> import oxyline
    >>> m = oxyline.load_model("bifurcation")
    >>> m.vessel_names
    ['parent', 'daughter1', 'daughter2']
    """
    if check_plausibility:
        return _load(source)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlausibilityWarning)
        return _load(source)


def _load(source: str | os.PathLike[str] | Mapping[str, Any] | Model) -> Model:
    if isinstance(source, Model):
        return source
    if not isinstance(source, (Mapping, str, os.PathLike)):
        raise ModelError(f"load_model: expected a model dict, a file path or a built-in model "
                         f"name, got {type(source).__name__} {source!r:.80}")
    if isinstance(source, Mapping):
        with _structure_errors(source):
            converted = formats.from_mapping(source)
            if converted is not None:
                return _build(converted)
            with gc_paused():
                return build_model(source)
    p = Path(source)
    if not p.exists() and not p.suffix:
        return catalogue.load(str(source))  # built-in models and examples
    claimed = formats.claimed(p)
    if claimed:
        data, _where = formats.read_native(p)
    else:  # any other suffix: a JSON mapping (read_mapping's rule), in any mapping format
        data = read_mapping(p)
    with _structure_errors(data):
        if not claimed:
            data = formats.from_mapping(data) or data
        with gc_paused():
            return _build(data)


#: deeper nesting than this is no model (the deepest native model has 6 levels)
MAX_DEPTH = 100
#: an integer beyond this has no float (IEEE double) value
_FLOAT_MAX = 2 ** 1024


def _where(path: list[Any]) -> str:
    return "model: " + ("/".join(str(k) for k in path) or "(top level)")


def structure_problem(data: Any, int_limit: int = _FLOAT_MAX) -> str | None:
    """What makes ``data`` no model at all, found without recursion (so any input can be
    looked at): a container that contains itself, nesting deeper than :data:`MAX_DEPTH`, or
    an integer of ``int_limit`` or more (default: one no float can hold). None if there is
    none. Named by the key path to it."""
    stack: list[tuple[Any, list[Any], frozenset[int]]] = [(data, [], frozenset())]
    while stack:
        value, path, above = stack.pop()
        if isinstance(value, bool):
            continue
        if isinstance(value, int) and abs(value) >= int_limit:
            return f"{_where(path)}: an integer of {value.bit_length()} bits is out of range " \
                   "(at most 2**63 for a count, a float's range for a quantity)"
        if isinstance(value, Mapping):
            items: Any = value.items()
        elif isinstance(value, (list, tuple)):
            items = enumerate(value)
        else:
            continue
        if id(value) in above:
            return f"{_where(path)}: refers to itself (a container holding itself, e.g. a " \
                   "YAML alias of an enclosing node)"
        if len(path) >= MAX_DEPTH:
            return f"{_where(path[:5])}/...: nested deeper than {MAX_DEPTH} levels"
        inner = above | {id(value)}
        stack.extend((v, [*path, k], inner) for k, v in items)
    return None


@contextlib.contextmanager
def _structure_errors(data: Any) -> Iterator[None]:
    """Turn the RecursionError or OverflowError of a self-referencing, too deeply nested or
    huge-integer input into a :class:`ModelError` naming where in the input it is."""
    try:
        yield
    except (RecursionError, OverflowError) as exc:
        problem = structure_problem(data, 2 ** 63 if isinstance(exc, OverflowError)
                                    else _FLOAT_MAX)
        raise ModelError(problem or f"model: a value out of range ({exc})") from None


__all__ = ["load_model"]
