"""Network models: checking keys and values of a native model dict, converting units, and
writing the canonical SI description handed to the Rust core. A leaf module: reading files,
built-in names and other formats is :func:`oxyline.loader.load_model`'s job.

The user-facing schema (see README) is::

    name: carotid
    units: SI                          # or cgs (cm, dyn/cm^2, mL/s) as svZeroDSolver files
    blood: {density: 1050, viscosity: 0.0035}
    arrangement: inverted-L            # L, pi
    segmentation: {max_length: 0.0065} # or per-vessel `segments: N`
    period: 1.0
    vessels: [...]
    boundary_conditions: {...}
    simulation: {cycles: 10, dt: auto, method: auto, output: {cycles: last, every: 1e-3}}
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from oxyline import _core
from oxyline import memory as _memory  # a leaf too: imports only _core and errors
from oxyline.errors import ModelError
from oxyline.units import factor

TOP_KEYS = {
    "name", "units", "blood", "arrangement", "segmentation", "period", "vessels",
    "boundary_conditions", "simulation", "wall_model", "inertance_profile", "description",
    "oxygen", "species", "transport",
}
VESSEL_KEYS = {
    "name", "from", "to", "length", "radius", "radius_in", "radius_out", "wall_thickness",
    "youngs_modulus", "poisson_ratio", "segments", "lumped", "arrangement", "output",
    "description", "valve", "chamber", "through_rc", "heart_pulmonary", "coronary_bed",
    "initial", "initial_rate", "chamber_sphere",
}
#: heart elements (docs/physics.md §1.8): each law's keys and their quantities ("1/pressure":
#: a valve's steepness; "elastance": pressure per volume; "volume": the flow factor times 1 s)
VALVE_KEYS = {
    "tanh": {"min_resistance": "resistance", "max_resistance": "resistance",
             "steepness": "1/pressure"},
    "piecewise": {"min_resistance": "resistance", "max_resistance": "resistance"},
}
CHAMBER_KEYS = {
    "elastance-inductor": {"max_elastance": "elastance", "min_elastance": "elastance",
                           "rest_volume_diastole": "volume", "rest_volume_systole": "volume"},
    "linear": {"max_elastance": "elastance", "passive_elastance": "elastance",
               "rest_volume": "volume"},
    "exponential": {"max_elastance": "elastance", "passive_pressure": "pressure",
                    "passive_volume_coefficient": "1/volume", "rest_volume": "volume"},
}
THROUGH_RC_KEYS = {"resistance": "resistance", "capacitance": "capacitance"}
#: a spherical chamber with wall mechanics (docs/physics.md §1.11): keys and quantities
CHAMBER_SPHERE_KEYS = {
    "density": "density", "wall_thickness": "length", "reference_radius": "length",
    "w1": "pressure", "w2": "pressure", "viscosity": "viscosity",
    "max_active_stress": "pressure", "max_activation_rate": "1/time",
    "min_activation_rate": "1/time", "systole_start": "time", "diastole_start": "time",
    "activation_steepness": "time", "period": "time",
}
#: the closed-loop heart block (docs/physics.md §1.10): keys and quantities ("number": none)
HEART_PULMONARY_KEYS = {
    "period": "time", "atrial_systole_fraction": "number", "p_wave_divisor": "number",
    **{f"{side}_ventricle_{k}": q for side in ("right", "left")
       for k, q in (("elastance", "elastance"), ("rest_volume", "volume"))},
    **{f"{side}_atrium_{k}": q for side in ("right", "left")
       for k, q in (("elastance", "elastance"), ("passive_pressure", "pressure"),
                    ("passive_volume_coefficient", "1/volume"), ("rest_volume", "volume"))},
    **{f"{valve}_{k}": k for valve in ("tricuspid", "pulmonary_valve", "mitral", "aortic_valve")
       for k in ("resistance", "inductance")},
    "pulmonary_resistance": "resistance", "pulmonary_capacitance": "capacitance",
    "aortic_capacitance": "capacitance",
}
#: optional start values of the heart block
HEART_PULMONARY_START = {
    **{f"initial_{c}_volume": "volume" for c in ("right_atrium", "right_ventricle",
                                                 "left_atrium", "left_ventricle")},
    "initial_pulmonary_pressure": "pressure",
}
#: a closed-loop coronary bed (docs/physics.md §1.10), besides its "heart" and "ventricle"
CORONARY_BED_KEYS = {
    "arterial_resistance": "resistance", "arterial_capacitance": "capacitance",
    "microvascular_resistance": "resistance", "intramyocardial_capacitance": "capacitance",
    "venous_resistance": "resistance", "intramyocardial_factor": "number",
}
CHAMBER_COMMON = {"period": "time", "inductance": "inductance", "initial_volume": "volume"}
ACTIVATION_KEYS = {
    "half-cosine": {"t_active", "t_twitch"},
    "piecewise-cosine": {"contract_start", "relax_start", "contract_duration", "relax_duration"},
    "two-hill": {"t_shift", "tau_1", "tau_2", "m1", "m2"},
    "wrapping-cosine": {"systole_fraction", "p_wave_divisor"},
    "fourier": set(),
}
LUMPED_KEYS = {"resistance", "inductance", "capacitance", "stenosis_coefficient",
               "stenosis_form"}
#: how generalized-α discretises an RCL vessel's stenosis (docs/svzerod.md, "C + stenosis")
STENOSIS_FORMS = ("branch", "svzerod")
BC_KEYS = {
    "flow": {"type", "time", "flow", "value", "fourier", "interpolation", "steady"},
    "pressure": {"type", "time", "pressure", "value", "fourier", "interpolation", "steady"},
    "resistance": {"type", "resistance", "pressure"},
    "rcr": {"type", "proximal_resistance", "capacitance", "distal_resistance", "pressure"},
    # svZeroDSolver's RESISTANCE / RCR at a vessel inlet, its own equations (docs/svzerod.md)
    "svzerod-inlet": {"type", "resistance", "proximal_resistance", "capacitance",
                      "distal_resistance", "pressure"},
    "coronary": {"type", "arterial_resistance", "arterial_capacitance", "microvascular_resistance",
                 "intramyocardial_capacitance", "venous_resistance", "intramyocardial_pressure",
                 "pressure", "microvascular_resistance_max", "contraction_time",
                 "relaxation_time", "cycle_period"},
}
#: a coronary outlet's numbers and their quantities (docs/physics.md §1.7)
CORONARY_QUANTITIES = {
    "arterial_resistance": "resistance", "arterial_capacitance": "capacitance",
    "microvascular_resistance": "resistance", "intramyocardial_capacitance": "capacitance",
    "venous_resistance": "resistance", "microvascular_resistance_max": "resistance",
    "contraction_time": "time", "relaxation_time": "time", "cycle_period": "time",
}
CORONARY_REQUIRED = ("arterial_resistance", "arterial_capacitance", "microvascular_resistance",
                     "intramyocardial_capacitance", "venous_resistance", "intramyocardial_pressure")
SIM_KEYS = {"cycles", "dt", "method", "output", "until_periodic", "max_cycles", "rho_infty", "start",
            "max_memory"}
OUTPUT_KEYS = {"cycles", "every", "segments", "variables", "vessels"}
METHODS = {"auto", "rk4", "generalized-alpha"}
ARRANGEMENTS = {"inverted-L", "L", "pi", "RCL"}


def output_names(value: Any, key: str) -> list[str] | None:
    """An output selection list of names (None, or ``all``: everything); a single name is a
    list of one."""
    if value is None or value == "all":
        return None
    if isinstance(value, str):
        return [value]
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise ModelError(f"simulation output: {key} must be a list of names, got {value!r}")
    return list(value)


def output_vessels(value: Any) -> list[str] | None:
    """Output ``vessels``: ``all`` (None: every vessel with output), ``none`` (no vessel) or a
    list of vessel names."""
    if value == "all":
        return None
    if value == "none":
        return []
    return output_names(value, "vessels")


_ATOMS = frozenset({str, int, float, bool, type(None)})


def _copy(data: Any) -> Any:
    """Deep copy of a model description: dicts and lists (tuples become lists) are rebuilt,
    plain values shared, anything else (arrays, ...) deep-copied. A quarter of the cost of a JSON
    round trip on 10^5-vessel models and linear in their size."""
    t = type(data)
    # a dict or list of plain values only (a vessel, a waveform table) is copied in C: the
    # type check of its values runs in C too (map + issuperset), 4x faster than rebuilding it
    if t is dict:
        if _ATOMS.issuperset(map(type, data.values())):
            return data.copy()
        return {k: v if type(v) in _ATOMS else _copy(v) for k, v in data.items()}
    if t is list or t is tuple:
        if _ATOMS.issuperset(map(type, data)):
            return list(data)
        return [v if type(v) in _ATOMS else _copy(v) for v in data]
    if t in _ATOMS:
        return data
    if isinstance(data, Mapping):
        return {k: _copy(v) for k, v in data.items()}
    return copy.deepcopy(data)


def _err(element: str, message: str) -> ModelError:
    return ModelError(f"{element}: {message}")


def _check_keys(d: Mapping[str, Any], allowed: set[str], element: str) -> None:
    if not isinstance(d, Mapping):
        raise _err(element, f"expected a mapping, got {type(d).__name__}")
    for k in d:
        if k not in allowed:
            raise _err(element, f"unknown key '{k}' (allowed: {', '.join(sorted(allowed))})")


def _number(value: Any, element: str, key: str) -> float:
    if isinstance(value, str):  # YAML 1.1 reads 5.0e5 (no exponent sign) as a string
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _err(element, f"'{key}' must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise _err(element, f"'{key}' must be finite, got {v}")
    return v


def _positive(value: Any, element: str, key: str, allow_zero: bool = False) -> float:
    """A finite number > 0 (>= 0 with ``allow_zero``), named by the user's key."""
    v = _number(value, element, key)
    if v < 0 or (v == 0 and not allow_zero):
        raise _err(element, f"{key} must be a finite number {'>=' if allow_zero else '>'} 0, "
                            f"got {v:g}")
    return v


