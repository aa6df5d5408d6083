"""svZeroDSolver drop-in: ``external_solver_coupling_blocks`` that carry prescribed ``values``
(docs/svzerod.md). Such a block stands for the 3-D solver on the other side of a coupling
interface; with its flow or pressure given as a table, svZeroDSolver's own test suite runs the
file as an ordinary forward simulation. :func:`as_forward` rewrites those blocks into the
ordinary input sections before the importer reads them:

* connected to a vessel: a ``FLOW``/``PRESSURE`` boundary condition of the block's name at that
  vessel's inlet or outlet (svZeroDSolver's node between them keeps its name);
* connected to a boundary condition that needs a vessel end (``ClosedLoopRCR``, closed-loop
  coronaries) or, at an outlet, to the closed-loop heart (whose ``outlet_blocks`` name it): a
  hidden zero-resistance vessel of the block's name carrying the condition at its free end, so
  the node between the block and its neighbour is the one svZeroDSolver has.

A coupling block without ``values`` is driven by an external solver through svZeroDSolver's C
interface: :class:`oxyline.UnsupportedElement`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from oxyline.errors import ModelError, UnsupportedElement

KEYS = {"name", "type", "location", "connected_block", "values", "periodic"}
#: coupling type -> (boundary condition type, its value key)
TYPES = {"FLOW": "Q", "PRESSURE": "P"}
HEART = "ClosedLoopHeartAndPulmonary"


def as_forward(cfg: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str], set[str]]:
    """``cfg`` with its coupling blocks as boundary conditions (and hidden wire vessels).
    Returns (config, the wire vessels' names and the blocks they connect to, names of the
    conditions at their free ends, which svZeroDSolver's variable table does not have)."""
    blocks = cfg.get("external_solver_coupling_blocks")
    if not blocks:
        return cfg, {}, set()
    if not isinstance(blocks, list):
        raise ModelError("external_solver_coupling_blocks: must be a list")
    cfg = dict(cfg, vessels=list(cfg.get("vessels", [])),
               boundary_conditions=list(cfg.get("boundary_conditions", [])))
    cfg.pop("external_solver_coupling_blocks")
    vessels = {v.get("vessel_name"): v for v in cfg["vessels"] if isinstance(v, Mapping)}
    bcs = {b.get("bc_name") for b in cfg["boundary_conditions"] if isinstance(b, Mapping)}
    wires: dict[str, str] = {}
    ends: set[str] = set()
    for i, b in enumerate(blocks):
        if not isinstance(b, Mapping) or not isinstance(b.get("name"), str):
            raise ModelError(f"external_solver_coupling_blocks[{i}]: must be a mapping with a "
                             "'name'")
        name, el = b["name"], f"coupling block '{b['name']}'"
        bad = sorted(k for k in b if k not in KEYS and not str(k).startswith("_"))
        if bad:
            raise UnsupportedElement(f"{el}: unknown key '{bad[0]}'")
        if "values" not in b:
            raise UnsupportedElement(f"{el}: a coupling block without 'values' is driven by an "
                                     "external (3-D) solver through svZeroDSolver's C "
                                     "interface, which oxyline does not implement")
        kind, loc, other = b.get("type"), b.get("location"), b.get("connected_block")
        if kind not in TYPES:
            raise UnsupportedElement(f"{el}: type '{kind}' is not supported (supported: FLOW, "
                                     "PRESSURE)")
        if loc not in ("inlet", "outlet"):
            raise ModelError(f"{el}: location must be 'inlet' or 'outlet', got {loc!r}")
        values = b["values"]
        key = TYPES[kind]
        if not isinstance(values, Mapping) or key not in values or "t" not in values:
            raise ModelError(f"{el}: 'values' needs 't' and '{key}'")
        bc = {"bc_name": name, "bc_type": kind, "bc_values": {"t": values["t"], key: values[key]}}
        if other in vessels:
            v = dict(vessels[other])
            v["boundary_conditions"] = dict(v.get("boundary_conditions", {}), **{loc: name})
            cfg["vessels"][cfg["vessels"].index(vessels[other])] = v
            vessels[other] = v
            cfg["boundary_conditions"].append(bc)
            continue
        if not (other in bcs or (loc == "outlet" and other == HEART)):
            raise ModelError(f"{el}: connected_block '{other}' is not a vessel, a boundary "
                             f"condition or (at an outlet) the {HEART} block")
        # the wire: the condition at its free end, the neighbour at the other
        free = f"{name}:values"
        bc["bc_name"] = free
        sides = {"inlet": free} if loc == "inlet" else {"outlet": free}
        if loc == "inlet":
            sides["outlet"] = other
        elif other != HEART:
            sides["inlet"] = other
        cfg["vessels"].append({"vessel_id": f"{free}:vessel", "vessel_name": name,
                               "zero_d_element_type": "BloodVessel",
                               "zero_d_element_values": {"R_poiseuille": 0.0},
                               "boundary_conditions": sides})
        cfg["boundary_conditions"].append(bc)
        wires[name] = other
        ends.add(free)
    return cfg, wires, ends
