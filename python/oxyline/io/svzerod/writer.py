"""Native model → svZeroDSolver JSON, the same circuit element for element.

svZeroDSolver's ``BloodVessel`` is R, then C (at the node after R), then L. An oxyline vessel of
n segments is a chain ``c_0 | R_1 L_1 | c_1 | … | R_n L_n | c_n`` of series branches and node
capacitances (inverted-L puts each segment's C at its proximal node, L at its distal node, pi half
at each), with each segment's R, L, C exactly as the core assembles them (docs/physics.md §1.1,
exact over a linear taper). Because R and L in one branch commute, the chain is exactly the
n + 1 BloodVessels ``(R=0, C=c_0, L=L_1), (R_1, c_1, L_2), …, (R_n, c_n, L=0)`` joined by
one-to-one ``NORMAL_JUNCTION``s; junction nodes become ``NORMAL_JUNCTION``s too (each vessel's
end capacitance sits at the junction pressure, as in the core). ``RCL`` vessels (lumped values)
are one BloodVessel; other lumped vessels follow the arrangement as a chain of their
``segments`` (R, L, C and S split evenly, as the core does), with the stenosis coefficient next
to R. The segments come from the core's segment table, so the exporter and the core cannot
disagree on the physics. The exported circuit is therefore the model's own circuit,
and svZeroDSolver's generalized-α run with the same step gives the same waveforms. Boundary
conditions become FLOW, PRESSURE, RESISTANCE and RCR; Fourier and periodic-cubic waveforms are
sampled (``samples`` points per period; svZeroDSolver interpolates linearly).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import UnsupportedElement
from oxyline.model import Model
from oxyline.units import CGS_TO_SI


def vessel_segments(model: Model) -> dict[str, list[dict[str, float]]]:
    """Per vessel, the list of segments with SI ``R``, ``L``, ``C``, ``S`` and ``length``
    (``length`` is 0 for lumped vessels), read from the core's segment table
    (``model.network.segment_table()``): the segments the core assembled, never a copy of its
    formulas."""
    t = model.network.segment_table()
    names = t["vessel_names"]
    out: dict[str, list[dict[str, float]]] = {name: [] for name in names}
    cols = [t[k].tolist() for k in ("vessel", "resistance", "inductance", "compliance",
                                    "stenosis", "length")]
    for v, R, L, C, S, length in zip(*cols, strict=True):
        out[names[v]].append({"R": R, "L": L, "C": C, "S": S, "length": length})
    return out


_CAPACITANCE_SPLIT = {"inverted-L": (1.0, 0.0), "L": (0.0, 1.0), "pi": (0.5, 0.5)}


def vessel_blocks(model: Model) -> dict[str, list[dict[str, float]]]:
    """Per vessel, the svZeroDSolver BloodVessels (SI ``R``, ``C``, ``L``, ``S``, ``length``)
    that reproduce its chain of segments exactly (see the module docstring)."""
    canon = model.canonical
    # each vessel's arrangement as the core assembled it (a vessel that states none is a π
    # ladder where `auto` cut it, else inverted-L: the core's rule, not re-derived here)
    t = model.network.segment_table()
    arrangements = dict(zip(t["vessel_names"], t["vessel_arrangements"], strict=True))
    out: dict[str, list[dict[str, float]]] = {}
    segs_by_vessel = vessel_segments(model)
    for v in canon["vessels"]:
        segs = segs_by_vessel[v["name"]]
        arrangement = arrangements[v["name"]]
        if arrangement == "RCL":  # one R-C-L, the BloodVessel itself
            s0 = segs[0]
            out[v["name"]] = [{"R": s0["R"], "C": s0["C"], "L": s0["L"], "S": s0["S"],
                               "length": sum(s["length"] for s in segs)}]
            continue
        cp, cd = _CAPACITANCE_SPLIT[arrangement]
        n = len(segs)
        node_c = [0.0] * (n + 1)
        for k, s in enumerate(segs):
            node_c[k] += cp * s["C"]
            node_c[k + 1] += cd * s["C"]
        chain = [{"R": 0.0, "S": 0.0, "C": node_c[0], "L": segs[0]["L"], "length": 0.0}]
        for k in range(1, n + 1):
            chain.append({"R": segs[k - 1]["R"], "S": segs[k - 1]["S"], "C": node_c[k],
                          "L": segs[k]["L"] if k < n else 0.0, "length": segs[k - 1]["length"]})
        # drop empty blocks (e.g. no capacitance and no inductance before the first R)
        kept = [b for b in chain if b["R"] or b["C"] or b["L"] or b["S"]]
        out[v["name"]] = kept or chain[:1]
    return out


def _sample(w: Mapping[str, Any], period: float, samples: int,
            element: str) -> tuple[list[float], list[float]]:
    """Waveform (canonical, SI) as svZeroDSolver (t, value) lists: a constant and a linear
    table as they are, a Fourier series over its period and a periodic-cubic table over its
    span sampled at ``samples`` points by the core's evaluator (the one the run uses)."""
    kind = w["kind"]
    if kind == "constant":
        return [0.0, period], [w["value"], w["value"]]
    if kind == "table" and w.get("interpolation", "linear") == "linear":
        return list(w["time"]), list(w["value"])
    start, end = (0.0, period) if kind == "fourier" else (w["time"][0], w["time"][-1])
    t = np.linspace(start, end, samples)
    return t.tolist(), _core.waveform_values(element, json.dumps(dict(w)), t.tolist()).tolist()


