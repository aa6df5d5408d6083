"""svZeroDSolver reader: an svZeroDSolver JSON configuration (a dict or a path) -> an oxyline
native model dict and the run settings of the drop-in (:class:`RunSettings`).

The file's own keys are checked here, so that an error names them as the user wrote them
(``R_poiseuille``, ``bc_values``, ``t``): the core sees the translated model. Values stay in
the file's units (cgs unless a top-level ``"units": "SI"`` or ``units="SI"``); the model
names them and the core converts. Every element and option, the units and measured errors
against svZeroDSolver: docs/svzerod.md ("What is supported", "Peer cases"); the drop-in
:func:`oxyline.svzerod.simulate` that runs it: ``io/svzerod/dropin.py``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

from oxyline import _core
from oxyline.description import copy_description
from oxyline.errors import ModelError, ResourceError, UnsupportedElement
from oxyline.io.native import read_mapping
from oxyline.io.svzerod import closed_loop as svzerod_closed_loop
from oxyline.io.svzerod import coupling as svzerod_coupling
from oxyline.io.svzerod import heart as svzerod_heart
from oxyline.io.svzerod import initial as svzerod_initial
from oxyline.io.svzerod.values import is_comment, mapped, number, numbers, required
from oxyline.model import Model, _build

COLUMNS = ("name", "time", "flow_in", "flow_out", "pressure_in", "pressure_out")
METHODS = ("generalized-alpha", "rk4")

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
BVJ_PARAMS = ("R_poiseuille", "L", "stenosis_coefficient")
#: svZeroDSolver's parameter -> the native key, of a BloodVessel, a BloodVesselRC (a native
#: ``through_rc`` element, docs/physics.md §1.8) and the RESISTANCE and RCR conditions
LUMPED_KEYS = {"R_poiseuille": "resistance", "C": "capacitance", "L": "inductance",
               "stenosis_coefficient": "stenosis_coefficient"}
RC_KEYS = {"Rpd": "resistance", "Cp": "capacitance"}
RESISTANCE_KEYS = {"R": "resistance", "Pd": "pressure"}
RCR_KEYS = {"Rp": "proximal_resistance", "C": "capacitance", "Rd": "distal_resistance",
            "Pd": "pressure"}
BC_PARAMS = {
    "FLOW": {"Q", "t"},
    "PRESSURE": {"P", "t"},
    "RESISTANCE": set(RESISTANCE_KEYS),
    "RCR": set(RCR_KEYS),
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
        return copy_description(dict(config))
    return read_mapping(config)


def _mapping(d: Any, element: str) -> Mapping[str, Any]:
    if not isinstance(d, Mapping):
        raise ModelError(f"{element}: expected a JSON object, got {type(d).__name__}")
    return d


def _check_params(d: Any, allowed: Collection[str], element: str) -> Mapping[str, Any]:
    d = _mapping(d, element)
    for k in d:
        if not is_comment(k) and k not in allowed:
            raise UnsupportedElement(
                f"{element}: unknown parameter '{k}' (supported: {', '.join(sorted(allowed))})")
    return d


def _entry(raw: Any, where: str, name_key: str, label: str, allowed: Any, type_key: str,
           types: Any) -> tuple[Mapping[str, Any], str, str, str]:
    """Check one entry of a section list (vessel, junction, boundary condition): a mapping with a
    name, only known keys and a supported type (another is refused with the list of supported
    ones). Returns (entry, name, type, element label)."""
    entry = _mapping(raw, where)
    name = str(required(entry, name_key, where))
    el = f"{label} '{name}'"
    for k in entry:
        if k not in allowed and not is_comment(k):
            raise UnsupportedElement(f"{el}: unknown key '{k}'")
    kind = required(entry, type_key, el)
    if not isinstance(kind, str) or kind not in types:
        raise UnsupportedElement(f"{el}: {type_key} '{kind}' is not supported (supported: "
                                 f"{', '.join(sorted(types))})")
    return entry, name, kind, el


def _flag(sim: Mapping[str, Any], key: str, default: bool) -> bool:
    v = sim.get(key, default)
    if not isinstance(v, bool):
        raise ModelError(f"simulation_parameters: '{key}' must be true or false, got {v!r}")
    return v


def _int(sim: Mapping[str, Any], key: str, default: int | None, minimum: int) -> int:
    if key not in sim and default is not None:
        return default
    v = required(sim, key, "simulation_parameters")
    if isinstance(v, float) and v.is_integer():  # JSON 10.0, read as an integer by svZeroDSolver
        v = int(v)
    if isinstance(v, bool) or not isinstance(v, int) or not minimum <= v <= MAX_COUNT:
        raise ModelError(f"simulation_parameters: '{key}' must be an integer from {minimum} "
                         f"to {MAX_COUNT:.0e}, got {v!r:.40}")
    return v


#: the largest count (cycles, time points) a file may ask for; the planned number of time
#: steps is bounded again by MAX_TIME_STEPS
MAX_COUNT = 10**9
#: the most time steps (cycles x steps per cycle) a file may plan: about a day of running
#: at 100 µs per step, far beyond any svZeroDSolver case (svZeroDSolver itself allocates its
#: whole output up front and fails at once on such a file)
MAX_TIME_STEPS = 10**9


def _check_steps(cycles: int, pts: int, where: str) -> None:
    steps = cycles * (pts - 1)
    if steps > MAX_TIME_STEPS:
        raise ResourceError(f"simulation_parameters: {where}: {cycles} cycles x {pts - 1} "
                            f"steps per cycle = {steps:.3g} time steps, more than the "
                            f"{MAX_TIME_STEPS:.0e} a run may plan (number_of_cardiac_cycles, "
                            "number_of_time_pts_per_cardiac_cycle)")


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
    ref = found[0] if found else None  # the first period found, which the others must equal
    for p, where in found[1:]:
        if p != ref[0]:
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


def _junction_ports(j: Mapping[str, Any], key: str, by_id: bool, el: str,
                    ids: Mapping[Any, str], bcs: Mapping[str, Any],
                    vessel_names: set[str]) -> list[str]:
    """The vessels a junction's ``key`` lists (by vessel_id or by name)."""
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


