"""svZeroDSolver drop-in: the coronary outlets (``CORONARY``, ``CORONARY_VAR_RES``), translated
into oxyline's native ``coronary`` condition (docs/physics.md §1.7, docs/svzerod.md).

:mod:`oxyline.io.svzerod` calls :func:`boundary_condition` for the condition types listed in
:data:`BC_PARAMS` and :func:`finish` once the cardiac period is known. Numbers stay the file's
(cgs by svZeroDSolver's convention); the native dict's ``units`` converts them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from oxyline.errors import ModelError

#: svZeroDSolver's parameters of each supported condition type
BC_PARAMS = {
    "CORONARY": {"Ra1", "Ra2", "Rv1", "Ca", "Cc", "Pim", "P_v", "t"},
    "CORONARY_VAR_RES": {"Ra1", "Ra2_min", "Ra2_max", "Rv1", "Ca", "Cc", "Pim", "P_v", "T_vc",
                         "T_vr", "t"},
}
# svZeroDSolver name -> native key
_COMMON = {"Ra1": "arterial_resistance", "Ca": "arterial_capacitance",
           "Cc": "intramyocardial_capacitance", "Rv1": "venous_resistance"}
_VAR_RES = {"Ra2_min": "microvascular_resistance", "Ra2_max": "microvascular_resistance_max",
            "T_vc": "contraction_time", "T_vr": "relaxation_time"}

Num = Callable[[Any, str, str], float]
NumList = Callable[[Any, str, str], list[float]]
Table = Callable[[list[float], list[float], str], tuple[list[float], list[float]]]


def boundary_condition(kind: str, vals: Mapping[str, Any], el: str, num: Num, numlist: NumList,
                       table: Table) -> tuple[dict[str, Any], float | None]:
    """The native ``coronary`` condition of a ``CORONARY``/``CORONARY_VAR_RES`` entry, and the
    period of its intramyocardial pressure table (None when constant). ``num``, ``numlist`` and
    ``table`` are the importer's checked readers (number, list of numbers, periodic table)."""
    names = dict(_COMMON, **(_VAR_RES if kind == "CORONARY_VAR_RES" else {"Ra2": "microvascular_resistance"}))
    native: dict[str, Any] = {"type": "coronary"}
    for key, nat in names.items():
        if key not in vals:
            raise ModelError(f"{el}: missing '{key}'")
        native[nat] = num(vals[key], el, key)
    native["pressure"] = num(vals.get("P_v", 0.0), el, "P_v")
    if "Pim" not in vals:
        raise ModelError(f"{el}: missing 'Pim'")
    raw = vals["Pim"]
    pim = [num(raw, el, "Pim")] if not isinstance(raw, (list, tuple)) else numlist(raw, el, "Pim")
    if not pim:
        raise ModelError(f"{el}: 'Pim' is empty")
    period = None
    if len(pim) == 1:
        native["intramyocardial_pressure"] = pim[0]
    else:
        t = numlist(vals.get("t"), el, "t")
        if len(t) != len(pim):
            raise ModelError(f"{el}: 't' has {len(t)} entries but 'Pim' has {len(pim)}")
        tt, yy = table(t, pim, el)
        period = t[-1] - t[0]
        # svZeroDSolver's steady start uses the arithmetic mean of the samples
        native["intramyocardial_pressure"] = {"time": tt, "pressure": yy,
                                              "steady": sum(pim) / len(pim)}
    return native, period


def finish(bcs: Mapping[str, tuple[str, dict[str, Any]]], period: float) -> None:
    """Give every varying microvascular resistance the cardiac period (svZeroDSolver evaluates
    its contraction law on the time within the cycle)."""
    for kind, native in bcs.values():
        if kind == "CORONARY_VAR_RES":
            native["cycle_period"] = period