def _segment_blocks(model: Model, f: Any, vessels: list[dict[str, Any]],
                    junctions: list[dict[str, Any]]) -> tuple[dict[str, int], dict[str, int]]:
    """One BloodVessel per segment (values scaled by ``f(quantity)``) into ``vessels``, the
    junctions between a vessel's segments into ``junctions``; returns the ids of each
    vessel's first and last block."""
    blocks = vessel_blocks(model)
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    for v in model.canonical["vessels"]:
        name = v["name"]
        ids = []
        for k, s in enumerate(blocks[name]):
            vals = {"R_poiseuille": s["R"] * f("resistance"), "C": s["C"] * f("capacitance"),
                    "L": s["L"] * f("inductance"), "stenosis_coefficient": s["S"] * f("stenosis")}
            vid = len(vessels)
            vessels.append({"vessel_id": vid, "vessel_name": f"{name}_seg{k}",
                            "vessel_length": s["length"] * f("length"),
                            "zero_d_element_type": "BloodVessel",
                            "zero_d_element_values": vals})
            ids.append(vid)
            if k > 0:
                junctions.append({"junction_name": f"J_{name}_{k}",
                                  "junction_type": "NORMAL_JUNCTION",
                                  "inlet_vessels": [ids[k - 1]], "outlet_vessels": [vid]})
        first[name], last[name] = ids[0], ids[-1]
    return first, last