def _resistive_junction(j: Mapping[str, Any], jname: str, el: str, inlets: list[str],
                        outlets: list[str], attach: Any, layout: _Layout,
                        hidden: list[dict[str, Any]]) -> None:
    """P_in,i - P_c = R_i Q_in,i and P_c - P_out,k = R_k Q_out,k around a centre node
    (svZeroDSolver's ResistiveJunction): one hidden R vessel per port, R listed for the
    inlets, then the outlets."""
    vals = _check_params(required(j, "junction_values", el), {"R"}, el)
    r = numbers(required(vals, "R", el), el, "R")
    if len(r) != len(inlets) + len(outlets):
        raise ModelError(f"{el}: 'R' has {len(r)} entries for {len(inlets)} inlets and "
                         f"{len(outlets)} outlets")
    ports = [(name, f"{name}:{jname}", jname) for name in inlets]
    ports += [(name, jname, f"{jname}:{name}") for name in outlets]
    for k, (name, a, b) in enumerate(ports):
        hidden.append({"name": a if k < len(inlets) else b, "from": a, "to": b,
                       "arrangement": "RCL", "output": False,
                       "lumped": {"resistance": r[k]}})
        attach(name, "out" if k < len(inlets) else "in", hidden[-1]["name"],
               f"junction '{jname}'")
    # its pressure_c: the centre end of the last port's hidden vessel
    layout.internal.append(("junction", jname, (hidden[-1]["name"], 0 if outlets else 1)))


