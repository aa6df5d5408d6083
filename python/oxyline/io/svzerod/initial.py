"""svZeroDSolver's ``initial_condition`` and ``initial_condition_d`` for the drop-in.

svZeroDSolver names the start value of each of its node variables, ``pressure:A:B`` and
``flow:A:B`` (the connection from block A to block B), and of a chamber's volume ``Vc:<chamber>``
(read by :mod:`oxyline.io.svzerod.heart`). ``pressure_all``/``flow_all`` set every node pressure
/ flow not named; names that match no variable are ignored, as svZeroDSolver's loader
(``load_initial_condition``) ignores them. Here each node value becomes the native ``initial``
(``initial_rate`` for ``initial_condition_d``) of the vessel ends that meet at that node
(docs/physics.md §1.9); the core spreads them to the unknowns inside a vessel.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from oxyline.errors import UnsupportedElement
from oxyline.io.svzerod import closed_loop as svzerod_closed_loop
from oxyline.io.svzerod.values import is_comment, number

#: blocks whose unknowns svZeroDSolver's node values fix (checked against svzerod 3.2, round-off
#: agreement): a coronary's compartment pressure at the start (P_Cim_0) and a
#: BloodVesselJunction's or resistive junction's hidden branches are not set from them
SUPPORTED_BCS = {"FLOW", "PRESSURE", "RESISTANCE", "RCR"}
SUPPORTED_JUNCTIONS = {"NORMAL_JUNCTION", "internal_junction"}
#: svZeroDSolver's node variables and chamber volumes; other prefixed names are internal
#: variables of a block (an RCR's ``pressure_c``), which are not set here
NODE_PREFIXES = {"pressure", "flow", "Vc"}


def _defaults(section: Mapping[str, Any]) -> dict[str, float]:
    return {q: float(section[f"{q}_all"]) for q in ("pressure", "flow") if f"{q}_all" in section}


def _check_blocks(cfg: Mapping[str, Any], key: str) -> None:
    """Refuse blocks whose own unknowns (an RCR's capacitor node, a junction's hidden branches)
    svZeroDSolver's node values do not fix: their start would not be svZeroDSolver's."""
    for b in cfg.get("boundary_conditions", []) or []:
        kind = b.get("bc_type") if isinstance(b, Mapping) else None
        if kind not in SUPPORTED_BCS:
            raise UnsupportedElement(
                f"model: '{key}' of pressures and flows with a {kind} boundary condition "
                f"('{b.get('bc_name')}') is not supported (only {sorted(SUPPORTED_BCS)}: its "
                "internal unknowns have no svZeroDSolver node value)")
    for j in cfg.get("junctions", []) or []:
        kind = j.get("junction_type", "NORMAL_JUNCTION") if isinstance(j, Mapping) else None
        if kind not in SUPPORTED_JUNCTIONS:
            raise UnsupportedElement(
                f"model: '{key}' of pressures and flows with a {kind} junction "
                f"('{j.get('junction_name')}') is not supported (its hidden branches have no "
                "svZeroDSolver node value)")


def _node_values(section: Mapping[str, Any], connections: list[tuple[str, str]],
                 el: str) -> dict[tuple[str, str], tuple[float, float]] | None:
    """(pressure, flow) of every svZeroDSolver node, or None when the section names none."""
    names = {f"{q}:{a}:{b}" for a, b in connections for q in ("pressure", "flow")}
    given = [k for k in section if k in names]
    defaults = _defaults(section)
    if not given and not defaults:
        return None
    return {(a, b): (number(section.get(f"pressure:{a}:{b}", defaults.get("pressure", 0.0)), el,
                            f"pressure:{a}:{b}"),
                     number(section.get(f"flow:{a}:{b}", defaults.get("flow", 0.0)), el,
                            f"flow:{a}:{b}"))
            for a, b in connections}


def apply(cfg: Mapping[str, Any], vessels: list[dict[str, Any]],
          ends: list[tuple[str, str, str]], connections: list[tuple[str, str]],
          crl: list[tuple[dict[str, Any], dict[str, Any]]]) -> None:
    """Write the native ``initial``/``initial_rate`` of ``vessels`` (dicts by name) from the
    file's sections. ``ends``: svZeroDSolver block -> (native vessel at its inlet, at its
    outlet); ``connections``: svZeroDSolver's nodes (upstream block, downstream block)."""
    by_name = {v["name"]: v for v in vessels}
    at = {name: (a, b) for name, a, b in ends}
    for key, native_key in (("initial_condition", "initial"),
                            ("initial_condition_d", "initial_rate")):
        section = cfg.get(key)
        if section is None:
            continue
        if not isinstance(section, Mapping):
            raise UnsupportedElement(f"model: '{key}' must be a mapping of variable names")
        if key == "initial_condition_d":
            vc = [k for k in section if k.startswith("Vc:")]
            if vc:
                raise UnsupportedElement(f"model: 'initial_condition_d' entry '{vc[0]}' (a "
                                         "chamber volume's rate) is not supported")
        # the heart block's own entries (V_RA:CLH, ...) are read by svzerod_closed_loop
        internal = [k for k in section if not is_comment(k) and ":" in k
                    and k.split(":", 1)[0] not in NODE_PREFIXES
                    and not svzerod_closed_loop.handles_initial(k)]
        if internal:
            raise UnsupportedElement(f"model: '{key}' entry '{internal[0]}' (an internal "
                                     "variable of a block) is not supported")
        values = _node_values(section, connections, key)
        if values is None:
            continue
        _check_blocks(cfg, key)
        for (a, b), (p, q) in values.items():
            if a in at:  # the node is at the outlet of block a ...
                by_name[at[a][1]].setdefault(native_key, {}).update(
                    {"pressure_out": p, "flow_out": q})
            if b in at:  # ... and at the inlet of block b
                by_name[at[b][0]].setdefault(native_key, {}).update(
                    {"pressure_in": p, "flow_in": q})
        for front, back in crl:
            # a BloodVesselCRL's capacitor node carries its inlet pressure (R = 0 in front of
            # the capacitor, L = 0 behind it); the flow past it is the CRL's outflow
            f, bk = front.setdefault(native_key, {}), back.setdefault(native_key, {})
            f["pressure_out"] = bk["pressure_in"] = f.get("pressure_in", 0.0)
            f["flow_out"] = bk["flow_in"] = bk.get("flow_out", 0.0)


def zero_start_coronaries(bcs: Mapping[str, tuple[str, dict[str, Any]]],
                          steady_initial: bool) -> None:
    """svZeroDSolver's coronary outlets measure the intramyocardial volume from the start:
    ``setup_initial_state_dependent_params`` takes P_Cim_0, the compartment pressure of the
    start state, and Pim_0 = P_im(0), and its equations use P_im(t) − Pim_0 + P_Cim_0. From a
    zero start (no ``initial_condition``) P_Cim_0 = 0: the bed sees P_im(t) − P_im(0), which
    the native condition gets here. (From the steady start the shift is svZeroDSolver's steady
    compartment state, which the native steady start reproduces as it is.)"""
    if steady_initial:
        return
    for kind, native in bcs.values():
        if kind not in ("CORONARY", "CORONARY_VAR_RES"):
            continue
        pim = native["intramyocardial_pressure"]
        if isinstance(pim, Mapping):
            p0 = pim["pressure"][0]  # the periodic table starts at t = 0
            native["intramyocardial_pressure"] = dict(
                pim, pressure=[p - p0 for p in pim["pressure"]], steady=pim["steady"] - p0)
        else:
            native["intramyocardial_pressure"] = 0.0
