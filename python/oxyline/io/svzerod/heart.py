"""svZeroDSolver drop-in: the coronary outlets (``CORONARY``, ``CORONARY_VAR_RES``), translated
into oxyline's native ``coronary`` condition (docs/physics.md §1.7, docs/svzerod.md).

:mod:`oxyline.io.svzerod` calls :func:`boundary_condition` for the condition types listed in
:data:`BC_PARAMS` and :func:`finish` once the cardiac period is known. Numbers stay the file's
(cgs by svZeroDSolver's convention); the native dict's ``units`` converts them.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

from oxyline import _core
from oxyline.errors import ModelError, UnsupportedElement
from oxyline.io.svzerod.values import mapped, number, numbers, required

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

def boundary_condition(kind: str, vals: Mapping[str, Any], el: str
                       ) -> tuple[dict[str, Any], float | None]:
    """The native ``coronary`` condition of a ``CORONARY``/``CORONARY_VAR_RES`` entry, and the
    period of its intramyocardial pressure table (None when constant)."""
    names = dict(_COMMON, **(_VAR_RES if kind == "CORONARY_VAR_RES" else {"Ra2": "microvascular_resistance"}))
    native: dict[str, Any] = {"type": "coronary", **mapped(vals, el, names),
                              "pressure": number(vals.get("P_v", 0.0), el, "P_v")}
    raw = required(vals, "Pim", el)
    pim = [number(raw, el, "Pim")] if not isinstance(raw, (list, tuple)) \
        else numbers(raw, el, "Pim")
    if not pim:
        raise ModelError(f"{el}: 'Pim' is empty")
    period = None
    if len(pim) == 1:
        native["intramyocardial_pressure"] = pim[0]
    else:
        t = numbers(vals.get("t"), el, "t")
        if len(t) != len(pim):
            raise ModelError(f"{el}: 't' has {len(t)} entries but 'Pim' has {len(pim)}")
        tt, yy = _core.svzerod_periodic_table(t, pim, el)  # as the reader's FLOW tables
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
#: svZeroDSolver chamber type -> (native law, its parameter -> native key); every parameter is
#: required but the ChamberElastanceInductor's ``Impedance`` (0 when absent)
CHAMBER_LAWS = {
    "ChamberElastanceInductor": ("elastance-inductor", {
        "Emax": "max_elastance", "Emin": "min_elastance", "Vrd": "rest_volume_diastole",
        "Vrs": "rest_volume_systole", "Impedance": "inductance"}),
    "ChamberElastanceInductorExponential": ("exponential", {
        "Emax": "max_elastance", "Kxp": "passive_pressure",
        "Kxv": "passive_volume_coefficient", "Vaso": "rest_volume", "Impedance": "inductance"}),
    "LinearElastanceChamber": ("linear", {
        "Emax": "max_elastance", "Epass": "passive_elastance", "Vrest": "rest_volume"}),
}
CHAMBER_PARAMS = {kind: set(keys) for kind, (_, keys) in CHAMBER_LAWS.items()}
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


def chamber(c: Mapping[str, Any], period: float, initial: Mapping[str, Any]) -> dict[str, Any]:
    """The native ``chamber`` element of one svZeroDSolver chamber entry (without its ends)."""
    name = c["name"]
    kind, el, vals = _known_entry(c, "chamber", CHAMBER_LAWS, CHAMBER_PARAMS, "values")
    native_law, keys = CHAMBER_LAWS[kind]
    optional = {"Impedance": 0.0} if kind == "ChamberElastanceInductor" else {}
    law: dict[str, Any] = {"law": native_law, **mapped(vals, el, keys, optional)}
    act = c.get("activation_function")
    if kind == "ChamberElastanceInductor":
        # its own half-cosine when no activation function is given
        act = act or {"type": "half_cosine", **{k: c["values"][k] for k in ("t_active", "t_twitch")
                                                  if k in c["values"]}}
    if not isinstance(act, Mapping) or act.get("type") not in ACTIVATIONS:
        raise UnsupportedElement(f"{el}: activation_function must be one of "
                                 f"{sorted(ACTIVATIONS)}, got {act!r}")
    native_kind, keys = ACTIVATIONS[act["type"]]
    for k in keys:
        if k not in act:
            raise ModelError(f"{el}: activation_function needs '{k}'")
    law["activation"] = {"kind": native_kind,
                         **{ACTIVATION_KEYS.get(k, k): number(act[k], el, k) for k in keys}}
    law["period"] = period
    v0 = initial.get(f"Vc:{name}")
    if v0 is not None:
        law["initial_volume"] = number(v0, el, f"initial_condition Vc:{name}")
    return law


def valve(v: Mapping[str, Any]) -> tuple[dict[str, Any], str, str]:
    """The native ``valve`` element of one svZeroDSolver valve entry and its (upstream,
    downstream) block names."""
    kind, el, p = _known_entry(v, "valve", VALVE_TYPES, VALVE_PARAMS, "params")
    for k in VALVE_PARAMS[kind]:
        if k not in p:
            raise ModelError(f"{el}: missing '{k}'")
    native = {"law": VALVE_TYPES[kind], "min_resistance": number(p["Rmin"], el, "Rmin"),
              "max_resistance": number(p["Rmax"], el, "Rmax")}
    if kind == "ValveTanh":
        native["steepness"] = number(p["Steepness"], el, "Steepness")
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


def chamber_sphere(vals: Mapping[str, Any], el: str, period: float) -> dict[str, Any]:
    """The native ``chamber_sphere`` element of a ChamberSphere vessel's
    ``zero_d_element_values`` (every parameter is required, as svZeroDSolver requires it)."""
    # svZeroDSolver evaluates the activation on the time within the model's cardiac period
    return {**mapped(vals, el, SPHERE_KEYS), "period": period}