def _blood_vessel_junction(j: Mapping[str, Any], jname: str, el: str, inlets: list[str],
                           outlets: list[str], attach: Any,
                           hidden: list[dict[str, Any]]) -> None:
    """BloodVesselJunction: one inlet, an R(+S)-L branch (no C) to every outlet."""
    vals = _check_params(required(j, "junction_values", el), BVJ_PARAMS, el)
    if len(inlets) != 1:
        raise UnsupportedElement(f"{el}: {len(inlets)} inlets; a BloodVesselJunction has "
                                 "exactly one")
    lists = {}
    for key in BVJ_PARAMS:
        lists[key] = numbers(required(vals, key, el), el, key)
        if len(lists[key]) != len(outlets):
            raise ModelError(f"{el}: '{key}' has {len(lists[key])} entries for "
                             f"{len(outlets)} outlets")
    what = f"junction '{jname}'"
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
        if "inlet_vessels" in j and "outlet_vessels" in j:
            keys, by_id = ("inlet_vessels", "outlet_vessels"), True
        elif "inlet_blocks" in j and "outlet_blocks" in j:
            keys, by_id = ("inlet_blocks", "outlet_blocks"), False
        else:
            raise ModelError(f"{el}: needs 'inlet_vessels' and 'outlet_vessels' (vessel ids) or "
                             "'inlet_blocks' and 'outlet_blocks' (names)")
        inlets, outlets = (_junction_ports(j, key, by_id, el, ids, bcs, vessel_names)
                           for key in keys)
        layout.connections += [(name, jname) for name in inlets]
        layout.connections += [(jname, name) for name in outlets]
        if kind in NORMAL_JUNCTIONS:
            _check_params(j.get("junction_values", {}), set(), el)
            for name in inlets:
                attach(name, "out", jname, f"junction '{jname}'")
            for name in outlets:
                attach(name, "in", jname, f"junction '{jname}'")
        elif kind == "resistive_junction":
            _resistive_junction(j, jname, el, inlets, outlets, attach, layout, hidden)
        else:
            _blood_vessel_junction(j, jname, el, inlets, outlets, attach, hidden)
    return hidden


def _attach_condition(bc: str, vessel: str, end: str, what: str, used_bcs: dict[str, str],
                      attach: Any) -> None:
    """Connect boundary condition ``bc`` to the ``end`` of ``vessel`` (the block ``what``); a
    condition is connected once."""
    if bc in used_bcs:
        raise ModelError(f"boundary condition '{bc}': connected to both {used_bcs[bc]} and "
                         f"{what}")
    used_bcs[bc] = what
    attach(vessel, end, bc, f"boundary condition '{bc}'")


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
        native = svzerod_heart.chamber(c, period, initial)
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
        native, up, down = svzerod_heart.valve(v)
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
                _attach_condition(block, name, end, what, used_bcs, attach)
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


def _check_top(cfg: Mapping[str, Any]) -> None:
    """The top-level sections: required ones present, none unknown (in svZeroDSolver's order
    of complaints: an inconsistent period first)."""
    if "simulation_parameters" not in cfg:
        bad = [k for k in ("calibration_parameters", "y", "dy") if k in cfg]
        if bad:
            raise UnsupportedElement(f"model: '{bad[0]}' without 'simulation_parameters' is an "
                                     "svZeroDCalibrator input, not a simulation: calibrate "
                                     "it with oxyline.svzerod.calibrate")
        raise ModelError("model: missing 'simulation_parameters' (Define simulation_parameters)")
    if "boundary_conditions" not in cfg:
        raise ModelError("model: missing 'boundary_conditions' (Define at least one boundary "
                         "condition)")
    # svZeroDSolver rejects an inconsistent period while loading, before anything else fails
    _check_period(cfg, _mapping(cfg["simulation_parameters"], "simulation_parameters"))
    for k in cfg:
        if k not in TOP_KEYS and k not in TOP_IGNORED and not is_comment(k):
            raise UnsupportedElement(f"model: unknown top-level key '{k}'")