def to_svzerod(model: Model, units: str = "cgs", samples: int = 201,
               points_per_cycle: int | None = None, cycles: int | None = None) -> dict[str, Any]:
    """svZeroDSolver input dict for ``model`` (see the module docstring for the mapping).

    ``units="cgs"`` (svZeroDSolver's usual cm, dyn/cm², mL/s) or ``"SI"``. The BloodVessels of
    a vessel are named ``<vessel>_seg<k>`` (k from 0; ``_seg0`` starts at the vessel's inlet, the
    last one ends at its outlet), junctions ``J_<node>`` and ``J_<vessel>_<k>``,
    boundary conditions ``BC_<node>``. ``points_per_cycle`` and ``cycles`` default to the
    model's ``simulation`` settings (output every, cycles).

    >>> import oxyline, oxyline.io
    >>> d = oxyline.io.to_svzerod(oxyline.load_model("bifurcation"))
    >>> len(d["vessels"]), d["vessels"][0]["zero_d_element_type"]  # 3 vessels x (10 + 1)
    (33, 'BloodVessel')
    """
    if units.lower() not in ("cgs", "si"):
        raise ValueError(f"units must be 'cgs' or 'SI', got {units!r}")
    cgs = units.lower() == "cgs"

    def f(q: str) -> float:
        return 1.0 / CGS_TO_SI[q] if cgs else 1.0

    canon = model.canonical
    period = float(model.period or 1.0)
    vessels: list[dict[str, Any]] = []
    junctions: list[dict[str, Any]] = []
    first, last = _segment_blocks(model, f, vessels, junctions)
    # network nodes: ends arriving (inlets of the junction) and leaving
    arriving: dict[str, list[str]] = {}
    leaving: dict[str, list[str]] = {}
    for v in canon["vessels"]:
        leaving.setdefault(v["from"], []).append(v["name"])
        arriving.setdefault(v["to"], []).append(v["name"])
    bcs_out: list[dict[str, Any]] = []
    bcs = canon["boundary_conditions"]
    for node in dict.fromkeys([*leaving, *arriving]):
        ins, outs = arriving.get(node, []), leaving.get(node, [])
        if node in bcs:
            if len(ins) + len(outs) != 1:
                raise UnsupportedElement(f"boundary condition '{node}': sits on a node joined by "
                                         f"{len(ins) + len(outs)} vessel ends; svZeroDSolver "
                                         "needs it on a single vessel end")
            bc_name = f"BC_{node}"
            if outs:
                vessels[first[outs[0]]].setdefault("boundary_conditions", {})["inlet"] = bc_name
            else:
                vessels[last[ins[0]]].setdefault("boundary_conditions", {})["outlet"] = bc_name
            bcs_out.append(_bc(node, bc_name, bcs[node], period, samples, f))
        elif len(ins) + len(outs) >= 2:
            junctions.append({"junction_name": f"J_{node}", "junction_type": "NORMAL_JUNCTION",
                              "inlet_vessels": [last[n] for n in ins],
                              "outlet_vessels": [first[n] for n in outs]})
        else:
            raise UnsupportedElement(f"node '{node}': a free vessel end without a boundary "
                                     "condition cannot be exported to svZeroDSolver")
    # the model's output interval and cycles, with the core's defaults
    sim = _core.resolve_settings(model.simulation or {}, {}, model.period)
    n_pts = points_per_cycle or max(2, round(period / sim["output_every"]) + 1)
    return {
        "description": {"description of test case":
                        f"{model.name}: exported from oxyline ({units} units)"},
        # read by oxyline's importer (svZeroDSolver ignores it): the numbers' unit system
        "units": "cgs" if cgs else "SI",
        "simulation_parameters": {
            "number_of_cardiac_cycles": int(cycles or sim["cycles"]),
            "number_of_time_pts_per_cardiac_cycle": int(n_pts),
            "output_all_cycles": False,
            "steady_initial": True,
        },
        "boundary_conditions": bcs_out,
        "junctions": junctions,
        "vessels": vessels,
    }


def _bc(node: str, bc_name: str, bc: Mapping[str, Any], period: float, samples: int,
        f: Any) -> dict[str, Any]:
    kind = bc["type"]
    el = f"boundary condition '{node}'"

    def constant(w: Mapping[str, Any], key: str) -> float:
        if w["kind"] != "constant":
            raise UnsupportedElement(f"{el}: a time-varying '{key}' has no svZeroDSolver "
                                     f"{kind.upper()} equivalent")
        return float(w["value"])

    if kind in ("flow", "pressure"):  # a table of Q or P
        t, y = _sample(bc[kind], period, samples, el)
        return {"bc_name": bc_name, "bc_type": kind.upper(),
                "bc_values": {"Q" if kind == "flow" else "P": [x * f(kind) for x in y], "t": t}}
    if kind == "resistance":
        return {"bc_name": bc_name, "bc_type": "RESISTANCE",
                "bc_values": {"R": bc["resistance"] * f("resistance"),
                              "Pd": constant(bc["pressure"], "pressure") * f("pressure")}}
    if kind == "rcr":
        return {"bc_name": bc_name, "bc_type": "RCR",
                "bc_values": {"Rp": bc["proximal_resistance"] * f("resistance"),
                              "C": bc["capacitance"] * f("capacitance"),
                              "Rd": bc["distal_resistance"] * f("resistance"),
                              "Pd": constant(bc["pressure"], "pressure") * f("pressure")}}
    raise UnsupportedElement(f"{el}: type '{kind}' has no svZeroDSolver equivalent")
