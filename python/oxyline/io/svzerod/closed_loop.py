"""svZeroDSolver drop-in: the closed-loop blocks (``closed_loop_blocks`` with
``ClosedLoopHeartAndPulmonary``, and the ``ClosedLoopRCR``, ``ClosedLoopCoronaryLeft`` and
``ClosedLoopCoronaryRight`` boundary conditions), translated into oxyline's native
``heart_pulmonary`` and ``coronary_bed`` elements and lumped vessels (docs/physics.md §1.10,
docs/svzerod.md "Closed-loop blocks").

svZeroDSolver joins the outlets of every closed-loop boundary condition at one junction in
front of the heart block (``J_heart_inlet``) and the heart's outlet to the block's
``outlet_blocks`` (``J_heart_outlet``); a junction of svZeroDSolver is a node of oxyline's. The
heart block's name is always ``CLH`` (the name its ``initial_condition`` entries carry).
Numbers stay the file's, as in :mod:`oxyline.io.svzerod`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from oxyline.errors import ModelError, UnsupportedElement
from oxyline.io.svzerod.values import mapped, number

HEART = "CLH"
HEART_INLET = "J_heart_inlet"
HEART_OUTLET = "J_heart_outlet"
CORONARY_TYPES = {"ClosedLoopCoronaryLeft": "left", "ClosedLoopCoronaryRight": "right"}
#: svZeroDSolver's parameters of the closed-loop boundary conditions
BC_PARAMS = {
    "ClosedLoopRCR": {"Rp", "C", "Rd", "closed_loop_outlet"},
    **{k: {"Ra", "Ram", "Rv", "Ca", "Cim"} for k in CORONARY_TYPES},
}
#: svZeroDSolver's heart parameter -> the native ``heart_pulmonary`` key
HEART_PARAMS = {
    "Tsa": "atrial_systole_fraction", "tpwave": "p_wave_divisor",
    "Erv_s": "right_ventricle_elastance", "Elv_s": "left_ventricle_elastance",
    "Vrv_u": "right_ventricle_rest_volume", "Vlv_u": "left_ventricle_rest_volume",
    "Lra_v": "tricuspid_inductance", "Rra_v": "tricuspid_resistance",
    "Lrv_a": "pulmonary_valve_inductance", "Rrv_a": "pulmonary_valve_resistance",
    "Lla_v": "mitral_inductance", "Rla_v": "mitral_resistance",
    "Llv_a": "aortic_valve_inductance", "Rlv_ao": "aortic_valve_resistance",
    "Rpd": "pulmonary_resistance", "Cp": "pulmonary_capacitance", "Cpa": "aortic_capacitance",
    "Emax_ra": "right_atrium_elastance", "Kxp_ra": "right_atrium_passive_pressure",
    "Kxv_ra": "right_atrium_passive_volume_coefficient", "Vaso_ra": "right_atrium_rest_volume",
    "Emax_la": "left_atrium_elastance", "Kxp_la": "left_atrium_passive_pressure",
    "Kxv_la": "left_atrium_passive_volume_coefficient", "Vaso_la": "left_atrium_rest_volume",
}
#: the coronary beds' intramyocardial factors (heart parameters in svZeroDSolver)
FACTORS = {"iml": "left", "imr": "right"}
#: the heart's internal variables that ``initial_condition`` may set
INITIAL = {"V_RA": "initial_right_atrium_volume", "V_RV": "initial_right_ventricle_volume",
           "V_LA": "initial_left_atrium_volume", "V_LV": "initial_left_ventricle_volume",
           "P_pul": "initial_pulmonary_pressure"}
#: the heart block's internal variables in svZeroDSolver's order (its variable table): a
#: chamber's volume (the core's ``chamber_volumes`` entry ``CLH:<chamber>``) or a pressure or
#: flow at a valve (the core's valve probe ``CLH:<valve>``: 0 the pressure behind it, 1 the
#: pressure in front, 2 its flow; the pulmonary valve opens into the pulmonary pressure P_pul)
VARIABLES = (("V_RA", "right_atrium"), ("Q_RA", ("tricuspid", 2)), ("P_RV", ("tricuspid", 1)),
             ("V_RV", "right_ventricle"), ("Q_RV", ("pulmonary", 2)),
             ("P_pul", ("pulmonary", 1)), ("P_LA", ("mitral", 0)), ("V_LA", "left_atrium"),
             ("Q_LA", ("mitral", 2)), ("P_LV", ("mitral", 1)), ("V_LV", "left_ventricle"),
             ("Q_LV", ("aortic", 2)))
BLOCK_KEYS = {"outlet_blocks", "closed_loop_type", "cardiac_cycle_period", "parameters"}


def handles_initial(key: str) -> bool:
    """Whether an ``initial_condition`` entry is the heart block's (read here)."""
    return key.endswith(f":{HEART}")


