"""svZeroDSolver drop-in: run svZeroDSolver JSON inputs with oxyline's core.

:func:`simulate` takes an svZeroDSolver configuration (a dict or a path to a JSON file) and
returns the same pandas DataFrame as ``svzerod.simulate``: for vessel-based output columns
``name, time, flow_in, flow_out, pressure_in, pressure_out`` (and ``d_*`` with
``output_derivative``), rows grouped by vessel in file order; with ``output_variable_based``
columns ``name, time, y`` (and ``ydot``), rows grouped by svZeroDSolver variable. The frame holds the file's own numbers, as svZeroDSolver's does (the equations are
unit-agnostic), and names their units in ``df.attrs["units"]``: cgs (cm, dyn/cm², mL/s), the
svZeroDSolver convention, unless the file has a top-level ``"units": "SI"`` (oxyline's exporter
writes it; svZeroDSolver ignores it) or ``units="SI"`` is passed. :func:`to_model` (and
``oxyline.load_model``/``oxyline run`` on such a file) converts to SI like any oxyline model,
so results, files, the console table and plots are in the units they say. With the default ``method="generalized-alpha"`` the time stepping, the steady
initialisation and the Newton stopping rule are svZeroDSolver's, so results agree with the
peer's to round-off.

Every svZeroDSolver element and option (details and measured errors in ``docs/svzerod.md``):

======================================================  ===========  ===================
Example::

    import oxyline.svzerod as svz

    config = {
        "simulation_parameters": {"number_of_cardiac_cycles": 2,
                                  "number_of_time_pts_per_cardiac_cycle": 5},
        "boundary_conditions": [
            {"bc_name": "INFLOW", "bc_type": "FLOW", "bc_values": {"Q": [5.0, 5.0], "t": [0.0, 1.0]}},
            {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 100.0}},
        ],
        "vessels": [
            {"vessel_id": 0, "vessel_name": "aorta", "zero_d_element_type": "BloodVessel",
             "zero_d_element_values": {"R_poiseuille": 100.0, "C": 1e-4},
             "boundary_conditions": {"inlet": "INFLOW", "outlet": "OUT"}},
        ],
    }
    df = svz.simulate(config)                 # same frame as svzerod.simulate(config)
    print(df.round(6).iloc[0].to_dict())
    # {'name': 'aorta', 'time': 0.0, 'flow_in': 5.0, 'flow_out': 5.0,
    #  'pressure_in': 1100.0, 'pressure_out': 600.0}
    df_rk4 = svz.simulate(config, method="rk4")   # explicit RK4, same output times
    model = svz.to_model(config)              # an oxyline.Model, for oxyline.simulate etc.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oxyline.errors import ModelError, UnsupportedElement
from oxyline.io import (
    svzerod_closed_loop,
    svzerod_coupling,
    svzerod_cycles,
    svzerod_heart,
    svzerod_initial,
)
from oxyline.model import Model, _build, _copy

COLUMNS = ("name", "time", "flow_in", "flow_out", "pressure_in", "pressure_out")
METHODS = ("generalized-alpha", "rk4")
#: RK4 sub-steps per output step, at least, when time derivatives are output (their error is
#: then far below that of svZeroDSolver's own first-order ẏ)
RK4_DERIVATIVE_SUBSTEPS = 20

TOP_KEYS = {"simulation_parameters", "boundary_conditions", "vessels", "junctions", "units",
            "valves", "chambers", "initial_condition", "initial_condition_d",
            "closed_loop_blocks"}
# svZeroDSolver's equations do not depend on units and its files do not say which they use; by
# its convention (and SimVascular's) they are cgs. oxyline's exporter writes a top-level
# ``units`` ("cgs" or "SI"), which svZeroDSolver ignores and this importer reads.
DEFAULT_UNITS = "cgs"
#: units of the drop-in's DataFrame columns, per unit system of the file
FRAME_UNITS = {
    "cgs": {"time": "s", "flow_in": "mL/s", "flow_out": "mL/s", "pressure_in": "dyn/cm^2",
            "pressure_out": "dyn/cm^2"},
    "SI": {"time": "s", "flow_in": "m^3/s", "flow_out": "m^3/s", "pressure_in": "Pa",
           "pressure_out": "Pa"},
}
# `description` is free text; the calibrator's observations and settings do not change a forward
# simulation, and svZeroDSolver ignores them too
TOP_IGNORED = {"description", "calibration_parameters", "y", "dy"}
TOP_UNSUPPORTED: dict[str, str] = {}
SIM_KEYS = {
    "number_of_cardiac_cycles", "number_of_time_pts_per_cardiac_cycle", "absolute_tolerance",
    "maximum_nonlinear_iterations", "steady_initial", "rho_infty", "output_variable_based",
    "output_mean_only", "output_derivative", "output_all_cycles", "output_interval",
    "cardiac_period", "use_cycle_to_cycle_error", "sim_cycle_to_cycle_percent_error",
    "coupled_simulation", "number_of_time_pts", "external_step_size",
}
# written by SimVascular's model builders and ignored by svZeroDSolver
SIM_IGNORED = {"density", "viscosity", "model_name"}
# boolean options oxyline cannot honour when true
SIM_UNSUPPORTED_FLAGS = {
    "coupled_simulation": "3D-0D coupled simulation",
}
VESSEL_KEYS = {"vessel_id", "vessel_name", "zero_d_element_type", "zero_d_element_values",
               "boundary_conditions", "vessel_length", "calibrate"}
JUNCTION_KEYS = {"junction_name", "junction_type", "inlet_vessels", "outlet_vessels",
                 "inlet_blocks", "outlet_blocks", "junction_values", "calibrate"}
BC_ENTRY_KEYS = {"bc_name", "bc_type", "bc_values"}
VESSEL_TYPES = {"BloodVessel", "BloodVesselCRL", "BloodVesselRC", "ChamberSphere"}
NORMAL_JUNCTIONS = {"NORMAL_JUNCTION", "internal_junction"}
JUNCTION_TYPES = NORMAL_JUNCTIONS | {"BloodVesselJunction", "resistive_junction"}
# block types this importer knows and cannot translate, with the reason (other unknown types
# are refused with the list of supported ones)
UNSUPPORTED_TYPES: dict[str, str] = {}
BLOOD_VESSEL_PARAMS = {"R_poiseuille", "C", "L", "stenosis_coefficient"}
#: BloodVesselRC's parameters (a native ``through_rc`` element, docs/physics.md §1.8)
RC_VESSEL_PARAMS = {"Rpd", "Cp"}
BVJ_PARAMS = ("R_poiseuille", "L", "stenosis_coefficient")
BC_PARAMS = {
    "FLOW": {"Q", "t"},
    "PRESSURE": {"P", "t"},
    "RESISTANCE": {"R", "Pd"},
    "RCR": {"Rp", "C", "Rd", "Pd"},
    **svzerod_heart.BC_PARAMS,
    **svzerod_closed_loop.BC_PARAMS,
}


@dataclass
class _Layout:
    """Where the drop-in's outputs come from: the recorded end values (pressure_in,
    pressure_out, flow_in, flow_out) of the native vessels."""

    #: svZeroDSolver vessel -> (native vessel of its inlet end, native vessel of its outlet end)
    vessels: list[tuple[str, str, str]] = field(default_factory=list)
    #: svZeroDSolver's nodes (upstream block, downstream block) in the order it numbers them
    connections: list[tuple[str, str]] = field(default_factory=list)
    #: internal variables: ("rcr", name, Rp), ("junction", name, (hidden vessel, 0 or 1: its
    #: pressure_in or pressure_out is the junction's centre)), ("ClosedLoopRCR" or
    #: "ClosedLoopCoronary", name, native vessel), ("CORONARY", name, C_im: an open-loop
    #: coronary's volume_im), ("heart", name, None), ("valve", name,
    #: None: a tanh valve's status); output in svZeroDSolver's block order (see
    #: ``INTERNAL_ORDER``), ChamberSphere wall variables first and ``Vc`` last
    internal: list[tuple[str, str, Any]] = field(default_factory=list)
    #: blocks svZeroDSolver leaves out of its vessel-based table (chambers, valves,
    #: BloodVesselRC): in ``vessels`` only for the variable table's node lookup
    not_vessels: set[str] = field(default_factory=set)
    #: ChamberSphere vessels, whose wall variables follow the nodes in the variable table
    spheres: list[str] = field(default_factory=list)


@dataclass
class RunSettings:
    """svZeroDSolver run settings, resolved (period, cycle count after the cycle-to-cycle
    rule, step size)."""

    period: float
    cycles: int
    points_per_cycle: int
    dt: float
    output_interval: int
    output_all_cycles: bool
    output_mean_only: bool
    steady_initial: bool
    rho_infty: float
    absolute_tolerance: float
    max_iterations: int
    #: the file's unit system, "cgs" or "SI" (its numbers are kept as they are here)
    units: str = DEFAULT_UNITS
    #: one row per svZeroDSolver variable (name, time, y) instead of per vessel
    output_variable_based: bool = False
    #: add the time derivatives (d_* columns, or ydot)
    output_derivative: bool = False
    #: svZeroDSolver's cycle-to-cycle rule without RCR: the relative error of the vessel caps'
    #: cycle means that ends the run (extra cycles), else None; the caps (vessel, "in"/"out")
    cycle_error: float | None = None
    caps: list[tuple[str, str]] = field(default_factory=list)
    #: record every unknown of the core (the chambers' volumes are no vessel column)
    all_unknowns: bool = False
    #: RK4 sub-steps per output step (None: from the stability bound and the time tables)
    rk4_substeps: int | None = None


# ------------------------------------------------------------------------------------------
# reading and checking


def _read_config(config: Mapping[str, Any] | str | os.PathLike[str]) -> dict[str, Any]:
    if isinstance(config, Mapping):
        return _copy(dict(config))
    from oxyline.io.native import read_mapping

    return read_mapping(config)


def _is_comment(key: str) -> bool:
    return isinstance(key, str) and key.startswith("_")


def _mapping(d: Any, element: str) -> Mapping[str, Any]:
    if not isinstance(d, Mapping):
        raise ModelError(f"{element}: expected a JSON object, got {type(d).__name__}")
    return d


def _check_params(d: Any, allowed: set[str] | tuple[str, ...], element: str) -> Mapping[str, Any]:
    d = _mapping(d, element)
    for k in d:
        if not _is_comment(k) and k not in allowed:
            raise UnsupportedElement(
                f"{element}: unknown parameter '{k}' (supported: {', '.join(sorted(allowed))})")
    return d


def _num(v: Any, element: str, key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ModelError(f"{element}: '{key}' must be a number, got {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise ModelError(f"{element}: '{key}' must be finite, got {x}")
    return x


def _numlist(v: Any, element: str, key: str) -> list[float]:
    if not isinstance(v, (list, tuple)):
        raise ModelError(f"{element}: '{key}' must be a list of numbers (svZeroDSolver reads "
                         f"it as an array), got {v!r}")
    return [_num(x, element, f"{key}[{i}]") for i, x in enumerate(v)]


def _entry(raw: Any, where: str, name_key: str, label: str, allowed: Any, type_key: str,
           types: Any) -> tuple[Mapping[str, Any], str, str, str]:
    """Check one entry of a section list (vessel, junction, boundary condition): a mapping with a
    name, only known keys and a supported type (an unsupported one is refused with the reason
    from ``UNSUPPORTED_TYPES`` when it has one). Returns (entry, name, type, element label)."""
    entry = _mapping(raw, where)
    name = str(_required(entry, name_key, where))
    el = f"{label} '{name}'"
    for k in entry:
        if k not in allowed and not _is_comment(k):
            raise UnsupportedElement(f"{el}: unknown key '{k}'")
    kind = _required(entry, type_key, el)
    if isinstance(kind, str) and kind in UNSUPPORTED_TYPES:
        raise UnsupportedElement(f"{el}: {type_key} '{kind}' is not supported: "
                                 f"{UNSUPPORTED_TYPES[kind]}")
    if not isinstance(kind, str) or kind not in types:
        raise UnsupportedElement(f"{el}: {type_key} '{kind}' is not supported (supported: "
                                 f"{', '.join(sorted(types))})")
    return entry, name, kind, el


def _required(d: Mapping[str, Any], key: str, element: str) -> Any:
    if key not in d:
        raise ModelError(f"{element}: missing '{key}'")
    return d[key]


def _flag(sim: Mapping[str, Any], key: str, default: bool) -> bool:
    v = sim.get(key, default)
    if not isinstance(v, bool):
        raise ModelError(f"simulation_parameters: '{key}' must be true or false, got {v!r}")
    return v


def _int(sim: Mapping[str, Any], key: str, default: int | None, minimum: int) -> int:
    if key not in sim and default is not None:
        return default
    v = _required(sim, key, "simulation_parameters")
    if isinstance(v, float) and v.is_integer():  # JSON 10.0, read as an integer by svZeroDSolver
        v = int(v)
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise ModelError(f"simulation_parameters: '{key}' must be an integer >= {minimum}, "
                         f"got {v!r}")
    return v


# ------------------------------------------------------------------------------------------
# time tables


def _periodic_table(t: list[float], v: list[float], element: str) -> tuple[list[float], list[float]]:
    """Time table over [0, P] that reproduces svZeroDSolver's lookup ``fmod(time, P)`` with
    P = t[-1] - t[0] (linear extrapolation of the first segment below t[0])."""
    for i in range(1, len(t)):
        if t[i] <= t[i - 1]:
            raise ModelError(f"{element}: 't' must be strictly increasing: t[{i}] = {t[i]} <= "
                             f"t[{i - 1}] = {t[i - 1]}")
    if t[0] == 0.0:
        return t, v
    if t[0] < 0.0:
        raise UnsupportedElement(f"{element}: a time table starting before 0 (t[0] = {t[0]}) "
                                 "is not supported")
    period = t[-1] - t[0]

    def f(r: float) -> float:
        k = next((i for i, x in enumerate(t) if x >= r), len(t) - 1)
        m = k - 1 if k else 1
        return v[m] + (v[k] - v[m]) / (t[k] - t[m]) * (r - t[m])

    times = [0.0] + [x for x in t if x < period] + [period]
    return times, [f(x) for x in times]


# ------------------------------------------------------------------------------------------
# conversion


def _crl_vessels(name: str, lumped: Mapping[str, float]) -> tuple[dict[str, Any], dict[str, Any]]:
    """svZeroDSolver's BloodVesselCRL: Q_in - Q_out = C dP_in/dt and
    P_in - P_out = (R + S|Q_out|) Q_out + L dQ_out/dt, so its capacitor sits at the inlet and
    its flow_in includes the capacitor's flow. Two RCL vessels give exactly these equations:
    ``name`` (R = 0 into its capacitor node, L = 0 out of it; its flow_in and pressure_in are
    the CRL's, also where the inlet pressure is prescribed) and the hidden ``name:RL`` (R,
    stenosis and L with C = 0; its flow_out and pressure_out are the CRL's)."""
    what = f"svZeroDSolver BloodVesselCRL '{name}'"
    front = {"name": name, "arrangement": "RCL", "description": f"{what}: its capacitor",
             "lumped": {"resistance": 0.0, "capacitance": lumped["capacitance"]}}
    back = {"name": f"{name}:RL", "arrangement": "RCL", "output": False,
            "description": f"{what}: its R-L part",
            "lumped": {"resistance": lumped["resistance"], "inductance": lumped["inductance"],
                       "stenosis_coefficient": lumped["stenosis_coefficient"]}}
    return front, back


def _check_period(cfg: Mapping[str, Any], sim: Mapping[str, Any]) -> None:
    """svZeroDSolver's period consistency rules, checked over every block (also unsupported
    ones, so that a mismatch is reported as such): each time table of a boundary condition
    spans t[-1] - t[0], a ClosedLoopHeartAndPulmonary block has its cardiac_cycle_period, and
    all of these and ``cardiac_period`` must be exactly equal."""
    found: list[tuple[float, str]] = []
    bc_list = cfg.get("boundary_conditions")
    for b in bc_list if isinstance(bc_list, list) else []:
        vals = b.get("bc_values") if isinstance(b, Mapping) else None
        if not isinstance(vals, Mapping) or not isinstance(vals.get("t"), list):
            continue
        t = vals["t"]
        for k, v in vals.items():
            if k != "t" and isinstance(v, list) and len(v) > 1 and len(t) > 1 and all(
                    isinstance(x, (int, float)) for x in (t[0], t[-1])):
                found.append((float(t[-1]) - float(t[0]),
                              f"boundary condition '{b.get('bc_name')}' ({k})"))
    blocks = cfg.get("closed_loop_blocks")
    for c in blocks if isinstance(blocks, list) else []:
        if isinstance(c, Mapping) and isinstance(c.get("cardiac_cycle_period"), (int, float)):
            where = f"closed-loop block '{c.get('closed_loop_type')}'"
            found.append((float(c["cardiac_cycle_period"]), where))
    ref = None
    for p, where in found:
        if ref is None:
            ref = (p, where)
        elif p != ref[0]:
            raise ModelError(f"{where}: Inconsistent cardiac cycle period defined in parameters "
                             f"({p}, but {ref[1]} has {ref[0]})")
    sim_period = sim.get("cardiac_period", -1.0)
    if ref is not None and isinstance(sim_period, (int, float)) and sim_period >= 0 \
            and sim_period != ref[0]:
        raise ModelError(f"simulation_parameters: Inconsistent cardiac cycle period defined in "
                         f"parameters (cardiac_period = {sim_period}, but {ref[1]} has a "
                         f"period of {ref[0]})")


def file_units(cfg: Mapping[str, Any], units: str | None = None) -> str:
    """The unit system of an svZeroDSolver config: ``units`` if given, else the file's own
    top-level ``units`` key (written by oxyline's exporter), else cgs (svZeroDSolver's
    convention)."""
    value = units if units is not None else cfg.get("units", DEFAULT_UNITS)
    if not isinstance(value, str) or value.lower() not in ("cgs", "si"):
        raise ModelError(f"model: units must be 'cgs' or 'SI', got {value!r}")
    return "cgs" if value.lower() == "cgs" else "SI"


def _junctions(junctions: Any, ids: Mapping[Any, str], bcs: Mapping[str, Any],
               vessel_names: set[str], attach: Any, layout: _Layout) -> list[dict[str, Any]]:
    """svZeroDSolver's junctions: shared nodes (NORMAL_JUNCTION), or hidden vessels around
    a node (BloodVesselJunction, resistive_junction), attached to the vessels' ends with
    ``attach``; their svZeroDSolver nodes and internal variables go to ``layout``. Returns the
    hidden vessels."""
    if not isinstance(junctions, list):
        raise ModelError("junctions: must be a list")
    hidden: list[dict[str, Any]] = []
    for i, j in enumerate(junctions):
        j, jname, kind, el = _entry(j, f"junctions[{i}]", "junction_name", "junction",
                                    JUNCTION_KEYS, "junction_type", JUNCTION_TYPES)
        el = f"{kind} '{jname}'"
        if jname in bcs or jname in vessel_names:
            raise ModelError(f"{el}: name already used by another block")

        def resolve(key: str, by_id: bool, j: Mapping[str, Any] = j, el: str = el) -> list[str]:
            items = j[key]
            if not isinstance(items, list):
                raise ModelError(f"{el}: '{key}' must be a list")
            out = []
            for x in items:
                if isinstance(x, bool) or not isinstance(x, (int, str)):
                    raise ModelError(f"{el}: '{key}' must list vessel ids or names, got {x!r}")
                if by_id:
                    if x not in ids:
                        raise ModelError(f"{el}: '{key}' names vessel_id {x!r}, which no vessel has")
                    out.append(ids[x])
                elif x in vessel_names:
                    out.append(str(x))
                elif x in bcs:
                    raise UnsupportedElement(f"{el}: connecting boundary condition '{x}' to a "
                                             "junction is not supported")
                else:
                    raise ModelError(f"{el}: '{key}' names block '{x}', which is not defined")
            return out

        if "inlet_vessels" in j and "outlet_vessels" in j:
            inlets, outlets = resolve("inlet_vessels", True), resolve("outlet_vessels", True)
        elif "inlet_blocks" in j and "outlet_blocks" in j:
            inlets, outlets = resolve("inlet_blocks", False), resolve("outlet_blocks", False)
        else:
            raise ModelError(f"{el}: needs 'inlet_vessels' and 'outlet_vessels' (vessel ids) or "
                             "'inlet_blocks' and 'outlet_blocks' (names)")
        what = f"junction '{jname}'"
        layout.connections += [(name, jname) for name in inlets]
        layout.connections += [(jname, name) for name in outlets]
        if kind in NORMAL_JUNCTIONS:
            _check_params(j.get("junction_values", {}), set(), el)
            for name in inlets:
                attach(name, "out", jname, what)
            for name in outlets:
                attach(name, "in", jname, what)
            continue
        if kind == "resistive_junction":
            # P_in,i - P_c = R_i Q_in,i and P_c - P_out,k = R_k Q_out,k around a centre node
            # (svZeroDSolver's ResistiveJunction): one hidden R vessel per port, R listed for
            # the inlets, then the outlets
            vals = _check_params(_required(j, "junction_values", el), {"R"}, el)
            r = _numlist(_required(vals, "R", el), el, "R")
            if len(r) != len(inlets) + len(outlets):
                raise ModelError(f"{el}: 'R' has {len(r)} entries for {len(inlets)} inlets and "
                                 f"{len(outlets)} outlets")
            ports = [(name, f"{name}:{jname}", jname) for name in inlets]
            ports += [(name, jname, f"{jname}:{name}") for name in outlets]
            for k, (name, a, b) in enumerate(ports):
                hidden.append({"name": a if k < len(inlets) else b, "from": a, "to": b,
                               "arrangement": "RCL", "output": False,
                               "lumped": {"resistance": r[k]}})
                attach(name, "out" if k < len(inlets) else "in", hidden[-1]["name"], what)
            # its pressure_c: the centre end of the last port's hidden vessel
            layout.internal.append(("junction", jname, (hidden[-1]["name"], 0 if outlets else 1)))
            continue
        # BloodVesselJunction: one inlet, an R(+S)-L branch (no C) to every outlet
        vals = _check_params(_required(j, "junction_values", el), BVJ_PARAMS, el)
        if len(inlets) != 1:
            raise UnsupportedElement(f"{el}: {len(inlets)} inlets; a BloodVesselJunction has "
                                     "exactly one")
        lists = {}
        for key in BVJ_PARAMS:
            lists[key] = _numlist(_required(vals, key, el), el, key)
            if len(lists[key]) != len(outlets):
                raise ModelError(f"{el}: '{key}' has {len(lists[key])} entries for "
                                 f"{len(outlets)} outlets")
        attach(inlets[0], "out", jname, what)
        for k, name in enumerate(outlets):
            node = f"{jname}:{name}"
            hidden.append({
                "name": node, "from": jname, "to": node, "arrangement": "RCL", "output": False,
                "lumped": {"resistance": lists["R_poiseuille"][k], "capacitance": 0.0,
                           "inductance": lists["L"][k],
                           "stenosis_coefficient": lists["stenosis_coefficient"][k]},
            })
            attach(name, "in", node, what)

    return hidden

def _heart_elements(cfg: Mapping[str, Any], period: float, vessels: list[dict[str, Any]],
                    layout: _Layout, bcs: Mapping[str, Any], used_bcs: dict[str, str],
                    attach: Any) -> None:
    """svZeroDSolver's ``chambers`` and ``valves`` as native ``chamber`` and ``valve``
    elements (appended to ``vessels``), each valve joined to its upstream and downstream
    blocks (a vessel's free end, a chamber, another valve or a boundary condition)."""
    initial = _mapping(cfg.get("initial_condition", {}), "initial_condition")
    names = {v["name"] for v in vessels}
    for c in svzerod_heart._entries(cfg.get("chambers", []), "chambers"):
        if c["name"] in names or c["name"] in bcs:
            raise ModelError(f"chamber '{c['name']}': name already used by another block")
        native = svzerod_heart.chamber(c, period, initial, _num)
        vessels.append({"name": c["name"], "chamber": native,
                        "description": f"svZeroDSolver {c.get('type')}"})
        layout.vessels.append((c["name"], c["name"], c["name"]))
        layout.not_vessels.add(c["name"])
        names.add(c["name"])
    valves = svzerod_heart._entries(cfg.get("valves", []), "valves")
    for v in valves:
        if v["name"] in names or v["name"] in bcs:
            raise ModelError(f"valve '{v['name']}': name already used by another block")
        names.add(v["name"])
    for v in valves:
        native, up, down = svzerod_heart.valve(v, _num)
        name = v["name"]
        vessels.append({"name": name, "valve": native,
                        "description": f"svZeroDSolver {v.get('type')}"})
        layout.vessels.append((name, name, name))
        layout.not_vessels.add(name)
        if native["law"] == "tanh":  # its valve_status (svZeroDSolver's ValveTanh only)
            layout.internal.append(("valve", name, None))
        for block, end, other_end in ((up, "in", "out"), (down, "out", "in")):
            what = f"valve '{name}'"
            if block in bcs:
                if block in used_bcs:
                    raise ModelError(f"boundary condition '{block}': connected to both "
                                     f"{used_bcs[block]} and {what}")
                used_bcs[block] = what
                attach(name, end, block, f"boundary condition '{block}'")
            elif block in names:
                node = f"{up}:{name}" if end == "in" else f"{name}:{down}"
                attach(name, end, node, what)
                attach(block, other_end, node, what)
            else:
                raise ModelError(f"{what}: its {'upstream' if end == 'in' else 'downstream'}_block "
                                 f"'{block}' is not defined")
        layout.connections += [(up, name), (name, down)]
    # the other initial_condition entries: svzerod_initial.apply


def _closed_loop_layout(cfg: Mapping[str, Any], vessels: list[dict[str, Any]],
                        bcs: Mapping[str, Any], layout: _Layout) -> list[tuple[str, str]]:
    """The heart block and the closed-loop conditions in the variable table: each as a block
    whose ends are those of its native vessels (svZeroDSolver has no vessel row for them), the
    heart's internal variables, and svZeroDSolver's nodes around the heart, in its order: the
    heart's inlet, each closed-loop condition into it (file order), the heart's outlet, the
    outlet into each of its ``outlet_blocks`` (a vessel, or a coupling block's wire)."""
    cl = svzerod_closed_loop
    if not any(v["name"] == cl.HEART and "heart_pulmonary" in v for v in vessels):
        return []
    outlets = next(b["outlet_blocks"] for b in cfg["closed_loop_blocks"]
                   if b.get("closed_loop_type") == "ClosedLoopHeartAndPulmonary")
    layout.vessels.append((cl.HEART, cl.HEART, cl.HEART))
    layout.not_vessels.add(cl.HEART)
    layout.internal.append(("heart", cl.HEART, None))
    nodes = [(cl.HEART_INLET, cl.HEART)]
    for name, (kind, _) in bcs.items():
        if kind == "ClosedLoopRCR":
            layout.vessels.append((name, f"{name}:proximal", f"{name}:distal"))
        elif kind in cl.CORONARY_TYPES:
            layout.vessels.append((name, f"{name}:bed", f"{name}:bed"))
        else:
            continue
        layout.not_vessels.add(name)
        nodes.append((name, cl.HEART_INLET))
    return nodes + [(cl.HEART, cl.HEART_OUTLET)] + [(cl.HEART_OUTLET, o) for o in outlets]


def _convert(config: Mapping[str, Any] | str | os.PathLike[str], units: str | None = None
             ) -> tuple[dict[str, Any], RunSettings, _Layout]:
    """svZeroDSolver config -> (oxyline native dict, svZeroDSolver run settings, output
    layout). The dict keeps the file's numbers and says their ``units`` (so a model built from
    it is in SI)."""
    cfg = _read_config(config)
    # coupling blocks with prescribed values are ordinary conditions (svzerod_coupling)
    cfg, wires, wire_ends = svzerod_coupling.as_forward(cfg)
    layout = _Layout()
    system = file_units(cfg, units)
    if "simulation_parameters" not in cfg:
        bad = [k for k in ("calibration_parameters", "y", "dy") if k in cfg]
        if bad:
            raise UnsupportedElement(f"model: '{bad[0]}' without 'simulation_parameters' is an "
                                     "svZeroDCalibrator input; calibration is not supported")
        raise ModelError("model: missing 'simulation_parameters' (Define simulation_parameters)")
    if "boundary_conditions" not in cfg:
        raise ModelError("model: missing 'boundary_conditions' (Define at least one boundary "
                         "condition)")
    # svZeroDSolver rejects an inconsistent period while loading, before anything else fails
    _check_period(cfg, _mapping(cfg["simulation_parameters"], "simulation_parameters"))
    for k in cfg:
        if k in TOP_KEYS or k in TOP_IGNORED or _is_comment(k):
            continue
        if k in TOP_UNSUPPORTED:
            if cfg[k]:
                raise UnsupportedElement(f"model: '{k}' ({TOP_UNSUPPORTED[k]}) is not supported")
            continue
        raise UnsupportedElement(f"model: unknown top-level key '{k}'")

    # ---- simulation parameters
    sim = _mapping(cfg["simulation_parameters"], "simulation_parameters")
    for k in sim:
        if _is_comment(k) or k in SIM_IGNORED:
            continue
        if k not in SIM_KEYS:
            raise UnsupportedElement(f"simulation_parameters: unknown key '{k}'")
    for k, what in SIM_UNSUPPORTED_FLAGS.items():
        if _flag(sim, k, False):
            raise UnsupportedElement(f"simulation_parameters: '{k}' ({what}) is not supported")
    cycles = _int(sim, "number_of_cardiac_cycles", None, 1)
    pts = _int(sim, "number_of_time_pts_per_cardiac_cycle", None, 2)
    interval = _int(sim, "output_interval", 1, 1)
    max_iter = _int(sim, "maximum_nonlinear_iterations", 30, 1)
    atol = _num(sim.get("absolute_tolerance", 1e-8), "simulation_parameters", "absolute_tolerance")
    rho = _num(sim.get("rho_infty", 0.5), "simulation_parameters", "rho_infty")
    cycle_error = _flag(sim, "use_cycle_to_cycle_error", False)
    percent = _num(sim.get("sim_cycle_to_cycle_percent_error", 1.0), "simulation_parameters",
                   "sim_cycle_to_cycle_percent_error")
    sim_period = _num(sim.get("cardiac_period", -1.0), "simulation_parameters", "cardiac_period")

    # ---- boundary conditions (svZeroDSolver adds their parameters in file order; the first
    # time table fixes the period and every other must match it exactly)
    bc_list = cfg["boundary_conditions"]
    # a closed loop of chambers needs none (the chambers fix the pressure level)
    if not isinstance(bc_list, list) or not (bc_list or cfg.get("chambers")):
        raise ModelError("boundary_conditions: must be a non-empty list")
    bcs: dict[str, tuple[str, dict[str, Any]]] = {}
    model_period = -1.0
    for i, b in enumerate(bc_list):
        b, name, kind, el = _entry(b, f"boundary_conditions[{i}]", "bc_name",
                                   "boundary condition", BC_ENTRY_KEYS, "bc_type", BC_PARAMS)
        el = f"{kind} boundary condition '{name}'"
        vals = _check_params(_required(b, "bc_values", el), BC_PARAMS[kind], el)
        if name in bcs:
            raise ModelError(f"{el}: bc_name used twice")
        native: dict[str, Any]
        if kind in ("FLOW", "PRESSURE"):
            key = "Q" if kind == "FLOW" else "P"
            y = _numlist(_required(vals, key, el), el, key)
            t = _numlist(_required(vals, "t", el), el, "t")
            q = "flow" if kind == "FLOW" else "pressure"
            if not y:
                raise ModelError(f"{el}: '{key}' is empty")
            if len(y) == 1:
                native = {"type": q, q: y[0]}
            else:
                if len(t) != len(y):
                    raise ModelError(f"{el}: 't' has {len(t)} entries but '{key}' has {len(y)}")
                p = t[-1] - t[0]
                if model_period > 0.0 and p != model_period:
                    raise ModelError(f"{el}: Inconsistent cardiac cycle period defined in "
                                     f"parameters (its table spans {p}, an earlier one "
                                     f"{model_period})")
                model_period = p
                tt, yy = _periodic_table(t, y, el)
                # svZeroDSolver's steady start uses the arithmetic mean of the samples
                native = {"type": q, "time": tt, q: yy, "steady": sum(y) / len(y)}
        elif kind in svzerod_heart.BC_PARAMS:
            native, p = svzerod_heart.boundary_condition(kind, vals, el, _num, _numlist,
                                                         _periodic_table)
            if p is not None and model_period > 0.0 and p != model_period:
                raise ModelError(f"{el}: Inconsistent cardiac cycle period defined in "
                                 f"parameters (its table spans {p}, an earlier one "
                                 f"{model_period})")
            model_period = p if p is not None else model_period
        elif kind in svzerod_closed_loop.BC_PARAMS:
            native = svzerod_closed_loop.boundary_condition(kind, vals, el, _num)
        elif kind == "RESISTANCE":
            native = {"type": "resistance", "resistance": _num(_required(vals, "R", el), el, "R"),
                      "pressure": _num(_required(vals, "Pd", el), el, "Pd")}
        else:
            native = {"type": "rcr",
                      "proximal_resistance": _num(_required(vals, "Rp", el), el, "Rp"),
                      "capacitance": _num(_required(vals, "C", el), el, "C"),
                      "distal_resistance": _num(_required(vals, "Rd", el), el, "Rd"),
                      "pressure": _num(vals.get("Pd", 0.0), el, "Pd")}
        bcs[name] = (kind, native)
        if kind == "RCR":
            layout.internal.append(("rcr", name, native["proximal_resistance"]))
        elif kind == "ClosedLoopRCR":  # P_c: the capacitor node of its hidden Rp-C vessel
            layout.internal.append((kind, name, f"{name}:proximal"))
        elif kind in svzerod_closed_loop.CORONARY_TYPES:  # volume_im of its coronary_bed
            layout.internal.append(("ClosedLoopCoronary", name, f"{name}:bed"))
        elif kind in svzerod_heart.BC_PARAMS:  # volume_im: C_im times its transmural change
            layout.internal.append(("CORONARY", name, native["intramyocardial_capacitance"]))

    heart_period = svzerod_closed_loop.heart_period(cfg)
    if heart_period is not None:  # svZeroDSolver takes the heart block's period
        model_period = heart_period
    if model_period < 0.0 and sim_period < 0.0:
        period = 1.0
    elif model_period >= 0.0:
        if sim_period >= 0.0 and model_period != sim_period:
            raise ModelError(f"simulation_parameters: Inconsistent cardiac cycle period defined "
                             f"in parameters (cardiac_period = {sim_period}, boundary "
                             f"condition tables span {model_period})")
        period = model_period
    else:
        period = sim_period
    if not period > 0.0:
        raise ModelError(f"simulation_parameters: the cardiac period must be > 0, got {period}")
    svzerod_heart.finish(bcs, period)

    if cycle_error and any(kind == "RCR" for kind, _ in bcs.values()):
        # Pfaller et al. 2021, eq. 21, as in svZeroDSolver's Solver.cpp
        tau = max(n["capacitance"] * n["distal_resistance"]
                  for kind, n in bcs.values() if kind == "RCR")
        cycles = math.ceil(-tau / period * math.log(percent / 100.0))
        if cycles < 1:
            raise ModelError(f"simulation_parameters: use_cycle_to_cycle_error gives {cycles} "
                             "cycles (largest RCR time constant too small)")
    # without an RCR, svZeroDSolver runs extra cycles until the caps' means converge
    # (oxyline.io.svzerod_cycles); the rule needs every step, so it is applied in `simulate`

    # ---- vessels
    vessels_in = cfg.get("vessels", [])
    if not isinstance(vessels_in, list):
        raise ModelError("vessels: must be a list")
    vessels: list[dict[str, Any]] = []
    ids: dict[Any, str] = {}
    ends: dict[tuple[str, str], str] = {}  # (vessel, "in"/"out") -> node name
    end_owner: dict[tuple[str, str], str] = {}
    used_bcs: dict[str, str] = {}

    def attach(vessel: str, end: str, node: str, what: str) -> None:
        key = (vessel, end)
        if key in ends:
            raise ModelError(f"vessel '{vessel}': its {'inlet' if end == 'in' else 'outlet'} is "
                             f"connected twice ({end_owner[key]} and {what})")
        ends[key] = node
        end_owner[key] = what

    seen_names: set[str] = set()
    crl: list[tuple[dict[str, Any], dict[str, Any]]] = []
    for i, v in enumerate(vessels_in):
        v, name, kind, el = _entry(v, f"vessels[{i}]", "vessel_name", "vessel", VESSEL_KEYS,
                                   "zero_d_element_type", VESSEL_TYPES)
        if name in seen_names:
            raise ModelError(f"{el}: vessel_name used twice")
        seen_names.add(name)
        el = f"{kind} '{name}'"
        params = {"BloodVesselRC": RC_VESSEL_PARAMS,
                  "ChamberSphere": set(svzerod_heart.SPHERE_KEYS)}.get(kind, BLOOD_VESSEL_PARAMS)
        vals = _check_params(_required(v, "zero_d_element_values", el), params, el)
        lumped = {} if kind in ("BloodVesselRC", "ChamberSphere") else {
            "resistance": _num(_required(vals, "R_poiseuille", el), el, "R_poiseuille"),
            "capacitance": _num(vals.get("C", 0.0), el, "C"),
            "inductance": _num(vals.get("L", 0.0), el, "L"),
            "stenosis_coefficient": _num(vals.get("stenosis_coefficient", 0.0), el,
                                         "stenosis_coefficient"),
        }
        if kind == "BloodVessel" and lumped["stenosis_coefficient"] != 0.0 \
                and lumped["capacitance"] != 0.0:
            # svZeroDSolver's own discretisation of the stenosis next to the capacitor
            # (docs/svzerod.md, "C + stenosis"); oxyline's native default is "branch"
            lumped["stenosis_form"] = "svzerod"
        vid = _required(v, "vessel_id", el)
        if isinstance(vid, bool) or not isinstance(vid, (int, str)):
            raise ModelError(f"{el}: vessel_id must be an integer or a name, got {vid!r}")
        if vid in ids:
            raise ModelError(f"{el}: vessel_id {vid!r} is also used by vessel '{ids[vid]}'")
        ids[vid] = name
        if kind == "ChamberSphere":
            # a vessel-class block upstream: in the vessel table with its inflow and outflow
            layout.vessels.append((name, name, name))
            layout.spheres.append(name)
            vessels.append({"name": name, "description": "svZeroDSolver ChamberSphere",
                            "chamber_sphere": svzerod_heart.chamber_sphere(vals, el, period,
                                                                          _num)})
        elif kind == "BloodVesselRC":
            layout.vessels.append((name, name, name))
            layout.not_vessels.add(name)
            vessels.append({"name": name, "description": "svZeroDSolver BloodVesselRC",
                            "through_rc": {"resistance": _num(_required(vals, "Rpd", el), el,
                                                              "Rpd"),
                                           "capacitance": _num(_required(vals, "Cp", el), el,
                                                               "Cp")}})
        elif kind == "BloodVesselCRL":
            front, back = _crl_vessels(name, lumped)
            vessels.append(front)
            crl.append((front, back))
            layout.vessels.append((name, name, back["name"]))
        else:
            layout.vessels.append((name, name, name))
            vessels.append({"name": name, "arrangement": "RCL", "lumped": lumped,
                            "description": "svZeroDSolver BloodVessel"})
        vbc = _mapping(v.get("boundary_conditions", {}), f"{el} boundary_conditions")
        for side, bc_name in vbc.items():
            if _is_comment(side):
                continue
            if side not in ("inlet", "outlet"):
                raise UnsupportedElement(f"{el}: unknown boundary_conditions key '{side}'")
            if not isinstance(bc_name, str) or bc_name not in bcs:
                raise ModelError(f"{el}: its {side} boundary condition '{bc_name}' is not defined")
            kind_bc = bcs[bc_name][0]
            if side == "inlet" and kind_bc in ("RESISTANCE", "RCR"):
                # svZeroDSolver applies its outlet equations with Q along the vessel:
                # P_in = Pd + R Q (native `svzerod-inlet`, docs/svzerod.md)
                bcs[bc_name] = (kind_bc, dict(bcs[bc_name][1], type="svzerod-inlet"))
            if bc_name in used_bcs:
                raise ModelError(f"boundary condition '{bc_name}': connected to both "
                                 f"{used_bcs[bc_name]} and {el}")
            used_bcs[bc_name] = el
            attach(name, "in" if side == "inlet" else "out", bc_name,
                   f"boundary condition '{bc_name}'")
        # svZeroDSolver's nodes of this vessel's boundary conditions, inlet first
        layout.connections += [(vbc["inlet"], name)] if "inlet" in vbc else []
        layout.connections += [(name, vbc["outlet"])] if "outlet" in vbc else []
    svzerod_closed_loop.add_blocks(cfg, period, vessels, bcs, attach, seen_names, _num)
    heart_nodes = _closed_loop_layout(cfg, vessels, bcs, layout)
    first_element_node = len(layout.connections)
    _heart_elements(cfg, period, vessels, layout, bcs, used_bcs, attach)
    # svZeroDSolver numbers the valves' nodes after the junctions' (it creates valves later)
    element_nodes = layout.connections[first_element_node:]
    del layout.connections[first_element_node:]
    vessel_names = {x["name"] for x in vessels}

    # ---- junctions
    hidden = _junctions(cfg.get("junctions", []), ids, bcs, vessel_names, attach, layout)
    layout.connections += element_nodes
    # a coupling block's wire: svZeroDSolver has no node at its free end, and no vessel row
    layout.connections = [c for c in layout.connections if not set(c) & wire_ends]
    layout.not_vessels |= set(wires)
    layout.connections += heart_nodes

    if not vessels:
        raise ModelError("model: no vessels")
    for name in used_bcs.keys() ^ bcs.keys():
        raise ModelError(f"boundary condition '{name}': not connected to any vessel")
    for v in vessels:
        v["from"] = ends.get((v["name"], "in"), f"{v['name']}:inlet")
        v["to"] = ends.get((v["name"], "out"), f"{v['name']}:outlet")
    for front, back in crl:  # the capacitor node between the two parts of a BloodVesselCRL
        back["to"] = front["to"]
        back["from"] = front["to"] = f"{front['name']}:C"
        hidden.append(back)
    names = {x["name"] for x in vessels}
    for front, _ in crl:
        if front["to"] in names or front["to"] in bcs:
            raise ModelError(f"BloodVesselCRL '{front['name']}': its capacitor node name "
                             f"'{front['to']}' is also used by another block")
    for h in hidden:
        if h["name"] in names:
            raise ModelError(f"junction branch '{h['name']}': name clashes with a vessel")
    # the closed-loop blocks' start values are the heart block's own (svzerod_closed_loop)
    closed = {a for a, _ in heart_nodes}
    svzerod_initial.apply(cfg, vessels + hidden, [e for e in layout.vessels if e[0] not in closed],
                          layout.connections, crl, _num)

    dt = period / (float(pts) - 1.0)
    settings = RunSettings(
        period=period, cycles=cycles, points_per_cycle=pts, dt=dt, output_interval=interval,
        output_all_cycles=_flag(sim, "output_all_cycles", False),
        output_mean_only=_flag(sim, "output_mean_only", False),
        steady_initial=_flag(sim, "steady_initial", True), rho_infty=rho,
        absolute_tolerance=atol, max_iterations=max_iter, units=system,
        output_variable_based=_flag(sim, "output_variable_based", False),
        output_derivative=_flag(sim, "output_derivative", False),
    )
    svzerod_initial.zero_start_coronaries(bcs, settings.steady_initial)
    if cycle_error and not any(kind == "RCR" for kind, _ in bcs.values()):
        settings.cycle_error = percent / 100.0
        settings.caps = svzerod_cycles.caps(
            [v for v in vessels_in if isinstance(v, Mapping)])
    native: dict[str, Any] = {
        "name": "svzerod",
        "units": system,  # the model converts the file's numbers to SI
        "description": "converted from an svZeroDSolver input by oxyline.svzerod",
        "period": period,
        "vessels": vessels + hidden,
        "boundary_conditions": {name: nat for name, (kind, nat) in bcs.items()
                                if kind not in svzerod_closed_loop.BC_PARAMS},
        "simulation": {
            "cycles": cycles,
            "dt": dt,
            "method": "generalized-alpha",
            "rho_infty": rho,
            "start": "svzerod-steady" if settings.steady_initial else "svzerod-zero",
            "output": {"cycles": "all" if settings.output_all_cycles else "last",
                       "every": dt * interval, "segments": False},
        },
    }
    return native, settings, layout


def to_oxyline_dict(config: Mapping[str, Any] | str | os.PathLike[str],
                    units: str | None = None) -> dict[str, Any]:
    """Translate an svZeroDSolver configuration into oxyline's native model schema.

    Vessels become lumped ``arrangement: RCL`` vessels, junctions become shared nodes (a
    ``BloodVesselJunction`` adds one hidden ``output: false`` R-L vessel per outlet), the
    boundary conditions keep their names as node names. Numbers are the file's; the dict's
    ``units`` says which system they are in (see :func:`file_units`: ``units`` given here, else
    the file's ``units`` key, else cgs), so the model built from it, and its results, are SI.
    """
    return _convert(config, units)[0]


def run_settings(config: Mapping[str, Any] | str | os.PathLike[str],
                 units: str | None = None) -> RunSettings:
    """The resolved svZeroDSolver run settings (period, cycles, dt, output options, units)."""
    return _convert(config, units)[1]


def to_model(config: Mapping[str, Any] | str | os.PathLike[str],
             units: str | None = None) -> Model:
    """An :class:`oxyline.Model` (SI) for an svZeroDSolver configuration (see
    :func:`to_oxyline_dict`; ``units`` as there); its ``simulation`` settings reproduce the
    file's."""
    native, _, _ = _convert(config, units)
    return _build(native)


# ------------------------------------------------------------------------------------------
# running


def _table_spacings(native: Mapping[str, Any]) -> list[float]:
    out = []
    for bc in native["boundary_conditions"].values():
        pim = bc.get("intramyocardial_pressure")
        for t in (bc.get("time"), pim.get("time") if isinstance(pim, Mapping) else None):
            if t and len(t) > 1:
                out.append(min(b - a for a, b in itertools.pairwise(t)))
    return out


def simulate(config: Mapping[str, Any] | str | os.PathLike[str], *,
             method: str = "generalized-alpha", units: str | None = None,
             rk4_substeps: int | None = None) -> Any:
    """Run an svZeroDSolver configuration and return ``svzerod.simulate``'s DataFrame.

    The frame holds the file's own numbers, as svZeroDSolver's does; ``df.attrs["units"]``
    names each column's units and ``df.attrs["units_system"]`` the system (``units`` given
    here, else the file's ``units`` key, else cgs: see :func:`file_units`).

    ``method="generalized-alpha"`` (default) reproduces svZeroDSolver's integrator, step and
    Newton tolerance. ``method="rk4"`` uses oxyline's explicit RK4 with a stable sub-step
    inside each output step (outputs at the same times). Inductor flows a FLOW condition fixes
    (e.g. an R-L vessel fed by a FLOW condition) are made algebraic first; circuits still
    singular after that raise :class:`oxyline.ModelError`. ``rk4_substeps`` sets the RK4
    sub-steps per output step (default: half the stability limit, and the spacing of the time
    tables); a smaller sub-step resolves a steep valve's switch (docs/physics.md §1.8).

    ``output_variable_based`` gives svZeroDSolver's variable table (``name, time, y``: the
    flow and pressure of each of its nodes, then internal variables such as an RCR's
    ``pressure_c``); ``output_derivative`` adds the time derivatives (``d_*`` columns or
    ``ydot``), computed from every step of the run (see docs/svzerod.md).
    """
    import pandas as pd

    if method not in METHODS:
        raise ModelError(f"simulate: method must be one of {', '.join(METHODS)}, got {method!r}")
    native, s, layout = _convert(config, units)
    if rk4_substeps is not None:
        if method != "rk4" or int(rk4_substeps) < 1:
            raise ModelError(f"simulate: rk4_substeps={rk4_substeps!r} needs method='rk4' and "
                             "a positive integer")
        s = dataclasses.replace(s, rk4_substeps=int(rk4_substeps))
    # record every native vessel an output comes from (the hidden parts of a BloodVesselCRL
    # and of a resistive junction too); the drop-in runs in the file's own units, as
    # svZeroDSolver does (same numbers, same Newton tolerance): the equations do not depend
    # on them
    needed = {x for _, a, b in layout.vessels for x in (a, b)}
    needed |= {ref[0] for kind, _, ref in layout.internal if kind == "junction"}
    vessels = [dict(v, output=True) if v["name"] in needed else v for v in native["vessels"]]
    model = _build({**native, "vessels": vessels, "units": "SI"})
    recorded = {v["name"]: 4 * k for k, v in enumerate(x for x in vessels if x.get("output", True))}
    chambers = [v["name"] for v in native["vessels"] if "chamber" in v]
    elements = chambers or layout.spheres or any(k in ELEMENT_KINDS for k, _, _ in
                                                 layout.internal)
    if s.output_variable_based and elements:
        # the elements' variables are unknowns of the core no vessel column holds
        names, columns = _output_columns(layout, recorded, True, model.network, chambers)
        s = dataclasses.replace(s, all_unknowns=True)
    else:
        names, columns = _output_columns(layout, recorded, s.output_variable_based)
    shape = (len(names), 1 if s.output_variable_based else 4)
    if s.cycle_error is not None:
        ends = {name: (a, b) for name, a, b in layout.vessels}
        cap_cols = [(recorded[ends[v][end == "out"]] + (2 if end == "in" else 3),
                     recorded[ends[v][end == "out"]] + (0 if end == "in" else 1))
                    for v, end in s.caps]
        if s.all_unknowns:  # the run records every unknown: the vessels' columns are theirs
            probe = model.network.unknown_layout()["vessel_unknowns"]
            cap_cols = [(int(probe[q]), int(probe[p])) for q, p in cap_cols]
        times, values = _run_cycle_error(model, native, s, method, columns, cap_cols)
        values = np.ascontiguousarray(values.reshape(len(times), *shape).transpose(1, 0, 2))
        return _frame(pd, names, times, values, None, s)
    # svZeroDSolver's valve_status is solved at generalized-α's α_f stage (see _alpha_stage):
    # a recursion over every step
    every_step = s.output_derivative or _needs_start(columns) or (
        bool(columns[2]) and method == "generalized-alpha")
    times, values, derivs = (_run_every_step if every_step else _run_streamed)(
        model, native, s, method, columns, shape)
    return _frame(pd, names, times, values, derivs, s)


#: svZeroDSolver's block order of the internal variables in its variable table (after the
#: ChamberSphere vessels' wall variables; the chambers' ``Vc`` come last)
INTERNAL_ORDER = {"rcr": 1, "ClosedLoopRCR": 1, "ClosedLoopCoronary": 1, "CORONARY": 1,
                  "junction": 2, "heart": 3, "valve": 4}
#: the internal variables read from the core's element unknowns (the run records every one)
ELEMENT_KINDS = {"ClosedLoopCoronary", "CORONARY", "heart", "valve"}


class _VolumeSinceStart:
    """An open-loop ``CORONARY``'s ``volume_im`` from the core's transmural pressure u of its
    intramyocardial compartment (docs/physics.md §1.7): V_im = C_im (u − u(0)).

    svZeroDSolver's block holds V_im itself, measured from the start (its
    ``setup_initial_state_dependent_params`` takes the start's compartment pressure P_Cim_0
    and P_im(0), or the mean P_im after the steady start, whose steady equations set V_im =
    0), and integrates dV_im/dt = Q_am − Q_v; the core integrates C_im du/dt over the same
    flows with the same steps. The law needs the run's first row, the start (``history``).
    Left out: after the steady start svZeroDSolver's P_Cim_0 also holds R_am C_a (Ṗ_in −
    R_a Q̇_in) of its leftover ẏ₀, a constant offset taken as 0 here (as ẏ₀ is, see
    ``_run_every_step``; −6.5e-10 mL in steadyFlow_R_coronary)."""

    history = True

    def __init__(self, capacitance: float) -> None:
        self.capacitance = capacitance

    def __call__(self, u: np.ndarray) -> np.ndarray:
        return self.capacitance * (u - u[0])


def _needs_start(columns: Columns) -> bool:
    """Whether a column's law needs the run from its start (see :class:`_VolumeSinceStart`)."""
    return any(getattr(f, "history", False) for _, f in columns[2])

#: output columns: column j is recorded column ``idx[j]`` plus ``w`` times recorded column
#: ``c`` for each (j, c, w) in ``extra``, then mapped by ``f`` for each (j, f) in ``post``
Columns = tuple[np.ndarray, list[tuple[int, int, float]], list[tuple[int, Any]]]


def _output_columns(layout: _Layout, recorded: Mapping[str, int], variable_based: bool,
                    network: Any = None, chambers: Sequence[str] = ()
                    ) -> tuple[list[str], Columns]:
    """The output names and columns. Recorded columns are each recorded vessel's pressure_in,
    pressure_out, flow_in, flow_out (at ``recorded[vessel] + 0 .. 3``); with ``network`` (the
    core network of a run recording every unknown) they are its unknowns instead, and the
    variable table has the elements' variables too (ChamberSphere walls, closed-loop
    coronary volumes, the heart block's variables, tanh valves' status, chambers' ``Vc``)."""
    ends = {name: (a, b) for name, a, b in layout.vessels}
    if not variable_based:
        shown = [n for n, _, _ in layout.vessels if n not in layout.not_vessels]
        idx = [recorded[ends[n][0]] + k if k in (0, 2) else recorded[ends[n][1]] + k
               for n in shown for k in range(4)]
        return shown, (np.asarray(idx, dtype=np.intp), [], [])
    lay = None if network is None else network.unknown_layout()
    probe = None if lay is None else np.asarray(lay["vessel_unknowns"], dtype=np.intp)

    def col(vessel: str, k: int) -> int:
        c = recorded[vessel] + k
        return c if probe is None else int(probe[c])

    names: list[str] = []
    idx: list[int] = []
    extra: list[tuple[int, int, float]] = []
    post: list[tuple[int, Any]] = []
    node_of: dict[str, tuple[str, int, int]] = {}  # a condition's node: (vessel, p, q)
    for up, down in layout.connections:
        # a node's flow and pressure are those of the vessel end it joins
        v, p, q = (ends[down][0], 0, 2) if down in ends else (ends[up][1], 1, 3)
        node_of.setdefault(up, (v, p, q))
        node_of.setdefault(down, (v, p, q))
        names += [f"flow:{up}:{down}", f"pressure:{up}:{down}"]
        idx += [col(v, q), col(v, p)]
    element = {} if lay is None else dict(lay.get("element_unknowns", []))
    # a ChamberSphere is a vessel, svZeroDSolver's first blocks
    for name in (f"{var}:{s}" for s in layout.spheres for var in svzerod_heart.SPHERE_VARIABLES):
        names.append(name)
        idx.append(element[name])
    for kind, name, ref in sorted(layout.internal, key=lambda e: INTERNAL_ORDER[e[0]]):
        if kind in ELEMENT_KINDS and lay is None:
            raise ModelError(f"internal error: '{name}' needs every unknown recorded")
        if kind == "rcr":  # P_c = P - Rp Q at the Windkessel's node (Q along the vessel)
            v, p, q = node_of[name]
            names.append(f"pressure_c:{name}")
            idx.append(col(v, p))
            extra.append((len(idx) - 1, col(v, q), -float(ref)))
        elif kind == "junction":  # the resistive junction's centre: a port's hidden vessel end
            names.append(f"pressure_c:{name}")
            idx.append(col(ref[0], ref[1]))
        elif kind == "ClosedLoopRCR":  # P_c: the capacitor node, its Rp-C vessel's outlet
            names.append(f"P_c:{name}")
            idx.append(col(ref, 1))
        elif kind == "ClosedLoopCoronary":
            names.append(f"volume_im:{name}")
            idx.append(element[f"volume_im:{ref}"])
        elif kind == "CORONARY":  # the compartment node's unknown is u = P_c − P_im
            names.append(f"volume_im:{name}")
            idx.append(network.unknown_names().index(
                f"pressure at boundary condition '{name}' intramyocardial compartment"))
            post.append((len(idx) - 1, _VolumeSinceStart(float(ref))))
        elif kind == "heart":
            heart_cols = _heart_columns(lay, name)
            names += [f"{var}:{name}" for var, _ in svzerod_closed_loop.VARIABLES]
            idx += heart_cols
        else:  # a tanh valve: its law's switch at the pressure difference across it
            behind, front, _ = {n: u for n, u, _ in lay["valves"]}[name]
            names.append(f"valve_status:{name}")
            idx.append(int(front))
            extra.append((len(idx) - 1, int(behind), -1.0))
            post.append((len(idx) - 1, _valve_closure(network, name)))
    if lay is not None:  # svZeroDSolver's chambers are its last blocks
        volume = dict(lay["chamber_volumes"])
        names += [f"Vc:{c}" for c in chambers]
        idx += [volume[c] for c in chambers]
    return names, (np.asarray(idx, dtype=np.intp), extra, post)


def _heart_columns(lay: Mapping[str, Any], heart: str) -> list[int]:
    """The unknowns of the heart block's variables (svzerod_closed_loop.VARIABLES)."""
    volume = dict(lay["chamber_volumes"])
    valve = {n: u for n, u, _ in lay["valves"]}
    return [int(volume[f"{heart}:{where}"]) if isinstance(where, str)
            else int(valve[f"{heart}:{where[0]}"][where[1]])
            for _, where in svzerod_closed_loop.VARIABLES]


def _valve_closure(network: Any, name: str) -> Any:
    """The core's valve_status of valve ``name`` from the pressure difference across it."""
    def f(dp: np.ndarray) -> np.ndarray:
        return np.asarray(network.valve_closure(name, dp.tolist()))
    return f


def _apply(data: np.ndarray, columns: Columns) -> np.ndarray:
    idx, extra, post = columns
    out = data[:, idx]
    for j, c, w in extra:
        out[:, j] += w * data[:, c]
    for j, f in post:
        out[:, j] = f(out[:, j])
    return out


#: the most RK4 steps the drop-in takes before refusing a stiff model (about a minute of a
#: small circuit's steps)
RK4_MAX_STEPS = 5e7


def _core_kwargs(model: Model, native: Mapping[str, Any], s: RunSettings, method: str
                 ) -> tuple[dict[str, Any], int]:
    """The core's run settings for svZeroDSolver's, and the RK4 sub-steps per output step."""
    kw: dict[str, Any] = {
        "period": s.period, "cycles": s.cycles, "method": method, "rho_infty": s.rho_infty,
        "start": "svzerod-steady" if s.steady_initial else "svzerod-zero",
        "newton_atol": s.absolute_tolerance, "max_iterations": s.max_iterations,
        "output_all_cycles": s.output_all_cycles, "segments": False,
    }
    if s.all_unknowns:
        kw["all_unknowns"] = True
    if method == "generalized-alpha":
        kw["dt"] = s.dt
        return kw, 1
    # sub-steps per output step: stable (half the RK4 limit) and resolving the time tables
    dt_max, element, _ = model.network.rk4_stability_limit()
    h = min([0.5 * dt_max] + _table_spacings(native))
    sub = max(1, math.ceil(s.dt / h * (1.0 - 1e-12)))
    if s.rk4_substeps is not None:
        if s.rk4_substeps < sub and s.dt / s.rk4_substeps > 0.5 * dt_max:
            raise ModelError(
                f"rk4_substeps={s.rk4_substeps}: the sub-step {s.dt / s.rk4_substeps:.3g} s "
                f"exceeds half the RK4 stability limit {dt_max:.3g} s (set by {element})")
        sub = s.rk4_substeps
    else:
        sub *= _switch_refinement(model, kw, s, sub)
    steps = sub * (s.points_per_cycle - 1) * s.cycles
    if steps > RK4_MAX_STEPS:
        # e.g. a closed valve behind a chamber's outlet inductor: R_max/L is a nanosecond
        # time constant (docs/physics.md §1.8), which only an implicit step passes over
        raise ModelError(
            f"rk4 cannot integrate this model in reasonable time: its stability limit "
            f"{dt_max:.3g} s (set by {element}) needs {steps:.3g} steps, more than "
            f"{RK4_MAX_STEPS:.0e}; use method='generalized-alpha'")
    kw["dt"] = s.dt / sub
    return kw, sub


#: the accuracy the RK4 step of a model with valves or chambers is refined to: the estimated
#: error of the first cycles, scaled by each unknown's range (the core's
#: ``rk4_step_refinement``, docs/physics.md §1.8)
RK4_SWITCH_TOL = 1e-2
#: the most the RK4 step is divided by for that accuracy
RK4_MAX_REFINEMENT = 64


def _switch_refinement(model: Model, kw: Mapping[str, Any], s: RunSettings, sub: int) -> int:
    """The factor by which the core's step-doubling criterion divides the RK4 sub-step (1
    without valves or chambers), at most ``RK4_MAX_REFINEMENT`` and within ``RK4_MAX_STEPS``;
    the trial runs (the run's first cycles, up to 2e4 steps) cost up to 2 ``max_factor`` times
    as many steps."""
    budget = RK4_MAX_STEPS / (sub * (s.points_per_cycle - 1) * s.cycles)
    max_factor = 1
    while 2 * max_factor <= min(RK4_MAX_REFINEMENT, budget):
        max_factor *= 2
    if max_factor == 1:
        return 1
    settings = {k: v for k, v in kw.items() if k not in ("period", "all_unknowns")}
    factor, _, _ = model.network.rk4_step_refinement(
        period=s.period, output_every=s.dt, tol=RK4_SWITCH_TOL, max_factor=max_factor,
        dt=s.dt / sub, **settings)
    return int(factor)


def _wanted(s: RunSettings) -> tuple[np.ndarray, int]:
    """Global step indices svZeroDSolver outputs, and the first one."""
    steps = s.points_per_cycle - 1
    first = 0 if s.output_all_cycles else steps * (s.cycles - 1)
    return np.arange(first, steps * s.cycles + 1, s.output_interval), first


def _output_times(s: RunSettings, wanted: np.ndarray, first: int) -> np.ndarray:
    times = s.dt * wanted.astype(float)
    if not s.output_all_cycles:
        times = times - s.dt * float(first)
    return times


def _check_times(s: RunSettings, got: np.ndarray, times: np.ndarray) -> None:
    if np.max(np.abs(got - times), initial=0.0) > 1e-9 * s.period * max(1, s.cycles):
        raise ModelError("internal error: output times of the core do not match svZeroDSolver's")


def _run_streamed(model: Model, native: Mapping[str, Any], s: RunSettings, method: str,
                  columns: Columns,
                  shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, None]:
    """Run and keep the output rows only: (times, (output, time, width) values, None) for
    ``shape`` = (outputs, width: 4 quantities of a vessel or 1 variable)."""
    k = s.output_interval
    wanted, first = _wanted(s)
    # the core records every `stride`-th global step (and the start of the last cycle)
    if method == "generalized-alpha" and (s.output_all_cycles or first % k == 0):
        stride = k
    else:
        stride = 1
    kw, _ = _core_kwargs(model, native, s, method)
    kw["output_every"] = s.dt * stride if method == "generalized-alpha" else s.dt
    # The core streams its rows in small chunks, each written straight into the output-major
    # (output, time, width) block that becomes the DataFrame's float block: the run never
    # holds a second, time-major copy of the output (the largest allocation at 10^4 vessels).
    values = np.empty((shape[0], wanted.size, shape[1]))
    core_times: list[np.ndarray] = []
    count = {"core": 0, "out": 0}

    def take(chunk: Mapping[str, Any]) -> None:
        t = np.asarray(chunk["times"])
        data = np.asarray(chunk["data"]).reshape(len(t), -1)
        first_row = count["core"]
        count["core"] += len(t)
        if stride == 1:  # every core row recorded: keep svZeroDSolver's every k-th
            keep = (first_row + np.arange(len(t))) % k == 0
            t, data = t[keep], data[keep]
        o, n = count["out"], len(t)
        if o + n > wanted.size:
            raise ModelError(f"internal error: more than {wanted.size} output rows from the core")
        values[:, o:o + n, :] = _apply(data, columns).reshape(n, *shape).transpose(1, 0, 2)
        core_times.append(t)
        count["out"] = o + n

    chunk_rows = max(1, (1 << 20) // max(1, shape[0] * shape[1]))  # ~8 MB per chunk
    raw = model.network.simulate(**kw, chunk_sink=take, chunk_rows=chunk_rows,
                                 keep_current_cycle=False)
    if "error" in raw:
        raise raw["error"]
    if count["out"] != wanted.size:
        raise ModelError(f"internal error: {count['out']} output rows from the core, "
                         f"expected {wanted.size}")
    times = _output_times(s, wanted, first)
    _check_times(s, np.concatenate(core_times) if core_times else np.empty(0), times)
    return times, values, None


def _alpha_stage(dp: np.ndarray, law: Any, rho: float, steady: bool) -> np.ndarray:
    """svZeroDSolver's algebraic internal variable s = f(Δp) (a tanh valve's valve_status)
    through every generalized-α step: its equation holds at the α_f stage, f(Δp_{n+α_f}) =
    s_n + α_f (s_{n+1} − s_n), Δp_{n+α_f} = Δp_n + α_f (Δp_{n+1} − Δp_n), α_f = 1/(1 + ρ∞)
    (the pressures are the core's, which solves the same stage equations). Between steps
    s_{n+1} − f(Δp_{n+1}) changes sign and shrinks by ρ∞ (its output oscillates around
    f(Δp) after a switch, as svZeroDSolver's does). Start: 0, svZeroDSolver's zero state, or
    f(Δp_0) after its steady iterations (their leftover, as for ẏ₀ in ``_run_every_step``,
    decays as ρ∞^n)."""
    af = 1.0 / (1.0 + rho)
    stage = law(dp[:-1] + af * (dp[1:] - dp[:-1]))
    out = np.empty_like(dp)
    out[0] = law(dp[:1])[0] if steady else 0.0
    for n in range(len(dp) - 1):
        out[n + 1] = out[n] + (stage[n] - out[n]) / af
    return out


def _run_every_step(model: Model, native: Mapping[str, Any], s: RunSettings, method: str,
                    columns: Columns,
                    shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Run recording every step of every cycle and return (times, values, time derivatives
    or None without ``output_derivative``) at svZeroDSolver's output rows, the tanh valves'
    valve_status through :func:`_alpha_stage` with generalized-α. Derivatives: with
    generalized-α svZeroDSolver's own ẏ, from its update
    ẏ_{n+1} = (1 + ρ∞)(y_{n+1} − y_n)/Δt − ρ∞ ẏ_n from ẏ_0 = 0 (exact for ρ∞ = 0 and for a
    zero start; after a steady start its ẏ_0, left over from the steady iterations, is taken
    as 0, an error that decays as ρ∞^n). RK4: second-order backward differences of at least
    ``RK4_DERIVATIVE_SUBSTEPS`` sub-steps per output step."""
    wanted, first = _wanted(s)
    kw, sub = _core_kwargs(model, native, s, method)
    if method == "rk4" and sub < RK4_DERIVATIVE_SUBSTEPS:
        # the backward differences see a table's kink only at an output time itself
        sub = RK4_DERIVATIVE_SUBSTEPS
        kw["dt"] = s.dt / sub
    kw.update(output_all_cycles=True, output_every=kw["dt"])
    raw = model.network.simulate(**kw)
    if "error" in raw:
        raise raw["error"]
    t = np.asarray(raw["times"])
    idx, extra, post = columns
    y = _apply(np.asarray(raw["data"]).reshape(len(t), -1), (idx, extra, []))
    if len(t) != (s.points_per_cycle - 1) * s.cycles * sub + 1:
        raise ModelError(f"internal error: {len(t)} rows from the core")
    for j, law in post:
        y[:, j] = law(y[:, j]) if method != "generalized-alpha" or getattr(law, "history", False) \
            else _alpha_stage(y[:, j], law, s.rho_infty, s.steady_initial)
    if not s.output_derivative:
        yd = None
    elif method == "generalized-alpha":
        rho = s.rho_infty
        yd = np.zeros_like(y)
        for n in range(len(t) - 1):
            yd[n + 1] = (1.0 + rho) * (y[n + 1] - y[n]) / kw["dt"] - rho * yd[n]
    else:
        yd = _backward_derivative(y, kw["dt"])
    rows = wanted * sub
    times = _output_times(s, wanted, first)
    _check_times(s, t[rows] - (0.0 if s.output_all_cycles else s.dt * first), times)
    def block(a: np.ndarray) -> np.ndarray:  # (time, output x width) -> (output, time, width)
        return np.ascontiguousarray(a[rows].reshape(len(rows), *shape).transpose(1, 0, 2))

    return times, block(y), None if yd is None else block(yd)


def _run_cycle_error(model: Model, native: Mapping[str, Any], s: RunSettings, method: str,
                     columns: Columns,
                     cap_cols: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """svZeroDSolver's extra cycles without RCR (:mod:`oxyline.io.svzerod_cycles`): the output
    times and the (rows, outputs x width) values."""
    if s.output_derivative:
        raise UnsupportedElement("simulation_parameters: 'use_cycle_to_cycle_error' without RCR "
                                 "together with 'output_derivative' is not supported")
    steps = s.points_per_cycle - 1

    planned, _ = _core_kwargs(model, native, s, method)  # once: its RK4 step trials

    def run(cycles: int) -> tuple[np.ndarray, np.ndarray]:
        kw = dict(planned, cycles=cycles, output_all_cycles=True, output_every=s.dt)
        raw = model.network.simulate(**kw)
        if "error" in raw:
            raise raw["error"]
        t = np.asarray(raw["times"])
        if len(t) != steps * cycles + 1:
            raise ModelError(f"internal error: {len(t)} rows from the core")
        data = np.asarray(raw["data"]).reshape(len(t), -1)
        caps = np.stack([data[:, [q, p]] for q, p in cap_cols], axis=1) if cap_cols else \
            np.zeros((len(t), 0, 2))
        return _apply(data, columns), caps

    return svzerod_cycles.run(run, s.cycles, steps, s.output_interval, s.output_all_cycles,
                              s.cycle_error or 0.0, s.dt)


def _backward_derivative(y: np.ndarray, h: float) -> np.ndarray:
    """Time derivative of rows `y` spaced `h` apart by second-order backward differences (the
    left derivative where a time table has a kink, as svZeroDSolver's ẏ there), forward ones
    at the first two rows."""
    yd = np.empty_like(y)
    if len(y) < 3:
        yd[:] = (y[-1] - y[0]) / (h * max(1, len(y) - 1))
        return yd
    yd[2:] = (3.0 * y[2:] - 4.0 * y[1:-1] + y[:-2]) / (2.0 * h)
    yd[:2] = (-3.0 * y[:2] + 4.0 * y[1:3] - y[2:4]) / (2.0 * h) if len(y) >= 4 else \
        (y[1:3] - y[:2]) / h
    return yd


def _frame(pd: Any, names: list[str], times: np.ndarray, values: np.ndarray,
           derivs: np.ndarray | None, s: RunSettings) -> Any:
    """svzerod.simulate's frame from (output, time, width) values (and derivatives)."""
    nv, nt = len(names), len(times)
    if s.output_variable_based:
        cols = {"y": values[:, :, 0]}
        if derivs is not None:
            cols["ydot"] = derivs[:, :, 0]
    else:
        if derivs is None and not s.output_mean_only:
            from oxyline.result import long_table_vessel_major

            frame = long_table_vessel_major(names, times, values.reshape(nv * nt, 4))
            return _with_units(frame, s)
        # values hold pressure_in, pressure_out, flow_in, flow_out; svzerod's column order
        order = {"flow_in": 2, "flow_out": 3, "pressure_in": 0, "pressure_out": 1}
        cols = {c: values[:, :, k] for c, k in order.items()}
        if derivs is not None:
            cols.update({f"d_{c}": derivs[:, :, k] for c, k in order.items()})
    if s.output_mean_only:
        data = {"name": names, "time": np.full(nv, np.nan)}
        data.update({c: v.mean(axis=1) for c, v in cols.items()})
    else:
        data = {"name": np.repeat(np.array(names, dtype=object), nt),
                "time": np.tile(times, nv)}
        data.update({c: v.reshape(nv * nt) for c, v in cols.items()})
    return _with_units(pd.DataFrame(data), s)


def _with_units(frame: Any, s: RunSettings) -> Any:
    units = dict(FRAME_UNITS[s.units])
    if s.output_variable_based:
        units = {"time": "s"}
    elif s.output_derivative:
        units.update({f"d_{c}": f"{u}/s" for c, u in FRAME_UNITS[s.units].items() if c != "time"})
    frame.attrs["units"] = units
    frame.attrs["units_system"] = s.units
    return frame


__all__ = ["RunSettings", "file_units", "run_settings", "simulate", "to_model",
           "to_oxyline_dict"]
