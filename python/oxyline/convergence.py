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

from oxyline import _core
from oxyline.errors import ModelError, ResourceError
from oxyline.frequency import Direction, impedance
from oxyline.loader import load_model
from oxyline.model import Model
from oxyline.structured_tree import expanded


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
    """The model with every vessel's segmentation refined ``factor`` times: each geometric
    vessel (structured-tree vessels included, the trees grown) gets ``factor`` times the
    segments it has now, however they were decided (``segments``, ``max_length`` or
    ``auto``); a lumped vessel only when it is cut into several already (or ``auto``): one
    lumped segment is an element, not a line."""
    if not (isinstance(factor, int) and not isinstance(factor, bool) and factor >= 1):
        raise ModelError(f"convergence: refinement factor must be an integer >= 1, got {factor!r}")
    m = load_model(model)
    data = copy.deepcopy(expanded(m.to_dict()))
    table = m.network.segment_table()
    counts = np.bincount(np.asarray(table["vessel"], dtype=np.int64),
                         minlength=len(table["vessel_names"]))
    by_name = dict(zip(table["vessel_names"], counts.tolist(), strict=True))
    extra = 0
    for v in data.get("vessels", []):
        n = by_name.get(str(v.get("name")), 0)
        if n > 0 and _is_line(v, n):
            v["segments"] = factor * n
            extra += (factor - 1) * n
    seg = data.get("segmentation")
    if isinstance(seg, Mapping):  # every count is explicit now
        data["segmentation"] = {k: x for k, x in seg.items() if k not in ("max_length",
                                                                          "segments")}
    out = load_model(data)
    # (the network's own counts: a model's summary() also asks for the RK4 limit, which an
    # index-2 circuit has none of)
    want, got = len(table["vessel"]) + extra, out.network.summary()["segments"]
    if got != want:
        raise ModelError(f"convergence: refining {factor}x gave {got} "
                         f"segments, not {want} (a vessel whose segmentation cannot be "
                         f"refined, e.g. an RCL block)")
    return out


def _is_line(vessel: Mapping[str, Any], segments: int) -> bool:
    """Whether a native vessel of ``segments`` segments stands for a transmission line to
    refine: a geometric vessel, or a lumped one cut into several (or ``auto``); a lumped
    vessel of one segment is an element its author sized (a wall branch, a resistor)."""
    if not isinstance(vessel, Mapping) or any(
            k in vessel for k in ("valve", "chamber", "through_rc", "chamber_sphere",
                                  "heart_pulmonary", "coronary_bed")):
        return False
    return "lumped" not in vessel or segments > 1 or vessel.get("segments") == "auto"


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
        out.append(ConvergenceLevel(r, int(mk.network.summary()["segments"]), z, change))
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
    try:
        levels = convergence(model, node, frequencies, levels=2, factor=factor,
                             direction=direction)
    except ResourceError as exc:  # the refined model is the one too large: say which knob
        raise ResourceError(f"estimate_space_error: factor = {factor!r}: {exc}") from None
    return levels[1].change


def forcing_harmonics(model: Model | str | os.PathLike[str] | Mapping[str, Any],
                      rtol: float | None = None) -> np.ndarray:
    """The frequencies (Hz) of the forcing's significant harmonics, the ones ``segments:
    auto`` resolves (docs/solvers.md, "Space"): the model period's harmonics up to the
    highest frequency the core's rule keeps at ``rtol`` (default: the model's
    ``segmentation: rtol``, else 1e-3).

    >>> import oxyline
    >>> f = oxyline.forcing_harmonics("adan56", rtol=1e-2)
    >>> float(f[0]), len(f)
    (1.0, 7)
    """
    m = load_model(model)
    f_max, _ = _core.forcing_frequency(m.source, rtol)
    if not m.period:
        raise ModelError("forcing_harmonics: the model has no period (no periodic forcing)")
    k = max(1, int(np.floor(f_max * m.period + 1e-9)))
    return np.arange(1, k + 1) / m.period


def inlet_space_error(model: Model | str | os.PathLike[str] | Mapping[str, Any],
                      rtol: float | None = None) -> float:
    """The spatial error estimate of a run: the largest :func:`estimate_space_error` (one
    refinement by 2) of the input impedance at any flow or pressure inlet over the forcing's
    significant harmonics (:func:`forcing_harmonics`). What ``simulate(...,
    estimate_space_error=True)`` records as ``result.error_estimate["space"]``.

    >>> from oxyline.convergence import inlet_space_error
    >>> bool(inlet_space_error("bifurcation") < 0.5)
    True
    """
    m = load_model(model)
    bcs = m.source.get("boundary_conditions") or {}
    inlets = [str(n) for n, bc in bcs.items()
              if isinstance(bc, Mapping) and bc.get("type") in ("flow", "pressure")]
    if not inlets:
        raise ModelError("estimate_space_error: the model has no flow or pressure inlet whose "
                         "input impedance the estimate is taken at")
    freqs = forcing_harmonics(m, rtol)
    levels = [convergence(m, node, freqs, levels=2) for node in inlets]
    return float(max(np.max(lv[1].change) for lv in levels))
