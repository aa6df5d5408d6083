"""Space-discretisation error: how far a network's input impedance moves when every vessel's
segmentation is refined (docs/solvers.md, "Space").

A vessel of n lumped segments stands for a transmission line; its input impedance converges to
the line's as n grows (first order in the segment's electrical length ωΔx/c for the L and
inverted-L arrangements, second order for π). :func:`convergence` refines every vessel by a
factor (2 by default) ``levels`` times and reports each level's impedance and its change;
:func:`estimate_space_error` is the relative change of one refinement, the usual estimate of the
model's own discretisation error at those frequencies (Richardson: for first-order convergence
the change of one doubling equals the error of the finer model and half that of the coarser).
"""

from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from oxyline.errors import ModelError
from oxyline.frequency import Direction, impedance
from oxyline.loader import load_model
from oxyline.model import Model


@dataclass(frozen=True)
class ConvergenceLevel:
    """One segmentation of a refinement study."""

    #: every vessel's segments are this many times the model's own
    refinement: int
    segments: int
    #: input impedance (Pa·s/m³, complex) at each frequency
    impedance: np.ndarray
    #: |Z − Z_previous| / |Z| at each frequency (NaN for the model's own segmentation)
    change: np.ndarray


def refined(model: Model | str | os.PathLike[str] | Mapping[str, Any],
            factor: int) -> Model:
    """The model with every vessel's segmentation refined ``factor`` times (``segments``
    multiplied, ``max_length`` divided, a vessel with neither given ``factor`` segments)."""
    if not (isinstance(factor, int) and factor >= 1):
        raise ModelError(f"convergence: refinement factor must be an integer >= 1, got {factor!r}")
    m = load_model(model)
    data = copy.deepcopy(m.to_dict())
    for v in data.get("vessels", []):
        if "segments" in v and isinstance(v["segments"], int):
            v["segments"] *= factor
        elif "max_length" in v:
            v["max_length"] = v["max_length"] / factor
        else:
            v["segments"] = factor
    out = load_model(data)
    want = factor * m.summary()["segments"]
    if out.summary()["segments"] != want:
        raise ModelError(f"convergence: refining {factor}x gave {out.summary()['segments']} "
                         f"segments, not {want} (a vessel whose segmentation is not given by "
                         f"'segments' or 'max_length')")
    return out


def convergence(model: Model | str | os.PathLike[str] | Mapping[str, Any], node: str,
                frequencies: Any, *, levels: int = 3, factor: int = 2,
                direction: Direction = "downstream") -> list[ConvergenceLevel]:
    """The input impedance seen from ``node`` at ``frequencies`` (Hz) for the model's own
    segmentation and ``levels − 1`` refinements by ``factor`` each, with each level's
    relative change from the one before.

    >>> import oxyline
    >>> levels = oxyline.convergence("bifurcation", "inlet", [1.0, 10.0], levels=3)
    >>> [lv.refinement for lv in levels]
    [1, 2, 4]
    >>> bool(levels[2].change.max() < levels[1].change.max())  # each refinement moves it less
    True
    """
    if not (isinstance(levels, int) and levels >= 2):
        raise ModelError(f"convergence: levels must be an integer >= 2, got {levels!r}")
    m = load_model(model)
    out: list[ConvergenceLevel] = []
    prev: np.ndarray | None = None
    for k in range(levels):
        r = factor ** k
        mk = m if r == 1 else refined(m, r)
        z = impedance(mk, node, frequencies, direction=direction)
        change = (np.full(z.shape, np.nan) if prev is None
                  else np.abs(z - prev) / np.abs(z))
        out.append(ConvergenceLevel(r, int(mk.summary()["segments"]), z, change))
        prev = z
    return out


def estimate_space_error(model: Model | str | os.PathLike[str] | Mapping[str, Any], node: str,
                         frequencies: Any, *, factor: int = 2,
                         direction: Direction = "downstream") -> np.ndarray:
    """|Z_refined − Z| / |Z_refined| of the input impedance seen from ``node`` at
    ``frequencies`` (Hz) when every vessel's segmentation is refined ``factor`` times: how far
    the model's results move with its segmentation, at each frequency.

    >>> import oxyline
    >>> err = oxyline.estimate_space_error("bifurcation", "inlet", [1.0, 10.0])
    >>> err.shape, bool(err.max() < 0.5)
    ((2,), True)
    """
    levels = convergence(model, node, frequencies, levels=2, factor=factor,
                         direction=direction)
    return levels[1].change