def _numbers(value: Any, element: str, key: str) -> list[float]:
    if not isinstance(value, (list, tuple)) and not hasattr(value, "tolist"):
        raise _err(element, f"'{key}' must be a list of numbers, got {value!r}")
    values = list(value.tolist() if hasattr(value, "tolist") else value)
    return [_number(v, element, f"{key}[{i}]") for i, v in enumerate(values)]


def _waveform(bc: Mapping[str, Any], key: str, quantity: str, units: str, element: str,
              required: bool = True) -> dict[str, Any] | None:
    """Canonical waveform from `value:`, `time:`+`key:` tables, `fourier:` or a scalar `key:`."""
    f = factor(units, quantity)
    if "fourier" in bc:
        fo = bc["fourier"]
        _check_keys(fo, {"period", "mean", "cos", "sin"}, f"{element} fourier")
        return {
            "kind": "fourier",
            "period": _number(fo.get("period"), element, "fourier.period"),
            "mean": f * _number(fo.get("mean", 0.0), element, "fourier.mean"),
            "cos": [f * x for x in _numbers(fo.get("cos", []), element, "fourier.cos")],
            "sin": [f * x for x in _numbers(fo.get("sin", []), element, "fourier.sin")],
        }
    if "time" in bc:
        if key not in bc:
            raise _err(element, f"has 'time' but no '{key}' table")
        t = _numbers(bc["time"], element, "time")
        v = [f * x for x in _numbers(bc[key], element, key)]
        if len(t) != len(v):
            raise _err(element, f"'time' has {len(t)} entries but '{key}' has {len(v)}")
        for i in range(1, len(t)):
            if t[i] <= t[i - 1]:
                raise _err(element, f"'time' must be strictly increasing: t[{i}] = {t[i]} <= "
                                    f"t[{i - 1}] = {t[i - 1]}")
        out: dict[str, Any] = {"kind": "table", "time": t, "value": v,
                               "interpolation": bc.get("interpolation", "linear")}
        if out["interpolation"] not in ("linear", "periodic-cubic"):
            raise _err(element, f"interpolation must be 'linear' or 'periodic-cubic', got "
                                f"{out['interpolation']!r}")
        if "steady" in bc:
            out["steady"] = f * _number(bc["steady"], element, "steady")
        return out
    for k in ("value", key):
        if k in bc and bc[k] is not None:
            if isinstance(bc[k], (list, tuple)):
                raise _err(element, f"'{k}' is a list but no 'time' table is given")
            return {"kind": "constant", "value": f * _number(bc[k], element, k)}
    if required:
        raise _err(element, f"needs '{key}' (a number, or 'time' + '{key}' tables, or 'fourier')")
    return None


