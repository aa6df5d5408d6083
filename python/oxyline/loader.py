"""``oxyline.load_model``: one entry point for every model source. It recognises the source
(a :class:`Model`, a dict, a file, a built-in name), sniffs the format of a mapping with
:func:`oxyline.io.native.sniff_format` (the one format rule) and hands it to the right reader;
:mod:`oxyline.model` itself only validates native dicts and imports no reader."""

from __future__ import annotations

import contextlib
import gc
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from oxyline.errors import ModelError
from oxyline.model import Model, _build, _copy


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector while a model is copied and checked: a 1e6-segment
    model allocates millions of small dicts (none of them cyclic), and every full collection
    walks all live objects again, which makes loading grow faster than linearly."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def load_model(source: str | os.PathLike[str] | Mapping[str, Any] | Model) -> Model:
    """Load and validate a network from a YAML/JSON file, a built-in model name, or a dict.

    >>> import oxyline
    >>> m = oxyline.load_model("bifurcation")
    >>> m.vessel_names
    ['parent', 'daughter1', 'daughter2']
    """
    from oxyline.io.native import read_mapping, sniff_format

    if isinstance(source, Model):
        return source
    if not isinstance(source, (Mapping, str, os.PathLike)):
        raise ModelError(f"load_model: expected a model dict, a file path or a built-in model "
                         f"name, got {type(source).__name__} {source!r:.80}")
    if isinstance(source, Mapping):
        with gc_paused():
            data = _copy(dict(source))
    else:
        p = Path(source)
        if not p.exists() and not p.suffix:
            from oxyline import models  # built-in models, then examples

            return models.load(str(source))
        data = read_mapping(p)
    if sniff_format(data) == "svzerod":
        from oxyline.io.svzerod import to_model

        return to_model(data)
    with gc_paused():
        return _build(data)


__all__ = ["load_model"]