def _simulation(cfg: Mapping[str, Any]) -> tuple[RunSettings, bool, float]:
    """The ``simulation_parameters`` section, checked: its run settings (``period`` the
    file's ``cardiac_period``, -1 without one, and ``dt`` not yet resolved), whether
    ``use_cycle_to_cycle_error`` is on, and ``sim_cycle_to_cycle_percent_error``."""
    sim = _mapping(cfg["simulation_parameters"], "simulation_parameters")
    for k in sim:
        if k not in SIM_KEYS and k not in SIM_IGNORED and not is_comment(k):
            raise UnsupportedElement(f"simulation_parameters: unknown key '{k}'")
    for k, what in SIM_UNSUPPORTED_FLAGS.items():
        if _flag(sim, k, False):
            raise UnsupportedElement(f"simulation_parameters: '{k}' ({what}) is not supported")
    where = "simulation_parameters"
    settings = RunSettings(
        cycles=_int(sim, "number_of_cardiac_cycles", None, 1),
        points_per_cycle=_int(sim, "number_of_time_pts_per_cardiac_cycle", None, 2),
        output_interval=_int(sim, "output_interval", 1, 1),
        max_iterations=_int(sim, "maximum_nonlinear_iterations", 30, 1),
        absolute_tolerance=number(sim.get("absolute_tolerance", 1e-8), where,
                                "absolute_tolerance"),
        rho_infty=number(sim.get("rho_infty", 0.5), where, "rho_infty"), dt=math.nan,
        period=number(sim.get("cardiac_period", -1.0), where, "cardiac_period"),
        output_all_cycles=_flag(sim, "output_all_cycles", False),
        output_mean_only=_flag(sim, "output_mean_only", False),
        steady_initial=_flag(sim, "steady_initial", True),
        output_variable_based=_flag(sim, "output_variable_based", False),
        output_derivative=_flag(sim, "output_derivative", False))
    return settings, _flag(sim, "use_cycle_to_cycle_error", False), number(
        sim.get("sim_cycle_to_cycle_percent_error", 1.0), where,
        "sim_cycle_to_cycle_percent_error")


def _condition(kind: str, vals: Mapping[str, Any], el: str, model_period: float
               ) -> tuple[dict[str, Any], float]:
    """One boundary condition as a native condition, and the period its table fixes."""
    if kind in ("FLOW", "PRESSURE"):
        key, q = ("Q", "flow") if kind == "FLOW" else ("P", "pressure")
        y = numbers(required(vals, key, el), el, key)
        t = numbers(required(vals, "t", el), el, "t")
        if not y:
            raise ModelError(f"{el}: '{key}' is empty")
        if len(y) == 1:
            return {"type": q, q: y[0]}, model_period
        if len(t) != len(y):
            raise ModelError(f"{el}: 't' has {len(t)} entries but '{key}' has {len(y)}")
        model_period = t[-1] - t[0]  # every table spans the same (_check_period)
        # over [0, P], P = t[-1] - t[0]: svZeroDSolver's lookup fmod(time, P), linear below
        # t[0]; the core's (``oxyline_core::waveform::fmod_table``, also checking t increases)
        tt, yy = _core.svzerod_periodic_table(t, y, el)
        # svZeroDSolver's steady start uses the arithmetic mean of the samples
        return {"type": q, "time": tt, q: yy, "steady": sum(y) / len(y)}, model_period
    if kind in svzerod_heart.BC_PARAMS:
        native, p = svzerod_heart.boundary_condition(kind, vals, el)
        return native, model_period if p is None else p
    if kind in svzerod_closed_loop.BC_PARAMS:
        return svzerod_closed_loop.boundary_condition(kind, vals, el), model_period
    if kind == "RESISTANCE":
        return {"type": "resistance", **mapped(vals, el, RESISTANCE_KEYS)}, model_period
    return {"type": "rcr", **mapped(vals, el, RCR_KEYS, {"Pd": 0.0})}, model_period