_FAST_KEYS = frozenset(VESSEL_KEYS - {"lumped", "initial", "initial_rate"})
# a vessel's start values (docs/physics.md §1.9): end pressures and flows
START_KEYS = {"pressure_in": "pressure", "pressure_out": "pressure", "flow_in": "flow",
              "flow_out": "flow"}
_REAL = (float, int)  # exact types: bool, str and None take the full check


def _vessels(vessels: list[Any], units: str) -> list[dict[str, Any]]:
    """Canonical vessels. Plain geometric vessels (the bulk of a large tree) take a fast path
    that only checks what the core cannot (keys, types, finiteness) plus the cheap sign checks;
    anything it does not accept goes through :func:`_vessel`, which gives the precise error."""
    L, E = factor(units, "length"), factor(units, "modulus")
    fast = _fast_vessel
    return [fast(v, L, E) or _vessel(v, i, units) for i, v in enumerate(vessels)]


def _fast_vessel(v: Any, L: float, E: float) -> dict[str, Any] | None:
    """The canonical form of a geometric vessel whose values are all in range, or None (the
    caller then runs the full check). Same result as :func:`_vessel` for the vessels it takes."""
    if type(v) is not dict or not v.keys() <= _FAST_KEYS:
        return None
    name, a, b, length = v.get("name"), v.get("from"), v.get("to"), v.get("length")
    if type(name) is not str or type(a) is not str or type(b) is not str:
        return None
    if "radius" in v:
        if "radius_in" in v or "radius_out" in v:
            return None
        r_in = r_out = v["radius"]
    else:
        r_in, r_out = v.get("radius_in"), v.get("radius_out")
    # 0 < x < inf is False for NaN, so one comparison checks sign and finiteness
    if not (type(length) in _REAL and type(r_in) in _REAL and type(r_out) in _REAL
            and 0 < length < math.inf and 0 < r_in < math.inf and 0 < r_out < math.inf):
        return None
    g: dict[str, Any] = {"length": L * length, "radius_in": L * r_in, "radius_out": L * r_out}
    if "wall_thickness" in v:
        h = v["wall_thickness"]
        if type(h) not in _REAL or not 0 < h < math.inf:
            return None
        g["wall_thickness"] = L * h
    if "youngs_modulus" in v:
        e = v["youngs_modulus"]
        if type(e) not in _REAL or not 0 < e < math.inf:
            return None
        g["youngs_modulus"] = E * e
    if "poisson_ratio" in v:
        nu = v["poisson_ratio"]
        if type(nu) not in _REAL or not -math.inf < nu < math.inf:
            return None
        g["poisson_ratio"] = float(nu)
    cv: dict[str, Any] = {"name": name, "from": a, "to": b}
    if "segments" in v:
        n = v["segments"]
        if type(n) is not int or n < 1:
            return None
        cv["segments"] = n
    if "arrangement" in v:
        if type(v["arrangement"]) is not str or v["arrangement"] not in ARRANGEMENTS:
            return None
        cv["arrangement"] = v["arrangement"]
    if "output" in v:
        cv["output"] = bool(v["output"])
    cv["geometry"] = g
    return cv