def boundary_condition(kind: str, vals: Mapping[str, Any], el: str) -> dict[str, Any]:
    """The parameters of a closed-loop boundary condition (placed as elements by
    :func:`add_blocks`, not as a native boundary condition)."""
    keys = sorted(BC_PARAMS[kind] - {"closed_loop_outlet"})
    out: dict[str, Any] = {"type": kind, **mapped(vals, el, {k: k for k in keys})}
    if kind == "ClosedLoopRCR" and vals.get("closed_loop_outlet") is not True:
        raise UnsupportedElement(f"{el}: a ClosedLoopRCR without closed_loop_outlet = true "
                                 "(its outlet joined to another block) is not supported")
    return out


def heart_period(cfg: Mapping[str, Any]) -> float | None:
    """The cardiac period of the file's heart block (None without one)."""
    blocks = cfg.get("closed_loop_blocks") or []
    for b in blocks if isinstance(blocks, list) else []:
        if isinstance(b, Mapping) and b.get("closed_loop_type") == "ClosedLoopHeartAndPulmonary":
            p = b.get("cardiac_cycle_period")
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not p > 0:
                raise ModelError("closed-loop block 'ClosedLoopHeartAndPulmonary': "
                                 f"cardiac_cycle_period must be > 0, got {p!r}")
            return float(p)
    return None


def _heart(block: Mapping[str, Any], period: float, initial: Mapping[str, Any]
           ) -> tuple[dict[str, Any], dict[str, float]]:
    """The native ``heart_pulmonary`` element and the intramyocardial factors by ventricle."""
    el = "closed-loop block 'ClosedLoopHeartAndPulmonary'"
    for k in block:
        if k not in BLOCK_KEYS and not k.startswith("_"):
            raise UnsupportedElement(f"{el}: unknown key '{k}'")
    params = block.get("parameters")
    if not isinstance(params, Mapping):
        raise ModelError(f"{el}: missing 'parameters'")
    for k in params:
        if k not in HEART_PARAMS and k not in FACTORS and not k.startswith("_"):
            raise UnsupportedElement(f"{el}: unknown parameter '{k}'")
    native: dict[str, Any] = {"period": period, **mapped(params, el, HEART_PARAMS,
                                                          what="parameter ")}
    factors = {side: number(params.get(k, 0.0), el, k) for k, side in FACTORS.items()}
    for key, value in initial.items():
        if not handles_initial(key):
            continue
        var = key[: -len(HEART) - 1]
        if var not in INITIAL:
            raise UnsupportedElement(f"model: 'initial_condition' entry '{key}' is not supported "
                                     f"(of the heart block only {', '.join(INITIAL)} are)")
        native[INITIAL[var]] = number(value, "initial_condition", key)
    return native, factors