def _conditions(cfg: Mapping[str, Any], layout: _Layout
                ) -> tuple[dict[str, tuple[str, dict[str, Any]]], float]:
    """The boundary conditions (name -> (svZeroDSolver type, native condition), in file
    order, as svZeroDSolver adds their parameters) and the period their tables fix (-1:
    none); their internal variables go to ``layout``."""
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
        vals = _check_params(required(b, "bc_values", el), BC_PARAMS[kind], el)
        if name in bcs:
            raise ModelError(f"{el}: bc_name used twice")
        native, model_period = _condition(kind, vals, el, model_period)
        bcs[name] = (kind, native)
        if kind == "RCR":
            layout.internal.append(("rcr", name, native["proximal_resistance"]))
        elif kind == "ClosedLoopRCR":  # P_c: the capacitor node of its hidden Rp-C vessel
            layout.internal.append((kind, name, f"{name}:proximal"))
        elif kind in svzerod_closed_loop.CORONARY_TYPES:  # volume_im of its coronary_bed
            layout.internal.append(("ClosedLoopCoronary", name, f"{name}:bed"))
        elif kind in svzerod_heart.BC_PARAMS:  # volume_im: C_im times its transmural change
            layout.internal.append(("CORONARY", name, native["intramyocardial_capacitance"]))
    return bcs, model_period


def _period(cfg: Mapping[str, Any], model_period: float, sim_period: float) -> float:
    """The cardiac period: the heart block's, else the tables' (-1: none), else
    ``cardiac_period`` (-1: none), else 1 (svZeroDSolver's rule; :func:`_check_period` has
    checked that they agree)."""
    period = next((p for p in (svzerod_closed_loop.heart_period(cfg), model_period, sim_period)
                   if p is not None and p >= 0.0), 1.0)
    if not period > 0.0:
        raise ModelError(f"simulation_parameters: the cardiac period must be > 0, got {period}")
    return period


def _rcr_cycles(bcs: Mapping[str, tuple[str, dict[str, Any]]], period: float,
                percent: float) -> int:
    """``use_cycle_to_cycle_error`` with RCR outlets: the cycles of Pfaller et al. 2021,
    eq. 21, as in svZeroDSolver's Solver.cpp."""
    need, tau = _core.svzerod_rcr_cycles(
        [(n["capacitance"], n["distal_resistance"]) for kind, n in bcs.values() if kind == "RCR"],
        period, percent)
    if not need <= MAX_COUNT:  # also NaN/inf of extreme time constants
        raise ResourceError(f"simulation_parameters: use_cycle_to_cycle_error gives "
                            f"{need:.3g} cycles (largest RCR time constant {tau:.3g} s), "
                            f"more than {MAX_COUNT:.0e}")
    cycles = math.ceil(need)
    if cycles < 1:
        raise ModelError(f"simulation_parameters: use_cycle_to_cycle_error gives {cycles} "
                         "cycles (largest RCR time constant too small)")
    return cycles


class _Ends:
    """The node at each vessel end, set once (a second connection of an end is an error
    naming both)."""

    def __init__(self) -> None:
        self.nodes: dict[tuple[str, str], str] = {}  # (vessel, "in"/"out") -> node name
        self.owner: dict[tuple[str, str], str] = {}

    def attach(self, vessel: str, end: str, node: str, what: str) -> None:
        key = (vessel, end)
        if key in self.nodes:
            raise ModelError(f"vessel '{vessel}': its {'inlet' if end == 'in' else 'outlet'} is "
                             f"connected twice ({self.owner[key]} and {what})")
        self.nodes[key] = node
        self.owner[key] = what


