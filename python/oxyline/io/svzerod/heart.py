"""svZeroDSolver drop-in: the coronary outlets (``CORONARY``, ``CORONARY_VAR_RES``), translated
into oxyline's native ``coronary`` condition (docs/physics.md §1.7, docs/svzerod.md).

:mod:`oxyline.io.svzerod` calls :func:`boundary_condition` for the condition types listed in
:data:`BC_PARAMS` and :func:`finish` once the cardiac period is known. Numbers stay the file's
(cgs by svZeroDSolver's convention); the native dict's ``units`` converts them.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from typing import Any

from oxyline.errors import ModelError, UnsupportedElement

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


# ------------------------------------------------------------------------------------------
# chambers and valves (native ``chamber`` and ``valve`` elements, docs/physics.md §1.8)

VALVE_TYPES = {"ValveTanh": "tanh", "PiecewiseValve": "piecewise"}
VALVE_PARAMS = {"ValveTanh": {"Rmax", "Rmin", "Steepness", "upstream_block", "downstream_block"},
                "PiecewiseValve": {"Rmax", "Rmin", "upstream_block", "downstream_block"}}
CHAMBER_TYPES = {"ChamberElastanceInductor", "LinearElastanceChamber",
                 "ChamberElastanceInductorExponential"}
CHAMBER_PARAMS = {"ChamberElastanceInductor": {"Emax", "Emin", "Vrd", "Vrs", "Impedance"},
                  "LinearElastanceChamber": {"Emax", "Epass", "Vrest"},
                  "ChamberElastanceInductorExponential": {"Emax", "Impedance", "Kxp", "Kxv",
                                                          "Vaso"}}
#: svZeroDSolver activation function -> (native kind, its parameters)
ACTIVATIONS = {
    "half_cosine": ("half-cosine", ("t_active", "t_twitch")),
    "piecewise_cosine": ("piecewise-cosine", ("contract_start", "relax_start",
                                              "contract_duration", "relax_duration")),
    "two_hill": ("two-hill", ("t_shift", "tau_1", "tau_2", "m1", "m2")),
    "wrapping_cosine": ("wrapping-cosine", ("Tsa", "tpwave")),
    "fourier": ("fourier", ()),
}
#: svZeroDSolver activation parameter -> native key (where they differ)
ACTIVATION_KEYS = {"Tsa": "systole_fraction", "tpwave": "p_wave_divisor"}


def _entries(raw: Any, key: str) -> list[Mapping[str, Any]]:
    if not isinstance(raw, list):
        raise ModelError(f"{key}: must be a list")
    for i, e in enumerate(raw):
        if not isinstance(e, Mapping) or not isinstance(e.get("name"), str):
            raise ModelError(f"{key}[{i}]: must be a mapping with a 'name'")
    return raw


def _known_entry(entry: Mapping[str, Any], what: str, types: Collection[str],
                 params: Mapping[str, set[str]], key: str) -> tuple[str, str, Mapping[str, Any]]:
    """(type, element label, parameters) of a chamber or valve entry whose type and parameter
    names svZeroDSolver defines; anything else raises ``UnsupportedElement`` naming it."""
    kind = entry.get("type")
    el = f"{kind} '{entry['name']}'"
    if kind not in types:
        raise UnsupportedElement(f"{el}: {what} type '{kind}' is not supported (supported: "
                                 f"{', '.join(sorted(types))})")
    vals = entry.get(key, {})
    if not isinstance(vals, Mapping) or set(vals) - params[kind]:
        raise UnsupportedElement(f"{el}: unknown {key} {sorted(set(vals) - params[kind])}")
    return kind, el, vals


def chamber(c: Mapping[str, Any], period: float, initial: Mapping[str, Any], num: Num
            ) -> dict[str, Any]:
    """The native ``chamber`` element of one svZeroDSolver chamber entry (without its ends)."""
    name = c["name"]
    kind, el, vals = _known_entry(c, "chamber", CHAMBER_TYPES, CHAMBER_PARAMS, "values")
    missing = [k for k in CHAMBER_PARAMS[kind] - {"Impedance"} if k not in vals]
    if missing:
        raise ModelError(f"{el}: missing '{missing[0]}'")
    act = c.get("activation_function")
    if kind == "ChamberElastanceInductor":
        # its own half-cosine when no activation function is given
        act = act or {"type": "half_cosine", **{k: c["values"][k] for k in ("t_active", "t_twitch")
                                                  if k in c["values"]}}
        law = {"law": "elastance-inductor", "max_elastance": num(vals["Emax"], el, "Emax"),
               "min_elastance": num(vals["Emin"], el, "Emin"),
               "rest_volume_diastole": num(vals["Vrd"], el, "Vrd"),
               "rest_volume_systole": num(vals["Vrs"], el, "Vrs"),
               "inductance": num(vals.get("Impedance", 0.0), el, "Impedance")}
    elif kind == "ChamberElastanceInductorExponential":
        law = {"law": "exponential", "max_elastance": num(vals["Emax"], el, "Emax"),
               "passive_pressure": num(vals["Kxp"], el, "Kxp"),
               "passive_volume_coefficient": num(vals["Kxv"], el, "Kxv"),
               "rest_volume": num(vals["Vaso"], el, "Vaso"),
               "inductance": num(vals["Impedance"], el, "Impedance")}
    else:
        law = {"law": "linear", "max_elastance": num(vals["Emax"], el, "Emax"),
               "passive_elastance": num(vals["Epass"], el, "Epass"),
               "rest_volume": num(vals["Vrest"], el, "Vrest")}
    if not isinstance(act, Mapping) or act.get("type") not in ACTIVATIONS:
        raise UnsupportedElement(f"{el}: activation_function must be one of "
                                 f"{sorted(ACTIVATIONS)}, got {act!r}")
    native_kind, keys = ACTIVATIONS[act["type"]]
    for k in keys:
        if k not in act:
            raise ModelError(f"{el}: activation_function needs '{k}'")
    law["activation"] = {"kind": native_kind,
                         **{ACTIVATION_KEYS.get(k, k): num(act[k], el, k) for k in keys}}
    law["period"] = period
    v0 = initial.get(f"Vc:{name}")
    if v0 is not None:
        law["initial_volume"] = num(v0, el, f"initial_condition Vc:{name}")
    return law


def valve(v: Mapping[str, Any], num: Num) -> tuple[dict[str, Any], str, str]:
    """The native ``valve`` element of one svZeroDSolver valve entry and its (upstream,
    downstream) block names."""
    kind, el, p = _known_entry(v, "valve", VALVE_TYPES, VALVE_PARAMS, "params")
    for k in VALVE_PARAMS[kind]:
        if k not in p:
            raise ModelError(f"{el}: missing '{k}'")
    native = {"law": VALVE_TYPES[kind], "min_resistance": num(p["Rmin"], el, "Rmin"),
              "max_resistance": num(p["Rmax"], el, "Rmax")}
    if kind == "ValveTanh":
        native["steepness"] = num(p["Steepness"], el, "Steepness")
    return native, str(p["upstream_block"]), str(p["downstream_block"])


# ------------------------------------------------------------------------------------------
# the spherical chamber (native ``chamber_sphere``, docs/physics.md §1.11)

#: svZeroDSolver's ChamberSphere parameter -> native key
SPHERE_KEYS = {"rho": "density", "thick0": "wall_thickness", "radius0": "reference_radius",
               "W1": "w1", "W2": "w2", "eta": "viscosity", "sigma_max": "max_active_stress",
               "alpha_max": "max_activation_rate", "alpha_min": "min_activation_rate",
               "tsys": "systole_start", "tdias": "diastole_start",
               "steepness": "activation_steepness"}
#: its internal variables in svZeroDSolver's order (``<var>:<block>`` in the variable table)
SPHERE_VARIABLES = ("radius", "velo", "stress", "tau", "volume")


def chamber_sphere(vals: Mapping[str, Any], el: str, period: float, num: Num) -> dict[str, Any]:
    """The native ``chamber_sphere`` element of a ChamberSphere vessel's
    ``zero_d_element_values`` (every parameter is required, as svZeroDSolver requires it)."""
    out: dict[str, Any] = {}
    for key, nat in SPHERE_KEYS.items():
        if key not in vals:
            raise ModelError(f"{el}: missing '{key}'")
        out[nat] = num(vals[key], el, key)
    # svZeroDSolver evaluates the activation on the time within the model's cardiac period
    out["period"] = period
    return out
