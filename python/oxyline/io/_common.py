"""Helpers shared by the readers and writers of :mod:`oxyline.io`."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from oxyline.errors import ModelError
from oxyline.memory import gc_paused
from oxyline.model import Model, _build, _copy

PathLike = str | os.PathLike[str]

# keys whose values are identifiers or words, never numbers
WORD_KEYS = {"name", "from", "to", "type", "interpolation", "description", "units", "arrangement",
             "method", "start", "wall_model", "inertance_profile", "cycles", "model"}
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")

VESSEL_COLUMNS = ("name", "from", "to", "length", "radius", "radius_in", "radius_out",
                  "wall_thickness", "youngs_modulus", "poisson_ratio", "segments", "arrangement",
                  "output", "description")
LUMPED_COLUMNS = ("resistance", "inductance", "capacitance", "stenosis_coefficient")
ALIASES = {
    "source": "from", "target": "to", "thickness": "wall_thickness", "h": "wall_thickness",
    "e": "youngs_modulus", "youngs": "youngs_modulus", "nu": "poisson_ratio",
    "lumped_resistance": "resistance", "lumped_inductance": "inductance",
    "lumped_capacitance": "capacitance", "lumped_stenosis_coefficient": "stenosis_coefficient",
}


def plain(value: Any, key: str | None = None) -> Any:
    """``value`` as plain JSON/YAML data: numpy scalars and arrays become Python numbers and
    lists, numeric strings (YAML 1.1 reads ``5.0e5`` as a string) become floats."""
    if isinstance(value, Mapping):
        return {str(k): plain(v, str(k)) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v, key) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return plain(value.tolist(), key)
    if isinstance(value, str) and key not in WORD_KEYS and _NUMBER.match(value.strip()):
        return float(value)
    if isinstance(value, float) and value.is_integer() and key == "segments":
        return int(value)
    return value


def is_missing(value: Any) -> bool:
    """True for None, NaN and empty strings (empty table cells)."""
    if value is None:
        return True
    if isinstance(value, float) and math.isnan(value):
        return True
    if isinstance(value, str) and not value.strip():
        return True
    try:
        import pandas as pd

        return bool(pd.isna(value)) if not isinstance(value, (list, tuple, dict)) else False
    except (TypeError, ValueError):
        return False


def build(data: dict[str, Any], where: str | None = None, *, owned: bool = False) -> Model:
    """The :class:`Model` of the native model dict ``data`` (copied first unless the caller
    ``owned`` it: the dict becomes the model's ``source``). A :class:`ModelError` is re-raised
    prefixed with ``where`` (the file or table it came from)."""
    try:
        with gc_paused():
            return _build(data if owned else _copy(dict(data)))
    except ModelError as exc:
        msg = str(exc)
        if where is None or msg.startswith(where):
            raise
        raise type(exc)(f"{where}: {msg}") from None


def model_source(model: Model) -> dict[str, Any]:
    """The model's user-facing dict with plain values."""
    return plain(model.to_dict())


def check_path(path: PathLike) -> Path:
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: file not found")
    return p