def _lumped(kind: str, vals: Mapping[str, Any], el: str) -> dict[str, Any]:
    """The lumped R-L-C (and stenosis) of a BloodVessel-class block."""
    if kind in ("BloodVesselRC", "ChamberSphere"):
        return {}
    lumped: dict[str, Any] = mapped(vals, el, LUMPED_KEYS,
                                    {"C": 0.0, "L": 0.0, "stenosis_coefficient": 0.0})
    if kind == "BloodVessel" and lumped["stenosis_coefficient"] != 0.0 \
            and lumped["capacitance"] != 0.0:
        # svZeroDSolver's own discretisation of the stenosis next to the capacitor
        # (docs/svzerod.md, "C + stenosis"); oxyline's native default is "branch"
        lumped["stenosis_form"] = "svzerod"
    return lumped


def _vessel(name: str, kind: str, vals: Mapping[str, Any], lumped: dict[str, Any], el: str,
            period: float, layout: _Layout, crl: list[tuple[dict[str, Any], dict[str, Any]]]
            ) -> dict[str, Any]:
    """The native vessel of one svZeroDSolver vessel block (the front part of a
    BloodVesselCRL, whose back part goes to ``crl``); its output rows go to ``layout``."""
    if kind == "BloodVesselCRL":
        front, back = _crl_vessels(name, lumped)
        crl.append((front, back))
        layout.vessels.append((name, name, back["name"]))
        return front
    layout.vessels.append((name, name, name))
    if kind == "ChamberSphere":
        # a vessel-class block upstream: in the vessel table with its inflow and outflow
        layout.spheres.append(name)
        return {"name": name, "description": "svZeroDSolver ChamberSphere",
                "chamber_sphere": svzerod_heart.chamber_sphere(vals, el, period)}
    if kind == "BloodVesselRC":
        layout.not_vessels.add(name)
        return {"name": name, "description": "svZeroDSolver BloodVesselRC",
                "through_rc": mapped(vals, el, RC_KEYS)}
    return {"name": name, "arrangement": "RCL", "lumped": lumped,
            "description": "svZeroDSolver BloodVessel"}


def _vessel_conditions(v: Mapping[str, Any], name: str, el: str,
                       bcs: dict[str, tuple[str, dict[str, Any]]], used_bcs: dict[str, str],
                       ends: _Ends, layout: _Layout) -> None:
    """Attach a vessel's ``boundary_conditions`` (inlet, outlet) to its ends."""
    vbc = _mapping(v.get("boundary_conditions", {}), f"{el} boundary_conditions")
    for side, bc_name in vbc.items():
        if is_comment(side):
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
        _attach_condition(bc_name, name, "in" if side == "inlet" else "out", el, used_bcs,
                          ends.attach)
    # svZeroDSolver's nodes of this vessel's boundary conditions, inlet first
    layout.connections += [(vbc["inlet"], name)] if "inlet" in vbc else []
    layout.connections += [(name, vbc["outlet"])] if "outlet" in vbc else []


@dataclass
class _Vessels:
    """The converted vessel blocks."""

    vessels: list[dict[str, Any]] = field(default_factory=list)
    ids: dict[Any, str] = field(default_factory=dict)
    #: the (front, back) parts of each BloodVesselCRL
    crl: list[tuple[dict[str, Any], dict[str, Any]]] = field(default_factory=list)


def _vessels(vessels_in: Any, period: float, bcs: dict[str, tuple[str, dict[str, Any]]],
             used_bcs: dict[str, str], ends: _Ends, layout: _Layout) -> _Vessels:
    if not isinstance(vessels_in, list):
        raise ModelError("vessels: must be a list")
    out = _Vessels()
    for i, v in enumerate(vessels_in):
        v, name, kind, el = _entry(v, f"vessels[{i}]", "vessel_name", "vessel", VESSEL_KEYS,
                                   "zero_d_element_type", VESSEL_TYPES)
        el = f"{kind} '{name}'"
        params = {"BloodVesselRC": RC_KEYS,
                  "ChamberSphere": svzerod_heart.SPHERE_KEYS}.get(kind, LUMPED_KEYS)
        vals = _check_params(required(v, "zero_d_element_values", el), params, el)
        lumped = _lumped(kind, vals, el)
        vid = required(v, "vessel_id", el)
        if isinstance(vid, bool) or not isinstance(vid, (int, str)):
            raise ModelError(f"{el}: vessel_id must be an integer or a name, got {vid!r}")
        if vid in out.ids:
            raise ModelError(f"{el}: vessel_id {vid!r} is also used by vessel '{out.ids[vid]}'")
        out.ids[vid] = name
        out.vessels.append(_vessel(name, kind, vals, lumped, el, period, layout, out.crl))
        _vessel_conditions(v, name, el, bcs, used_bcs, ends, layout)
    return out