def add_blocks(cfg: Mapping[str, Any], period: float, vessels: list[dict[str, Any]],
               bcs: Mapping[str, tuple[str, dict[str, Any]]], attach: Any, names: set[str]
               ) -> None:
    """Append the heart block, the closed-loop boundary conditions' elements and the heart's
    outlet connections to ``vessels`` (joined with ``attach`` as the importer joins vessels).
    ``bcs`` are the file's boundary conditions: each closed-loop one's node is already the
    outlet of the vessel it terminates."""
    blocks = cfg.get("closed_loop_blocks") or []
    if not isinstance(blocks, list):
        raise ModelError("closed_loop_blocks: must be a list")
    closed = {n: nat for n, (kind, nat) in bcs.items() if kind in BC_PARAMS}
    for b in blocks:
        kind = b.get("closed_loop_type") if isinstance(b, Mapping) else None
        if kind != "ClosedLoopHeartAndPulmonary":
            raise UnsupportedElement(f"closed_loop_blocks: closed_loop_type {kind!r} is not "
                                     "supported (supported: ClosedLoopHeartAndPulmonary)")
    hearts = blocks  # every block is the heart block (the one supported type)
    if len(hearts) > 1:
        raise ModelError("closed_loop_blocks: Only one ClosedLoopHeartAndPulmonary can be "
                         "included")
    if not hearts:
        if closed:
            raise UnsupportedElement(f"boundary condition '{next(iter(closed))}': a closed-loop "
                                     "boundary condition without a ClosedLoopHeartAndPulmonary "
                                     "block is not supported")
        return
    for n in (HEART, HEART_INLET, HEART_OUTLET):
        if n in names or n in bcs:
            raise ModelError(f"block '{n}': name already used (svZeroDSolver reserves it for "
                             "the closed-loop heart)")
    initial = cfg.get("initial_condition") or {}
    heart, factors = _heart(hearts[0], period, initial if isinstance(initial, Mapping) else {})
    vessels.append({"name": HEART, "heart_pulmonary": heart, "output": False,
                    "description": "svZeroDSolver ClosedLoopHeartAndPulmonary"})
    attach(HEART, "in", HEART_INLET, "the heart block")
    attach(HEART, "out", HEART_OUTLET, "the heart block")
    outlets = hearts[0].get("outlet_blocks")
    if not isinstance(outlets, list) or not outlets:
        raise ModelError("closed-loop block 'ClosedLoopHeartAndPulmonary': 'outlet_blocks' "
                         "must be a non-empty list of vessel names")
    for o in outlets:
        if o not in names:
            raise ModelError(f"closed-loop block 'ClosedLoopHeartAndPulmonary': outlet block "
                             f"'{o}' is not a vessel")
        attach(o, "in", HEART_OUTLET, "the heart block's outlet")
    for bc, nat in closed.items():
        _closed_bc(bc, nat, factors, vessels, attach)


def _closed_bc(bc: str, nat: Mapping[str, Any], factors: Mapping[str, float],
               vessels: list[dict[str, Any]], attach: Any) -> None:
    """A closed-loop boundary condition from its node ``bc`` to the heart's inlet: a
    ClosedLoopRCR as a resistance with its capacitor behind it and the distal resistance
    (svZeroDSolver's P_in − R_p Q_in = P_c, C dP_c/dt = Q_in − Q_out, P_c − R_d Q_out = P_out:
    two RCL vessels), a closed-loop coronary as a native ``coronary_bed``."""
    what = f"boundary condition '{bc}'"
    if nat["type"] == "ClosedLoopRCR":
        rp, rd = f"{bc}:proximal", f"{bc}:distal"
        vessels.append({"name": rp, "arrangement": "RCL", "output": False,
                        "lumped": {"resistance": nat["Rp"], "capacitance": nat["C"],
                                   "inductance": 0.0}, "description": "ClosedLoopRCR Rp, C"})
        vessels.append({"name": rd, "arrangement": "RCL", "output": False,
                        "lumped": {"resistance": nat["Rd"]}, "description": "ClosedLoopRCR Rd"})
        attach(rp, "in", bc, what)
        attach(rp, "out", f"{bc}:c", what)
        attach(rd, "in", f"{bc}:c", what)
        attach(rd, "out", HEART_INLET, what)
        return
    side = CORONARY_TYPES[nat["type"]]
    name = f"{bc}:bed"
    vessels.append({"name": name, "output": False, "description": nat["type"],
                    "coronary_bed": {
                        "arterial_resistance": nat["Ra"], "arterial_capacitance": nat["Ca"],
                        "microvascular_resistance": nat["Ram"],
                        "intramyocardial_capacitance": nat["Cim"],
                        "venous_resistance": nat["Rv"], "heart": HEART, "ventricle": side,
                        "intramyocardial_factor": factors[side]}})
    attach(name, "in", bc, what)
    attach(name, "out", HEART_INLET, what)
