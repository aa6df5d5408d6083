"""``oxyline.load_model``: one entry point for every model source. It recognises the source
(a :class:`Model`, a dict, a file, a built-in name) and hands it on: a file to the format
registry :mod:`oxyline.io.formats` (which returns a native model dict), a name to
:mod:`oxyline.catalogue`, a mapping in another format (svZeroDSolver) to its converter;
:mod:`oxyline.model` itself only validates native dicts and imports no reader."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from oxyline import catalogue
from oxyline.errors import ModelError
from oxyline.io import formats
from oxyline.io.native import read_mapping
from oxyline.memory import gc_paused
from oxyline.model import Model, _build, _copy


def load_model(source: str | os.PathLike[str] | Mapping[str, Any] | Model) -> Model:
    """Load and validate a network from a model file (any format of :mod:`oxyline.io.formats`),
    a built-in model name, or a dict.

    >>> import oxyline
    >>> m = oxyline.load_model("bifurcation")
    >>> m.vessel_names
    ['parent', 'daughter1', 'daughter2']
    """
    if isinstance(source, Model):
        return source
    if not isinstance(source, (Mapping, str, os.PathLike)):
        raise ModelError(f"load_model: expected a model dict, a file path or a built-in model "
                         f"name, got {type(source).__name__} {source!r:.80}")
    if isinstance(source, Mapping):
        converted = formats.from_mapping(source)
        if converted is not None:
            return _build(converted)
        with gc_paused():
            return _build(_copy(dict(source)))
    p = Path(source)
    if not p.exists() and not p.suffix:
        return catalogue.load(str(source))  # built-in models and examples
    if formats.claimed(p):
        data, _where = formats.read_native(p)
    else:  # any other suffix: a JSON mapping (read_mapping's rule), in any mapping format
        data = read_mapping(p)
        data = formats.from_mapping(data) or data
    with gc_paused():
        return _build(data)


__all__ = ["load_model"]