def _connect(vs: _Vessels, hidden: list[dict[str, Any]], ends: _Ends,
             bcs: Mapping[str, Any], used_bcs: Mapping[str, str]) -> None:
    """Name every vessel's end nodes (a free end gets ``<vessel>:inlet``/``:outlet``), split
    each BloodVesselCRL at its capacitor node, and refuse clashing names and unconnected
    conditions."""
    for name in used_bcs.keys() ^ bcs.keys():
        raise ModelError(f"boundary condition '{name}': not connected to any vessel")
    for v in vs.vessels:
        v["from"] = ends.nodes.get((v["name"], "in"), f"{v['name']}:inlet")
        v["to"] = ends.nodes.get((v["name"], "out"), f"{v['name']}:outlet")
    for front, back in vs.crl:  # the capacitor node between the two parts of a BloodVesselCRL
        back["to"] = front["to"]
        back["from"] = front["to"] = f"{front['name']}:C"
        hidden.append(back)
    names = {x["name"] for x in vs.vessels}
    for front, _ in vs.crl:
        if front["to"] in names or front["to"] in bcs:
            raise ModelError(f"BloodVesselCRL '{front['name']}': its capacitor node name "
                             f"'{front['to']}' is also used by another block")
    for h in hidden:
        if h["name"] in names:
            raise ModelError(f"junction branch '{h['name']}': name clashes with a vessel")


