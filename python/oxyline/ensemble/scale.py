"""The ``scale`` section of a variant patch (resistance and compliance factors for all or some
vessels), read by both routes of an ensemble: the merge of :mod:`oxyline.ensemble.patch` and
the value route of :mod:`oxyline.ensemble.values`; and the variant/path prefix of every patch
error message."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from oxyline.errors import ModelError

SCALE_KEYS = {"resistance", "compliance", "vessels"}


def where(k: int, path: str) -> str:
    return f"variant {k}: {path}"


def unknown(k: int, path: str, what: str, allowed: Iterable[str]) -> ModelError:
    return ModelError(f"{where(k, path)}: unknown {what} (allowed: {', '.join(sorted(allowed))})")


def mapping(value: Any, k: int, path: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ModelError(f"{where(k, path)}: expected a mapping, got {value!r}")
    return value


def scale_terms(scale: Any, index: Mapping[Any, int], k: int
                 ) -> tuple[set[int] | None, dict[str, float]]:
    """The vessels (indices; None: all) and the factors of a ``scale`` section, checked.
    ``index``: the vessel indices by name."""
    scale = mapping(scale, k, "scale")
    for key in scale:
        if key not in SCALE_KEYS:
            raise unknown(k, f"scale.{key}", "scale key", SCALE_KEYS)
    chosen = scale.get("vessels", "all")
    selected = None
    if chosen != "all":
        if isinstance(chosen, str) or not isinstance(chosen, Sequence):
            raise ModelError(f"{where(k, 'scale.vessels')}: expected 'all' or a list of vessel "
                             f"names, got {chosen!r}")
        for name in chosen:
            if name not in index:
                raise ModelError(f"{where(k, f'scale.vessels.{name}')}: no vessel named "
                                 f"{name!r} in the model")
        selected = {index[n] for n in chosen}
    factors = {}
    for key in ("resistance", "compliance"):
        if key in scale:
            f = scale[key]
            try:
                ok = not isinstance(f, bool) and isinstance(f, (int, float)) \
                    and math.isfinite(f)
            except OverflowError:  # an integer beyond any float
                ok = False
            if not ok:
                raise ModelError(f"{where(k, f'scale.{key}')}: expected a number, got "
                                 f"{f!r:.40}")
            factors[key] = float(f)
    return selected, factors