def _vessel(v: Any, i: int, units: str) -> dict[str, Any]:
    """The canonical form of vessel ``i``, checking every key and value."""
    L = factor(units, "length")
    el = (f"vessel '{v['name']}'" if isinstance(v, Mapping) and v.get("name") is not None
          else f"vessel #{i}")
    _check_keys(v, VESSEL_KEYS, el)
    for k in ("name", "from", "to"):
        if k not in v:
            raise _err(el, f"missing '{k}'")
        if not isinstance(v[k], (str, int)) or isinstance(v[k], bool):  # `name: null` is no name
            raise _err(el, f"'{k}' must be a name, got {v[k]!r}")
    cv: dict[str, Any] = {"name": str(v["name"]), "from": str(v["from"]), "to": str(v["to"])}
    if "segments" in v:
        n = v["segments"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise _err(el, f"'segments' must be an integer >= 1, got {n!r}")
        cv["segments"] = n
    if "arrangement" in v:
        if not isinstance(v["arrangement"], str) or v["arrangement"] not in ARRANGEMENTS:
            raise _err(el, f"arrangement must be one of {sorted(ARRANGEMENTS)}, got "
                           f"{v['arrangement']!r}")
        cv["arrangement"] = v["arrangement"]
    if "output" in v:
        cv["output"] = bool(v["output"])
    for key in ("initial", "initial_rate"):
        if key in v:
            cv[key] = _start_values(v[key], el, key, units)
    if "heart_pulmonary" in v or "coronary_bed" in v:
        return _closed_loop_element(v, cv, el, units)
    if "chamber_sphere" in v:
        return _sphere_element(v, cv, el, units)
    if "valve" in v or "chamber" in v or "through_rc" in v:
        return _heart_element(v, cv, el, units)
    if "lumped" in v:
        lp = v["lumped"]
        _check_keys(lp, LUMPED_KEYS, f"{el} lumped")
        q = {"resistance": "resistance", "inductance": "inductance",
             "capacitance": "capacitance", "stenosis_coefficient": "stenosis"}
        if "resistance" not in lp:
            raise _err(el, "lumped needs 'resistance'")
        # calibrated svZeroDSolver models carry negative stenosis coefficients: the core
        # accepts any finite one, so only R, L and C must be >= 0
        cv["lumped"] = {k: factor(units, q[k]) * (_number(lp[k], el, k)
                                                  if k == "stenosis_coefficient" else
                                                  _positive(lp[k], el, k, allow_zero=True))
                        for k in lp if k != "stenosis_form"}
        if "stenosis_form" in lp:
            if lp["stenosis_form"] not in STENOSIS_FORMS:
                raise _err(el, f"lumped stenosis_form must be one of {list(STENOSIS_FORMS)}, "
                               f"got {lp['stenosis_form']!r}")
            cv["lumped"]["stenosis_form"] = lp["stenosis_form"]
    else:
        if "length" not in v:
            raise _err(el, "missing 'length' (or give 'lumped' values)")
        if "radius" in v and ("radius_in" in v or "radius_out" in v):
            raise _err(el, "give 'radius' or 'radius_in'/'radius_out', not both")
        if "radius" in v:
            r_in = r_out = _positive(v["radius"], el, "radius")
        elif "radius_in" in v and "radius_out" in v:
            r_in = _positive(v["radius_in"], el, "radius_in")
            r_out = _positive(v["radius_out"], el, "radius_out")
        else:
            raise _err(el, "missing 'radius' (or 'radius_in' and 'radius_out')")
        g: dict[str, Any] = {"length": L * _positive(v["length"], el, "length"),
                             "radius_in": L * r_in, "radius_out": L * r_out}
        if "wall_thickness" in v:
            g["wall_thickness"] = L * _positive(v["wall_thickness"], el, "wall_thickness")
        if "youngs_modulus" in v:
            g["youngs_modulus"] = factor(units, "modulus") * _positive(
                v["youngs_modulus"], el, "youngs_modulus")
        if "poisson_ratio" in v:
            g["poisson_ratio"] = _number(v["poisson_ratio"], el, "poisson_ratio")
        cv["geometry"] = g
    return cv


def _closed_loop_element(v: Mapping[str, Any], cv: dict[str, Any], el: str, units: str
                         ) -> dict[str, Any]:
    """The canonical form of a ``heart_pulmonary`` or ``coronary_bed`` element
    (docs/physics.md §1.10)."""
    kinds = [k for k in ("heart_pulmonary", "coronary_bed", "valve", "chamber", "through_rc",
                         "lumped", "length") if k in v]
    if len(kinds) > 1:
        raise _err(el, f"give one of heart_pulmonary, coronary_bed, valve, chamber, through_rc, "
                       f"lumped or geometry, not {' and '.join(kinds)}")
    kind = kinds[0]
    spec = v[kind]
    if not isinstance(spec, Mapping):
        raise _err(el, f"'{kind}' must be a mapping")
    keys = HEART_PULMONARY_KEYS if kind == "heart_pulmonary" else CORONARY_BED_KEYS
    optional = HEART_PULMONARY_START if kind == "heart_pulmonary" else {}
    names = {"heart", "ventricle"} if kind == "coronary_bed" else set()
    _check_keys(spec, set(keys) | set(optional) | names, f"{el} {kind}")
    out: dict[str, Any] = {}
    for k, q in {**keys, **optional}.items():
        if k in spec:
            out[k] = (1.0 if q == "number" else _quantity(units, q)) * _number(spec[k], el, k)
        elif k in keys:
            raise _err(el, f"{kind} needs '{k}'")
    if kind == "coronary_bed":
        if not isinstance(spec.get("heart"), str):
            raise _err(el, "coronary_bed needs 'heart', the name of a heart_pulmonary element")
        if spec.get("ventricle") not in ("left", "right"):
            raise _err(el, f"coronary_bed ventricle must be 'left' or 'right', got "
                           f"{spec.get('ventricle')!r}")
        out["heart"], out["ventricle"] = spec["heart"], spec["ventricle"]
    cv[kind] = out
    return cv


def _sphere_element(v: Mapping[str, Any], cv: dict[str, Any], el: str, units: str
                    ) -> dict[str, Any]:
    """The canonical form of a ``chamber_sphere`` element (docs/physics.md §1.11)."""
    others = [k for k in ("valve", "chamber", "through_rc", "lumped", "length") if k in v]
    if others:
        raise _err(el, f"give one of chamber_sphere, {', '.join(others)}, not both")
    spec = v["chamber_sphere"]
    if not isinstance(spec, Mapping):
        raise _err(el, "'chamber_sphere' must be a mapping")
    _check_keys(spec, set(CHAMBER_SPHERE_KEYS), f"{el} chamber_sphere")
    for k in CHAMBER_SPHERE_KEYS:
        if k not in spec:
            raise _err(el, f"chamber_sphere needs '{k}'")
    cv["chamber_sphere"] = {k: _quantity(units, q) * _number(spec[k], el, k)
                            for k, q in CHAMBER_SPHERE_KEYS.items()}
    return cv


def _start_values(d: Any, el: str, key: str, units: str) -> dict[str, float]:
    """A vessel's ``initial`` (or ``initial_rate``: the same quantities per second) in SI."""
    if not isinstance(d, Mapping):
        raise _err(el, f"'{key}' must be a mapping of {sorted(START_KEYS)}")
    _check_keys(d, set(START_KEYS), f"{el} {key}")
    return {k: factor(units, START_KEYS[k]) * _number(x, el, f"{key} {k}") for k, x in d.items()}


def _quantity(units: str, q: str) -> float:
    if q == "1/pressure":
        return 1.0 / factor(units, "pressure")
    if q == "elastance":
        return 1.0 / factor(units, "capacitance")
    if q == "volume":
        return factor(units, "flow")
    if q == "1/volume":
        return 1.0 / factor(units, "flow")
    if q == "1/time":
        return 1.0 / factor(units, "time")
    return factor(units, q)


def _heart_element(v: Mapping[str, Any], cv: dict[str, Any], el: str, units: str
                   ) -> dict[str, Any]:
    """The canonical form of a ``valve`` or ``chamber`` element (docs/physics.md §1.8)."""
    kinds = [k for k in ("valve", "chamber", "through_rc", "lumped", "length") if k in v]
    if len(kinds) > 1:
        raise _err(el, f"give one of valve, chamber, through_rc, lumped or geometry, not "
                       f"{' and '.join(kinds)}")
    kind = kinds[0]
    spec = v[kind]
    if not isinstance(spec, Mapping):
        raise _err(el, f"'{kind}' must be a mapping")
    if kind == "through_rc":
        _check_keys(spec, set(THROUGH_RC_KEYS), f"{el} through_rc")
        for k in THROUGH_RC_KEYS:
            if k not in spec:
                raise _err(el, f"through_rc needs '{k}'")
        cv[kind] = {k: _quantity(units, q) * _number(spec[k], el, k)
                    for k, q in THROUGH_RC_KEYS.items()}
        return cv
    laws = VALVE_KEYS if kind == "valve" else CHAMBER_KEYS
    law = spec.get("law")
    if law not in laws:
        raise _err(el, f"{kind} law must be one of {sorted(laws)}, got {law!r}")
    keys = dict(laws[law], **(CHAMBER_COMMON if kind == "chamber" else {}))
    _check_keys(spec, set(keys) | {"law"} | ({"activation"} if kind == "chamber" else set()),
                f"{el} {kind}")
    out: dict[str, Any] = {"law": law}
    for k, q in keys.items():
        if k in spec:
            out[k] = _quantity(units, q) * _number(spec[k], el, k)
        elif k not in ("inductance", "initial_volume"):
            raise _err(el, f"{kind} needs '{k}'")
    if kind == "chamber":
        if out.get("initial_volume", 0.0) < 0.0:  # a blood volume (the core checks the rest)
            raise _err(el, f"chamber initial_volume must be >= 0, got "
                           f"{spec['initial_volume']!r}")
        act = spec.get("activation")
        if not isinstance(act, Mapping) or act.get("kind") not in ACTIVATION_KEYS:
            raise _err(el, f"chamber needs an 'activation' with kind one of "
                           f"{sorted(ACTIVATION_KEYS)}")
        _check_keys(act, ACTIVATION_KEYS[act["kind"]] | {"kind"}, f"{el} activation")
        for k in ACTIVATION_KEYS[act["kind"]]:
            if k not in act:
                raise _err(el, f"activation needs '{k}'")
        out["activation"] = {k: (x if k == "kind" else _number(x, el, k)) for k, x in act.items()}
    cv[kind] = out
    return cv


def _boundary_conditions(bcs: Mapping[str, Any], units: str
                         ) -> tuple[dict[str, Any], list[tuple[float, str]]]:
    """Canonical boundary conditions and the periods of their waveforms (with the element).
    Plain resistance and RCR outlets (one per leaf of a large tree) take a fast path; anything
    else goes through :func:`_boundary_condition`, which gives the precise error."""
    R, C, P = factor(units, "resistance"), factor(units, "capacitance"), factor(units, "pressure")
    out: dict[str, Any] = {}
    periods: list[tuple[float, str]] = []
    for node, bc in bcs.items():
        cb = _fast_outlet(bc, R, C, P)
        if cb is None:
            el = f"boundary condition '{node}'"
            cb = _boundary_condition(bc, units, el)
            for key in ("flow", "pressure", "intramyocardial_pressure"):
                w = cb.get(key)
                if isinstance(w, dict) and w["kind"] == "table" and len(w["time"]) > 1:
                    periods.append((w["time"][-1] - w["time"][0], el))
                elif isinstance(w, dict) and w["kind"] == "fourier":
                    periods.append((w["period"], el))
            if isinstance(cb.get("cycle_period"), float):  # a coronary's varying R_am
                periods.append((cb["cycle_period"], f"{el} cycle_period"))
        out[str(node)] = cb
    return out, periods


def _element_periods(vessels: list[dict[str, Any]]) -> list[tuple[float, str]]:
    """The cardiac periods of the heart elements (a `chamber`'s activation, a
    `heart_pulmonary` block), with the element: like a waveform's, each must equal the model
    period, or the chamber would beat out of step with the cycles that are run, output and
    tested for periodicity (docs/physics.md §1.8)."""
    out: list[tuple[float, str]] = []
    for v in vessels:
        for kind in ("chamber", "heart_pulmonary"):
            spec = v.get(kind)
            if isinstance(spec, dict) and "period" in spec:
                out.append((spec["period"], f"vessel '{v['name']}' {kind} (its activation)"))
    return out


def _finite(x: Any) -> bool:
    """A plain finite number (bool, str and None are not: they take the full check)."""
    return type(x) in _REAL and -math.inf < x < math.inf


def _fast_outlet(bc: Any, R: float, C: float, P: float) -> dict[str, Any] | None:
    """The canonical form of a resistance or RCR condition with plain finite values and a
    constant (or no) pressure, or None (the caller then runs the full check). Same result as
    :func:`_boundary_condition` for the conditions it takes; signs are the core's check."""
    if type(bc) is not dict:
        return None
    kind = bc.get("type")
    if kind not in ("rcr", "resistance") or not bc.keys() <= BC_KEYS[kind]:
        return None
    p = bc.get("pressure", 0.0)
    if not _finite(p):
        return None
    if kind == "resistance":
        r = bc.get("resistance")
        if not _finite(r):
            return None
        cb: dict[str, Any] = {"type": kind, "resistance": R * r}
    else:
        # one outlet per leaf of a large tree: the three checks inlined (no generator, no calls)
        rp, c, rd = bc.get("proximal_resistance"), bc.get("capacitance"), \
            bc.get("distal_resistance")
        if not (type(rp) in _REAL and type(c) in _REAL and type(rd) in _REAL
                and -math.inf < rp < math.inf and -math.inf < c < math.inf
                and -math.inf < rd < math.inf):
            return None
        cb = {"type": kind, "proximal_resistance": R * rp, "capacitance": C * c,
              "distal_resistance": R * rd}
    cb["pressure"] = {"kind": "constant", "value": P * p}
    return cb


def _boundary_condition(bc: Any, units: str, el: str) -> dict[str, Any]:
    """The canonical form of one boundary condition, checking every key and value."""
    if not isinstance(bc, Mapping) or "type" not in bc:
        raise _err(el, "needs a 'type' (flow, pressure, resistance, rcr or coronary)")
    kind = str(bc["type"]).lower()
    if kind not in BC_KEYS:
        raise _err(el, f"unknown type '{bc['type']}' (expected flow, pressure, resistance, rcr "
                       "or coronary)")
    _check_keys(bc, BC_KEYS[kind], el)
    cb: dict[str, Any] = {"type": kind}
    if kind == "flow":
        cb["flow"] = _waveform(bc, "flow", "flow", units, el)
    elif kind == "pressure":
        cb["pressure"] = _waveform(bc, "pressure", "pressure", units, el)
    elif kind == "coronary":
        return _coronary(bc, units, el)
    elif kind == "svzerod-inlet":
        for k, q in (("resistance", "resistance"), ("proximal_resistance", "resistance"),
                     ("capacitance", "capacitance"), ("distal_resistance", "resistance")):
            if k in bc:
                cb[k] = factor(units, q) * _number(bc[k], el, k)
        p = bc.get("pressure", 0.0)
        cb["pressure"] = _waveform({"pressure": p} if not isinstance(p, Mapping) else p,
                                   "pressure", "pressure", units, el)
    elif kind == "resistance":
        cb["resistance"] = factor(units, "resistance") * _number(bc.get("resistance"), el, "resistance")
        p = bc.get("pressure", 0.0)
        cb["pressure"] = _waveform({"pressure": p} if not isinstance(p, Mapping) else p,
                                   "pressure", "pressure", units, el)
    else:
        for k, q in (("proximal_resistance", "resistance"), ("capacitance", "capacitance"),
                     ("distal_resistance", "resistance")):
            if k not in bc:
                raise _err(el, f"rcr needs '{k}'")
            cb[k] = factor(units, q) * _number(bc[k], el, k)
        p = bc.get("pressure", 0.0)
        cb["pressure"] = _waveform({"pressure": p} if not isinstance(p, Mapping) else p,
                                   "pressure", "pressure", units, el)
    return cb


def _coronary(bc: Mapping[str, Any], units: str, el: str) -> dict[str, Any]:
    """The canonical form of a ``coronary`` outlet (numbers in SI; pressures as waveforms)."""
    for k in CORONARY_REQUIRED:
        if k not in bc:
            raise _err(el, f"coronary needs '{k}'")
    cb: dict[str, Any] = {"type": "coronary"}
    for k, q in CORONARY_QUANTITIES.items():
        if k in bc and bc[k] is not None:
            cb[k] = factor(units, q) * _number(bc[k], el, k)
    for k in ("intramyocardial_pressure", "pressure"):
        p = bc.get(k, 0.0)
        w = _waveform({"pressure": p} if not isinstance(p, Mapping) else p, "pressure", "pressure",
                      units, f"{el} {k}")
        cb[k] = w
    return cb


@dataclass
class Model:
    """A validated network model in SI units.

    ``canonical`` is the JSON-able description passed to the Rust core; ``simulation`` holds
    the run settings from the file (overridable in :func:`oxyline.simulate`).

    Once the core has assembled the model, its per-vessel canonical dicts are released (a
    whole tree's canonical vessels and outlets took ~185 B per segment beside the core's
    own tables; issue 9 item 6) and written again from ``source`` on first use
    (:meth:`release_canonical`); a run reads only the small transport section
    (:attr:`transport_spec`) and the vessel names.
    """

    name: str
    canonical: dict[str, Any]
    simulation: dict[str, Any] = field(default_factory=dict)
    period: float | None = None
    source: dict[str, Any] = field(default_factory=dict)
    #: species transport facts for results: ``species`` (names), ``oxygen`` (name of the O2
    #: species or None), ``solubility`` (O2, mol m^-3 mmHg^-1)
    transport: dict[str, Any] = field(default_factory=dict)
    #: the vessels output when the run selects none (None: all; structured-tree vessels are
    #: left out, see :mod:`oxyline.structured_tree`)
    default_output_vessels: list[str] | None = None
    _network: Any = field(default=None, repr=False, compare=False)
    #: the native dict ``canonical`` is written from again once released (None: kept)
    _rebuild: Any = field(default=None, repr=False, compare=False)
    #: the vessel names and the transport section of a released ``canonical``
    _kept: Any = field(default=None, repr=False, compare=False)

    def release_canonical(self, names: list[str] | None = None) -> None:
        """Drop ``canonical`` (the core holds the model); it is written again from the
        native dict it came from when next asked for, identical (the same conversion).
        ``names``: the vessel names, when ``canonical`` was written without its vessels."""
        canon = self.__dict__.get("_canonical")
        if canon is None or not self.source:  # nothing to write it again from
            return
        if names is None:
            names = [v["name"] for v in canon["vessels"]]
        self._kept = (names, canon.get("transport"))
        self._rebuild = self.source
        self.__dict__["_canonical"] = None

    @property
    def transport_spec(self) -> dict[str, Any] | None:
        """The canonical transport section (None without species), without writing a
        released ``canonical`` again."""
        if self.__dict__.get("_canonical") is None and self._kept is not None:
            return self._kept[1]
        return self.canonical.get("transport")

    @property
    def network(self) -> _core.Network:
        """The assembled Rust network (built on first use)."""
        if self._network is None:
            self._network = _network(self.canonical, self.simulation.get("max_memory"))
        return self._network

    @property
    def vessel_names(self) -> list[str]:
        if self.__dict__.get("_canonical") is None and self._kept is not None:
            return list(self._kept[0])
        return [v["name"] for v in self.canonical["vessels"]]

    def summary(self) -> dict[str, Any]:
        """Counts, totals and the RK4 stability limit (for ``oxyline validate``)."""
        s = dict(self.network.summary())
        dt_max, element, exact = self.network.rk4_stability_limit()
        s.update(rk4_dt_max=dt_max, rk4_limiting_element=element, rk4_limit_exact=exact,
                 period=self.period, name=self.name)
        return s

    def to_dict(self) -> dict[str, Any]:
        """The model as a plain dict in the user-facing schema (SI)."""
        return copy.deepcopy(self.source)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_network"] = None
        return state


def _get_canonical(self: Model) -> dict[str, Any]:
    canon = self.__dict__.get("_canonical")
    if canon is None and self._rebuild is not None:
        from oxyline.structured_tree import expanded

        canon = _unassembled(expanded(self._rebuild)).canonical
        self.__dict__["_canonical"] = canon
    return canon


def _set_canonical(self: Model, value: dict[str, Any]) -> None:
    self.__dict__["_canonical"] = value
    self._rebuild = self._kept = None


# a property over the dataclass field: the generated __init__, __eq__ and __repr__ go
# through it, so a released description is written again when they need it
Model.canonical = property(_get_canonical, _set_canonical)  # type: ignore[assignment]


def _plain_outlet(bc: Any) -> bool:
    """A canonical resistance or RCR condition with a constant (or no) pressure: the core
    reads it from the dict itself."""
    if type(bc) is not dict or bc.get("type") not in ("rcr", "resistance"):
        return False
    p = bc.get("pressure")
    return p is None or (type(p) is dict and p.get("kind") == "constant")


def _network(canonical: dict[str, Any], max_memory: Any = None,
             parts: Any = None) -> _core.Network:
    """The core network of a canonical model. The vessels and the plain outlets (the bulk of a
    large tree) are handed over as the dicts themselves, read key by key by the binding; the
    rest as JSON text. Writing the whole model as text cost ~2 µs per segment (the repr of
    every float, then the parse). The core refuses a model whose memory estimate exceeds
    ``max_memory`` (see :mod:`oxyline.memory`) before it allocates for it. ``parts``: the
    vessels and outlets :class:`_NativeReader` read from the native dict (not in
    ``canonical``)."""
    bcs = canonical.get("boundary_conditions")
    outlets, other = {}, {}
    if isinstance(bcs, dict):
        for node, bc in bcs.items():
            (outlets if _plain_outlet(bc) and type(node) is str else other)[node] = bc
    else:
        other = bcs
    rest = {k: v for k, v in canonical.items() if k not in ("vessels", "boundary_conditions")}
    rest["vessels"], rest["boundary_conditions"] = [], other
    rest["max_memory"] = _memory.limit(max_memory, "simulation: max_memory")
    vessels = canonical.get("vessels")
    if type(vessels) is not list:  # not a canonical model: the JSON parse reports it
        rest["vessels"], vessels = vessels, None
    # compact separators: the text is the core's input only (5 % less to write)
    return _core.Network(json.dumps(rest, separators=(",", ":")), vessels, outlets, parts)


class _NativeReader:
    """The vessels and outlets of a native model dict read by the core's binding
    (``_core.NativeParts``) instead of through a canonical dict per element: it takes the
    plain geometric vessels and resistance/RCR outlets (the bulk of a large tree) with the
    checks :func:`_fast_vessel` and :func:`_fast_outlet` make, and leaves every other element
    to :func:`_vessel` and :func:`_boundary_condition` (the full check and its precise error).
    Used as ``_unassembled``'s converters: the canonical description it gives has only the
    elements Python converted; ``parts`` holds all of them for :func:`_network`."""

    def __init__(self) -> None:
        self.parts: Any = None
        #: the vessels converted by :func:`_vessel` (every heart element is among them)
        self.converted: list[dict[str, Any]] = []

    def vessels(self, vessels: list[Any], units: str) -> list[dict[str, Any]]:
        self.parts = _core.NativeParts(vessels, factor(units, "length"),
                                       factor(units, "modulus"))
        for i in self.parts.slow_vessels():
            cv = _vessel(vessels[i], i, units)
            self.converted.append(cv)
            self.parts.put_vessel(i, cv)
        return []

    def boundary_conditions(self, bcs: Mapping[str, Any], units: str
                            ) -> tuple[dict[str, Any], list[tuple[float, str]]]:
        if type(bcs) is not dict:
            return _boundary_conditions(bcs, units)
        slow = self.parts.read_outlets(bcs, factor(units, "resistance"),
                                       factor(units, "capacitance"), factor(units, "pressure"))
        return _boundary_conditions({node: bcs[node] for node in slow}, units)


def build_model(data: dict[str, Any]) -> Model:
    """Validate a native model dict (the README schema) and assemble it."""
    return _build(_copy(dict(data)))


def _build(data: dict[str, Any]) -> Model:
    """The model of ``data``, which becomes the model's ``source``: callers pass a dict they
    own (a copy of the user's, or one they built)."""
    from oxyline.structured_tree import build_with_trees, has_trees

    if has_trees(data):  # a model-to-model step, like an importer
        return build_with_trees(data, _build_native)
    return _build_native(data)


def _build_native(data: dict[str, Any], grow: Callable[[Any], Any] | None = None) -> Model:
    """:func:`_build` of a model without structured-tree conditions; ``grow`` adds the
    structured trees to the parts the core reads (:func:`oxyline.structured_tree.build_with_trees`)."""
    # the bulk of the vessels and outlets goes to the core without canonical dicts; the
    # canonical description is written in full from ``source`` when asked for
    reader = _NativeReader()
    model = _unassembled(data, reader.vessels, reader.boundary_conditions)
    if grow is not None:
        grow(reader.parts)
    names = reader.parts.names()
    # assemble now so that invalid models fail at load time
    model._network = _network(model.canonical, model.simulation.get("max_memory"), reader.parts)
    sim = model.simulation
    out = sim.get("output") or {}
    if "variables" in out or "vessels" in out:  # unknown names fail at load time too
        model.network.output_layout(variables=output_names(out.get("variables"), "variables"),
                                    vessels=output_vessels(out.get("vessels", "all")))
    model.release_canonical(names)
    return model


def _unassembled(data: dict[str, Any], convert_vessels: Callable[..., Any] | None = None,
                 convert_boundary_conditions: Callable[..., Any] | None = None) -> Model:
    """The model of ``data`` with its canonical description, not yet assembled.
    ``convert_vessels`` and ``convert_boundary_conditions`` stand in for :func:`_vessels` and
    :func:`_boundary_conditions` (an ensemble reuses the base model's canonical elements that
    a variant leaves as they are)."""
    _check_keys(data, TOP_KEYS, "model")
    name = data.get("name", "network")
    if not isinstance(name, (str, int)) or isinstance(name, bool):
        raise _err("model", f"'name' must be a name, got {name!r}")
    name = str(name)
    units = str(data.get("units", "SI"))
    if units.lower() not in ("si", "cgs"):
        raise _err("model", f"units must be 'SI' or 'cgs', got {units!r}")
    L = factor(units, "length")
    blood = data.get("blood", {}) or {}
    _check_keys(blood, {"density", "viscosity"}, "blood")
    canon_blood = {
        "density": factor(units, "density") * _number(blood.get("density", 1050.0 / factor(units, "density")), "blood", "density"),
        "viscosity": factor(units, "viscosity") * _number(blood.get("viscosity", 3.5e-3 / factor(units, "viscosity")), "blood", "viscosity"),
    }
    arrangement = data.get("arrangement", "inverted-L")
    if not isinstance(arrangement, str) or arrangement not in ARRANGEMENTS - {"RCL"}:
        raise _err("model", f"arrangement must be inverted-L, L or pi, got {arrangement!r}")
    seg = data.get("segmentation", {}) or {}
    _check_keys(seg, {"max_length"}, "segmentation")
    canon: dict[str, Any] = {
        "name": name,
        "blood": canon_blood,
        "arrangement": arrangement,
        "wall_model": data.get("wall_model", "thin"),
        "inertance_profile": data.get("inertance_profile", "flat"),
        "vessels": [],
        "boundary_conditions": {},
    }
    if canon["wall_model"] not in ("thin", "thick"):
        raise _err("model", f"wall_model must be 'thin' or 'thick', got {canon['wall_model']!r}")
    if canon["inertance_profile"] not in ("flat", "poiseuille"):
        raise _err("model", f"inertance_profile must be 'flat' or 'poiseuille', got "
                            f"{canon['inertance_profile']!r}")
    if "max_length" in seg:
        canon["max_segment_length"] = L * _number(seg["max_length"], "segmentation", "max_length")
    vessels = data.get("vessels")
    if not isinstance(vessels, list) or not vessels:
        raise _err("model", "'vessels' must be a non-empty list")
    canon["vessels"] = (convert_vessels or _vessels)(vessels, units)
    bcs = data.get("boundary_conditions", {})
    if not isinstance(bcs, Mapping):
        raise _err("model", "'boundary_conditions' must be a mapping from node name to condition")
    canon["boundary_conditions"], periods = (convert_boundary_conditions
                                             or _boundary_conditions)(bcs, units)
    period = data.get("period")
    if period is not None:
        period = _number(period, "model", "period")
        if period <= 0:
            raise _err("model", f"period must be > 0, got {period}")
    period_source = "the model period is"
    # the native reader's canonical vessel list is empty: its converted vessels hold the rest
    converted = getattr(getattr(convert_vessels, "__self__", None), "converted", [])
    for p, el in periods + _element_periods(canon["vessels"] or converted):
        if period is None:
            period, period_source = p, f"{el} repeats every"
        elif abs(p - period) > 1e-9 * period:
            raise _err(el, f"period mismatch: it repeats every {p:g} s but "
                           f"{period_source} {period:g} s")
    sim = data.get("simulation", {}) or {}
    _check_keys(sim, SIM_KEYS, "simulation")
    if "output" in sim:
        _check_keys(sim["output"], OUTPUT_KEYS, "simulation output")
    if "method" in sim and (not isinstance(sim["method"], str) or sim["method"] not in METHODS):
        raise _err("simulation", f"method must be one of {sorted(METHODS)}, got {sim['method']!r}")
    from oxyline import transport as _transport

    cycles = sim.get("max_cycles", 100) if sim.get("until_periodic") else sim.get("cycles", 10)
    duration = (period or 1.0) * float(cycles) if isinstance(cycles, (int, float)) else None
    tr, tr_info = _transport.canonical(data, factor(units, "pressure"), period, duration)
    if tr is not None:
        _transport.add_blood(tr, canon["blood"])
        canon["transport"] = tr
    # ``data`` is the caller's private copy (load_model, build_model) and is only read here
    return Model(name=name, canonical=canon, simulation=dict(sim), period=period, source=data,
                 transport=tr_info)