def _native(system: str, period: float, vessels: list[dict[str, Any]],
            bcs: Mapping[str, tuple[str, dict[str, Any]]], settings: RunSettings
            ) -> dict[str, Any]:
    """The native model dict (the file's numbers, in ``system`` units)."""
    return {
        "name": "svzerod",
        "units": system,  # the model converts the file's numbers to SI
        "description": "converted from an svZeroDSolver input by oxyline.svzerod",
        "period": period,
        "vessels": vessels,
        "boundary_conditions": {name: nat for name, (kind, nat) in bcs.items()
                                if kind not in svzerod_closed_loop.BC_PARAMS},
        "simulation": {
            "cycles": settings.cycles,
            "dt": settings.dt,
            "method": "generalized-alpha",
            "rho_infty": settings.rho_infty,
            "start": "svzerod-steady" if settings.steady_initial else "svzerod-zero",
            "output": {"cycles": "all" if settings.output_all_cycles else "last",
                       "every": settings.dt * settings.output_interval, "segments": False},
        },
    }


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
    _check_top(cfg)
    sim, cycle_error, percent = _simulation(cfg)
    bcs, model_period = _conditions(cfg, layout)
    period = _period(cfg, model_period, sim.period)
    svzerod_heart.finish(bcs, period)
    cycles = sim.cycles
    if cycle_error and not 0.0 < percent < 100.0:
        raise ModelError(f"simulation_parameters: 'sim_cycle_to_cycle_percent_error' must be "
                         f"between 0 and 100 (exclusive) with use_cycle_to_cycle_error, got "
                         f"{percent:g}")
    if cycle_error and any(kind == "RCR" for kind, _ in bcs.values()):
        cycles = _rcr_cycles(bcs, period, percent)
    _check_steps(cycles, sim.points_per_cycle, "use_cycle_to_cycle_error" if cycle_error else
                 "number_of_cardiac_cycles")
    # without an RCR, svZeroDSolver runs extra cycles until the caps' means converge
    # (`_cycle_error_caps`); the rule needs every step, so the core applies it in its run

    ends, used_bcs = _Ends(), {}
    vessels_in = cfg.get("vessels", [])
    vs = _vessels(vessels_in, period, bcs, used_bcs, ends, layout)
    svzerod_closed_loop.add_blocks(cfg, period, vs.vessels, bcs, ends.attach,
                                   {v["name"] for v in vs.vessels})
    heart_nodes = _closed_loop_layout(cfg, vs.vessels, bcs, layout)
    first_element_node = len(layout.connections)
    _heart_elements(cfg, period, vs.vessels, layout, bcs, used_bcs, ends.attach)
    # svZeroDSolver numbers the valves' nodes after the junctions' (it creates valves later)
    element_nodes = layout.connections[first_element_node:]
    del layout.connections[first_element_node:]
    vessel_names = {x["name"] for x in vs.vessels}
    hidden = _junctions(cfg.get("junctions", []), vs.ids, bcs, vessel_names, ends.attach,
                        layout)
    layout.connections += element_nodes
    # a coupling block's wire: svZeroDSolver has no node at its free end, and no vessel row
    layout.connections = [c for c in layout.connections if not set(c) & wire_ends]
    layout.not_vessels |= set(wires)
    layout.connections += heart_nodes
    _connect(vs, hidden, ends, bcs, used_bcs)
    # the closed-loop blocks' start values are the heart block's own (svzerod_closed_loop)
    closed = {a for a, _ in heart_nodes}
    svzerod_initial.apply(cfg, vs.vessels + hidden,
                          [e for e in layout.vessels if e[0] not in closed],
                          layout.connections, vs.crl)

    settings = dataclasses.replace(sim, period=period, cycles=cycles, units=system,
                                   dt=period / (float(sim.points_per_cycle) - 1.0))
    svzerod_initial.zero_start_coronaries(bcs, settings.steady_initial)
    if cycle_error and not any(kind == "RCR" for kind, _ in bcs.values()):
        settings.cycle_error = percent / 100.0
        settings.caps = _cycle_error_caps(
            [v for v in vessels_in if isinstance(v, Mapping)])
    native = _native(system, period, vs.vessels + hidden, bcs, settings)
    # svZeroDSolver's own name for the model (VMR files carry it) names the results
    model_name = cfg["simulation_parameters"].get("model_name")
    if isinstance(model_name, str) and model_name.strip():
        native["name"] = model_name.strip()
    return native, settings, layout


def _cycle_error_caps(vessels: list[Mapping[str, Any]]) -> list[tuple[str, str]]:
    """The caps svZeroDSolver's ``use_cycle_to_cycle_error`` watches without RCR boundary
    conditions, (vessel, "in" or "out") in file order: the vessels with a boundary condition,
    at the outlet node of a vessel with an outlet condition (also one with both), else at the
    inlet node. svZeroDSolver (``Solver::run_integration``) runs the file's cycles, then extra
    cycles until at every cap the means of the flow and the pressure over the last cycle differ
    from those over the cycle before by at most ``sim_cycle_to_cycle_percent_error`` percent;
    the core runs that rule (``oxyline_core::run::CycleMeanStop``) and picks the rows
    svZeroDSolver outputs (``svzerod_output_rows``)."""
    out = []
    for v in vessels:
        bc = v.get("boundary_conditions") or {}
        if "outlet" in bc:  # svZeroDSolver's vessel type: outlet overrides inlet
            out.append((v["vessel_name"], "out"))
        elif "inlet" in bc:
            out.append((v["vessel_name"], "in"))
    return out


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


__all__ = ["RunSettings", "file_units", "run_settings", "to_model", "to_oxyline_dict"]
