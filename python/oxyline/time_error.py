"""Time-integration error of an error-controlled run, as a user reads it: every vessel's
pressure and flow against its own scale (docs/solvers.md, "Honesty").

The step control holds each unknown's *local* error per unit step within rtol of its scale
(``result.error_estimate``). On networks with lightly damped wave reflections the local errors
of the large vessels' flows accumulate through the pressures into the small vessels' flows,
which then miss rtol of their own amplitude by far more (adan56 at rtol 1e-3: 27 rtol, the left
gastric's flow, while no step's estimate exceeded rtol). That accumulated (global) error is what
:func:`oxyline.run.estimate_time_error` measures: it runs the model again at ``rtol/factor``
and takes the difference of the two runs per vessel. The achieved error of an error-controlled
run is proportional to rtol (measured: adan56 27–47 rtol over rtol 1e-2 … 1e-4), so the
difference is ``(1 − 1/factor)`` of the coarser run's error, and the estimate is the difference
over that (:func:`accumulated`). Cost: one more run at rtol/factor (about factor^½ times the
steps).

``simulate(..., estimate_time_error=True)`` measures the same within the one run, cheaper: once
the run has ended, the core integrates its *last cycle* again from that cycle's start state at
``rtol/factor`` (docs/solvers.md, "The accumulated error"), and the difference of the two last
cycles, over ``(1 − 1/factor)``, is the error that cycle accumulated from its start.

The runs themselves are :mod:`oxyline.run`'s (it imports this module, never the reverse): this
module holds what both the whole-run pair and the in-run estimate read and record.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from oxyline.errors import ModelError

if TYPE_CHECKING:  # (annotations only: the result's writers import this module)
    from oxyline.result import Result

#: the tolerance of the second run is rtol over this
FACTOR = 4.0

#: the share of the target :meth:`TimeErrorEstimate.rtol_to_meet` aims at (the achieved
#: error's ratio to rtol drifts with rtol by up to ~2.6x on adan56)
SAFETY = 0.5


@dataclass(frozen=True)
class TimeErrorEstimate:
    """The estimated time-integration error of ``result`` (the run at ``rtol``), per vessel
    against its own scale, from the run at ``rtol/factor`` (``finer``).

    >>> import oxyline
    >>> est = oxyline.estimate_time_error("bifurcation", rtol=1e-2, cycles=2)
    >>> est.factor, len(est.per_vessel["flow"]) == len(est.result.vessels)
    (4.0, True)
    >>> est.rtol_to_meet() <= 1e-2
    True
    """

    rtol: float
    factor: float
    result: Result
    finer: Result
    #: per vessel (``result.vessels``): flow max_t |ΔQ| / max_t |Q| (``flow_in``); pressure
    #: max_t |ΔP| / max_t |P| (``pressure_in``); pulse pressure |ΔPP| / PP (``pressure_in``);
    #: PO2 max_t |ΔPO2| / max_t PO2 (``po2_out``, models with oxygen), each the two runs'
    #: difference over (1 − 1/factor)
    per_vessel: dict[str, np.ndarray] = field(default_factory=dict)

    def rtol_to_meet(
        self, target: float | None = None, kinds: tuple[str, ...] = (), safety: float = SAFETY
    ) -> float:
        """The rtol whose run is estimated to meet ``target`` (default: ``rtol``) in every
        vessel for ``kinds`` (default: every kind estimated): the achieved error is nearly
        proportional to rtol (module text), so ``safety`` × rtol × target / the worst
        estimate, at most ``rtol``. The ratio of achieved error to rtol drifts with rtol
        (adan56, worst flow: 46, 27, 64 and 71 at rtol 1e-2, 1e-3, 1e-4 and 3e-5), hence the
        safety factor. Measured on adan56 and paper-bifurcated: docs/solvers.md, "Measuring it"."""
        goal = self.rtol if target is None else float(target)
        if not goal > 0:
            raise ModelError(f"rtol_to_meet: target must be > 0, got {target!r}")
        worst = max((w for k, (w, _) in self.worst.items() if not kinds or k in kinds), default=0.0)
        return self.rtol if worst <= safety * goal else self.rtol * safety * goal / worst

    @property
    def worst(self) -> dict[str, tuple[float, str]]:
        """Per kind, the largest estimated error over the vessels and that vessel."""
        names = self.result.vessels
        return {
            k: (float(np.max(e)), names[int(np.argmax(e))])
            for k, e in self.per_vessel.items()
            if e.size
        }


def differences(a: Result, b: Result) -> dict[str, np.ndarray]:
    """Every vessel's difference of ``a`` from ``b`` against ``b``'s own scale (the kinds of
    :attr:`TimeErrorEstimate.per_vessel`); the runs share their output times."""
    p, pb = a.pressure_in, b.pressure_in
    pulse, pulse_b = np.ptp(p, axis=0), np.ptp(pb, axis=0)
    out = {
        "flow": np.max(np.abs(a.flow_in - b.flow_in), 0) / np.max(np.abs(b.flow_in), 0),
        "pressure": np.max(np.abs(p - pb), 0) / np.max(np.abs(pb), 0),
        "pulse_pressure": np.abs(pulse - pulse_b) / pulse_b,
    }
    if a.oxygen is not None and b.oxygen is not None:
        o, ob = a.po2_out, b.po2_out
        out["po2"] = np.max(np.abs(o - ob), 0) / np.max(np.abs(ob), 0)
    return out


def accumulated(coarse: Result, finer: Result, factor: float = FACTOR) -> dict[str, np.ndarray]:
    """The accumulated error per vessel of ``coarse`` (the run at rtol), from ``finer`` (the
    same at ``rtol/factor``): their :func:`differences` over ``(1 − 1/factor)`` (module
    text)."""
    scale = 1.0 / (1.0 - 1.0 / factor)
    return {k: v * scale for k, v in differences(coarse, finer).items()}


#: what ``settings["time_error_from"]`` says of each way of measuring the estimate
FROM_LAST_CYCLE = "last cycle again at rtol/{factor:g}"
FROM_LAST_CYCLE_EXPLICIT = (
    "every cycle again at rtol/{factor:g}, the explicit pair's step ceiling over "
    "{factor:g}^(1/5)"
)
FROM_WHOLE_RUN = "whole run again at rtol/{factor:g}"
#: added to :data:`FROM_WHOLE_RUN` when the explicit pair took the same steps at rtol/factor:
#: the stability bound, not the tolerance, set them, and the difference understates the error
SAME_STEPS = "; the same steps there (set by the stability bound): a lower bound"


def per_vessel_table(per_vessel: Mapping[str, np.ndarray], vessels: list[str]) -> Any:
    """The per-vessel estimate as a ``pandas.DataFrame`` (index ``vessel``, a column per kind,
    each vessel's error against its own scale as in :attr:`TimeErrorEstimate.per_vessel`)."""
    import pandas as pd

    return pd.DataFrame({k: np.asarray(v, dtype=float) for k, v in per_vessel.items()},
                        index=pd.Index(list(vessels), name="vessel"))


#: the file variables of :attr:`oxyline.Result.time_error` (one per kind, over ``vessel``)
FILE_PREFIX = "time_error_"

#: what each kind's file variable holds (its ``description`` attribute)
FILE_DESCRIPTION = {
    "flow": "accumulated time-integration error of flow_in: max_t |dQ| / max_t |Q|",
    "pressure": "accumulated time-integration error of pressure_in: max_t |dP| / max_t |P|",
    "pulse_pressure": "accumulated time-integration error of the pulse pressure of "
    "pressure_in: |dPP| / PP",
    "po2": "accumulated time-integration error of po2_out: max_t |dPO2| / max_t PO2",
}


def table_variables(table: Any, vessels: list[str]) -> dict[str, Any]:
    """The per-vessel table (:attr:`oxyline.Result.time_error`) as dataset variables over the
    dimension ``vessel`` (in ``vessels``' order), one per kind: ``time_error_flow``, …, each a
    dimensionless error against the vessel's own scale."""
    rows = table.reindex(list(vessels))
    return {
        FILE_PREFIX + kind: (
            ("vessel",),
            rows[kind].to_numpy(dtype=float),
            {"units": "1", "description": FILE_DESCRIPTION.get(kind, kind)},
        )
        for kind in table.columns
    }


def table_from_dataset(ds: Any, vessels: list[str]) -> Any:
    """The per-vessel table written by :func:`table_variables` (None when ``ds`` has none)."""
    names = [
        str(n) for n in ds.data_vars if str(n).startswith(FILE_PREFIX) and ds[n].dims == ("vessel",)
    ]
    if not names:
        return None
    per_vessel = {n[len(FILE_PREFIX) :]: np.asarray(ds[n].values, dtype=float) for n in names}
    return per_vessel_table(per_vessel, vessels)


def record_estimate(
    result: Result, per_vessel: Mapping[str, np.ndarray], source: str, extra_steps: int
) -> None:
    """Put the accumulated estimate into ``result``: ``settings["error_estimate_<kind>"]``
    becomes the worst vessel's accumulated error of each kind (the step control's local
    estimates move to ``local_error_estimate_<kind>``), with that vessel's name in
    ``time_error_vessel_<kind>``, how it was measured in ``time_error_from`` and the second
    integration's steps in ``time_error_steps``; the per-vessel table is
    ``result.time_error``."""
    s = result.settings
    pre = "error_estimate_"
    for key in [k for k in s if k.startswith(pre) and k != pre + "space"]:
        s["local_" + key] = s.pop(key)
    names = result.vessels
    for kind, e in per_vessel.items():
        if e.size:
            worst = int(np.nanargmax(e))
            s[pre + kind] = float(e[worst])
            s[f"time_error_vessel_{kind}"] = names[worst]
    s["time_error_from"] = source
    s["time_error_steps"] = int(extra_steps)
    result.time_error = per_vessel_table(per_vessel, names)
