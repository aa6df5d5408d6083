"""Oxygen around a closed circulation (docs/oxygen.md "Oxygen around a closed
loop"): heart chambers, systemic arteries, organ beds consuming O2, systemic veins and the lungs
as well-mixed compartments joined by the circulation's flows. The physics (compartments,
Michaelis–Menten VO2, diffusion-limited lung exchange with Hill binding, the periodic steady
state) lives in the core (``oxyline_core::transport::closed_loop``); this module loads the
built-in parameter sets ``closed-loop-o2`` and ``closed-loop-o2-tree`` (the data file
``models_data/closed-loop-o2.yaml``), has the core convert
them to SI (``oxyline_core::transport::closed_loop_params``: compartments, branches, binding,
organ resistances, the prescribed flow table), builds the closed-loop heart that drives the
flows and summarises the result.

    from oxyline import closed_loop
    res = closed_loop.simulate_o2("closed-loop-o2")
    print(res.summary())     # SaO2, SvO2, PO2s, VO2 per organ, Fick and mass-balance residuals

The flows come from a closed-loop heart the core runs first (`heart_spec`): by default svZeroDSolver's
ClosedLoopHeartAndPulmonary block (`heart: "svzerod-block"`, docs/physics.md §1.10), or the
native two-ventricle heart (`heart: "two-ventricle"`), or a prescribed table (`flows:
"table"`: a pulsatile ejection of both ventricles, steady organ flows and venous return).
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.catalogue import shipped_data
from oxyline.errors import ModelError, ResourceError, core_errors
from oxyline.model import build_model
from oxyline.units import MMHG

ML_O2: float = _core.ML_O2  # mol per mL O2 (STPD; docs/physics.md: 1 mL = 1/22.414 mmol)

_DATA = shipped_data("closed-loop-o2.yaml")
#: ``closed-loop-o2``: a resting adult (textbook values; units L, L/min, mL/min, mmHg; each
#: value's source and unit in ``models_data/closed-loop-o2.yaml``)
STANDARD: dict[str, Any] = _DATA["standard"]
#: the systemic arterial trunk of ``closed-loop-o2-tree`` (ADAN56's aorta and one equivalent
#: artery per organ bed; SI): vessels (name, from, to, length, radius)
TREE: dict[str, Any] = _DATA["tree"]
#: svZeroDSolver's ClosedLoopHeartAndPulmonary block (docs/physics.md §1.10) with the
#: parameters of its closedLoopHeart cases, in their units (mmHg, mL, s: the core converts
#: them); the block beats at the loop's `period`
SVZEROD_HEART: dict[str, float] = _DATA["svzerod_heart"]

STANDARD_TREE: dict[str, Any] = {**copy.deepcopy(STANDARD), "name": "closed-loop-o2-tree",
                                 "arteries": "tree", "tree": TREE}

BUILTINS = {"closed-loop-o2": STANDARD, "closed-loop-o2-tree": STANDARD_TREE}


def _has_tree(p: dict[str, Any]) -> bool:
    return p.get("arteries", "pool") == "tree"


def load(name: str = "closed-loop-o2") -> dict[str, Any]:
    """A copy of a built-in closed-loop O2 parameter set (edit it and pass it to simulate_o2)."""
    if name not in BUILTINS:
        raise ModelError(f"'{name}': not a built-in closed-loop model (built-ins: "
                         f"{', '.join(BUILTINS)})")
    return copy.deepcopy(BUILTINS[name])


def _layout(p: dict[str, Any], table: bool = False) -> tuple[dict[str, Any], np.ndarray | None]:
    """The loop in SI, as the core converts the parameter set: ``compartments`` (flow order),
    ``branches`` and ``binding`` of its O2 run, ``organ_resistances`` (Pa s/m³, in organ
    order), ``solubility_per_mmhg`` and ``cardiac_output`` (m³/s); with ``table`` also the
    prescribed flow table (:func:`flow_table`)."""
    with core_errors("closed-loop layout"):
        text, flows = _core.closed_loop_layout(json.dumps(p), table)
    return json.loads(text), flows


def flow_table(p: dict[str, Any]) -> np.ndarray:
    """Branch flows (m³/s) for each step of one cycle, branches in the order of
    ``result.branches`` (the core's): half-sine ejections of both ventricles (duration
    `ejection_time`), steady organ flows, venous return, pulmonary and filling flows. The
    ejection is scaled so that its discrete cycle mean equals the cardiac output exactly
    (periodic chamber volumes, which the core checks)."""
    return np.asarray(_layout(p, table=True)[1])


def _organ_resistances(p: dict[str, Any]) -> dict[str, float]:
    """Each organ bed's resistance (Pa s/m³): the beds share the cardiac output at a mean
    arterial pressure of 93 mmHg (the core's)."""
    return dict(zip(p["organs"], _layout(p)[0]["organ_resistances"], strict=True))


def heart_model(p: dict[str, Any]) -> dict[str, Any]:
    """A native closed-loop circulation (no boundary condition) whose flows drive the O2 loop:
    the heart `p["heart"]` (`_block_heart` or `_two_ventricle_heart`) between the venous
    return (node ``venous_return``) and the aorta (``aorta_in``), the systemic arteries (a
    pool of 1.5 mL/mmHg, or the tree of `tree_vessels` with ``arteries: "tree"``), the organs
    as parallel resistances sharing the cardiac output by `flow_fraction` at a mean arterial
    pressure of ~93 mmHg, and the systemic veins (100 mL/mmHg); SI units."""
    kind = p.get("heart", "two-ventricle")
    if kind not in HEARTS:
        raise ModelError(f"closed loop: heart must be one of {', '.join(HEARTS)}, got {kind!r}")
    heart = HEARTS[kind](p)
    fdt = p.get("flow_dt", 1e-3)
    return {"name": "closed-loop-heart", "units": "SI", "period": p["period"],
            "vessels": _systemic(p) + heart, "boundary_conditions": {}, **_TREE_BLOOD,
            "simulation": {"cycles": 30, "dt": fdt, "method": "generalized-alpha",
                           "output": {"cycles": "last", "every": fdt}}}


def heart_run_options(p: dict[str, Any]) -> dict[str, Any]:
    """Run options of :func:`heart_model`'s model: svZeroDSolver's block needs an absolute
    Newton tolerance (its on/off valves, docs/physics.md §1.10); Pa, m³/s and m³ residuals
    here, 1e-10 is far below their discretisation error."""
    return {"newton_atol": 1e-10} if p.get("heart", "two-ventricle") == "svzerod-block" else {}


def _lumped(name: str, a: str, b: str, **values: float) -> dict[str, Any]:
    return {"name": name, "from": a, "to": b, "arrangement": "RCL", "lumped": values}


def _systemic(p: dict[str, Any]) -> list[dict[str, Any]]:
    """From the aorta (``aorta_in``) to the venous return (``venous_return``): arteries,
    organs, veins."""
    beds = _organ_resistances(p)
    if _has_tree(p):
        # the segment-resolved tree in place of the arterial pool; organs at its outlets
        v = tree_vessels(p)
        v += [_lumped(k, f"{k}_a", "veins_in", resistance=r) for k, r in beds.items()]
    else:
        v = [_lumped("arteries", "aorta_in", "arteries_out", resistance=1e6,
                     capacitance=1.5e-8, inductance=1e5)]
        v += [_lumped(k, "arteries_out", "veins_in", resistance=r) for k, r in beds.items()]
    return v + [_lumped("veins", "veins_in", "venous_return", resistance=1e6,
                        capacitance=7.5e-7)]


def _block_heart(p: dict[str, Any]) -> list[dict[str, Any]]:
    """svZeroDSolver's ClosedLoopHeartAndPulmonary (docs/physics.md §1.10) with the
    parameters of its closedLoopHeart cases (`SVZEROD_HEART`, in mmHg, mL and s as published:
    the core converts them), beating at the loop's
    period (run it with :func:`heart_run_options`). Measured (30 cycles, 1 ms, pool arteries, venous start
    pressure 7 mmHg): see docs/oxygen.md "Oxygen around a closed loop"."""
    values = dict(p.get("heart_block", SVZEROD_HEART))
    # the stressed blood volume the circulation needs beyond the cases' start volumes, put
    # into the ventricles at the start (their law is linear: it empties into the loop within
    # a few beats; the atria's exponential passive law would not take it smoothly)
    for side in ("left", "right"):
        values[f"initial_{side}_ventricle_volume"] += 0.5 * p["stressed_volume"]
    # the values as given, in their units: the core converts them (`units: mmHg-mL`)
    heart = {"name": "heart_pulmonary", "from": "venous_return", "to": "aorta_in",
             "heart_pulmonary": {"units": "mmHg-mL", "period": p["period"], **values}}
    return [heart]


def _two_ventricle_heart(p: dict[str, Any]) -> list[dict[str, Any]]:
    """The native two-ventricle heart (docs/physics.md §1.8: `chamber` and `valve` elements):
    left and right ventricles (linear elastance, piecewise-cosine activation), four tanh
    valves, pulmonary arteries, lungs, pulmonary veins. Chamber parameters are the `chambers`
    branch's minimal closed loop (LV) and a right ventricle with a fifth of its active
    elastance; SI units. Measured (30 cycles, 1 ms): cardiac output 4.97 L/min, arterial
    pressure 86/112 mmHg, pulmonary arterial mean 20 mmHg."""
    T = p["period"]
    scale = T / 0.8

    def act() -> dict[str, Any]:
        return {"kind": "piecewise-cosine", "contract_start": 0.0, "relax_start": 0.25 * scale,
                "contract_duration": 0.25 * scale, "relax_duration": 0.2 * scale}

    def chamber(e_max: float, e_pass: float) -> dict[str, Any]:
        return {"law": "linear", "max_elastance": e_max, "passive_elastance": e_pass,
                "rest_volume": 1e-5, "period": T, "initial_volume": 0.6e-3, "activation": act()}

    valve = {"law": "tanh", "min_resistance": 1.0e6, "max_resistance": 1.0e11, "steepness": 0.05}
    v = [{"name": "lv", "from": "mitral_out", "to": "lv_out", "chamber": chamber(3.3e8, 1.2e7)},
         {"name": "aortic_valve", "from": "lv_out", "to": "aorta_in", "valve": valve},
         {"name": "tricuspid_valve", "from": "venous_return", "to": "rv_in", "valve": valve},
         {"name": "rv", "from": "rv_in", "to": "rv_out", "chamber": chamber(0.6e8, 0.6e7)},
         {"name": "pulmonary_valve", "from": "rv_out", "to": "pa_in", "valve": valve},
         _lumped("pulmonary_arteries", "pa_in", "pa_out", resistance=1e6, capacitance=2.25e-8),
         _lumped("lungs", "pa_out", "pv_in", resistance=1.2e7),
         _lumped("pulmonary_veins", "pv_in", "mitral_in", resistance=1e6, capacitance=6e-8),
         {"name": "mitral_valve", "from": "mitral_in", "to": "mitral_out", "valve": valve}]
    return v


HEARTS = {"svzerod-block": _block_heart, "two-ventricle": _two_ventricle_heart}


# blood and segment layout shared by the closed loop and its tree's own model (the same
# equations for the tree's segments in both)
_TREE_BLOOD = {"blood": {"density": 1060.0, "viscosity": 0.004}, "arrangement": "inverted-L"}


def tree_vessels(p: dict[str, Any]) -> list[dict[str, Any]]:
    """The arterial tree's vessels (SI), each cut into ceil(length / max_segment_length)
    segments."""
    t = p["tree"]
    out = []
    for name, a, b, length, radius in t["vessels"]:
        out.append({"name": name, "from": a, "to": b, "length": length, "radius": radius,
                    "wall_thickness": t["wall_ratio"] * radius,
                    "youngs_modulus": t["youngs_modulus"], "poisson_ratio": 0.5,
                    "segments": max(1, math.ceil(length / t["max_segment_length"] - 1e-9))})
    return out


def tree_model(p: dict[str, Any], time: np.ndarray | None = None,
               inflow: np.ndarray | None = None,
               venous_pressure: np.ndarray | None = None) -> dict[str, Any]:
    """The tree as an open network driven by the closed-loop heart: the aortic-valve flow into
    its root and, at every outlet, its organ bed's resistance to the recorded venous pressure
    (both tables over one cycle; in :func:`simulate_o2` the core writes those of its heart run
    into them, here without tables the cardiac output and 7 mmHg): the same equations the
    tree's segments obey inside the closed loop. Its `oxygen` section carries the loop's blood
    (Hill binding) and the tree's wall closure; the root's PO2 is replaced step by step by the
    left heart's (`oxyline_core::transport::closed_loop_tree`)."""
    lay, _ = _layout(p)
    if time is None or inflow is None or venous_pressure is None:
        time = np.array([0.0, p["period"]])
        inflow = np.full(2, lay["cardiac_output"])
        venous_pressure = np.full(2, 7.0 * MMHG)
    T = p["period"]
    b = p["blood"]
    bcs: dict[str, Any] = {"aorta_in": {"type": "flow", "time": list(time),
                                        "flow": list(inflow)}}
    for k, r in zip(p["organs"], lay["organ_resistances"], strict=True):
        bcs[f"{k}_a"] = {"type": "resistance", "resistance": r,
                         "pressure": {"time": list(time), "pressure": list(venous_pressure)}}
    return {"name": "closed-loop-arterial-tree", "units": "SI", "period": T,
            "vessels": tree_vessels(p), "boundary_conditions": bcs, **_TREE_BLOOD,
            "oxygen": {"inlet": {"po2": 95.0}, "hemoglobin": "hill",
                       "hill": {"p50": b["p50"], "n": b["hill_n"], "hb": b["hemoglobin"],
                                "huefner": b["hufner"]},
                       "solubility": lay["solubility_per_mmhg"],  # mol m⁻³ mmHg⁻¹
                       "diffusivity": 2.0e-9, "wall": p["tree"]["wall"],
                       "reference_pressure": 93.0}}


@dataclass
class HeartRun:
    """The last cycle of the closed-loop heart's run (``ClosedLoopO2Result.heart``): the
    recorded times (s, from 0) and, by name, what the O2 loop reads: the flows (m³/s)
    ``aortic`` (ejection through the aortic valve), ``aortic_outflow`` (into the arteries or
    the tree's root), ``tricuspid``, ``pulmonary`` (the right ventricle's ejection), ``lungs``,
    ``mitral``, every organ's, and the pressure ``veins`` (Pa) at the systemic veins' inlet."""

    time: np.ndarray
    series: dict[str, np.ndarray]


def heart_spec(p: dict[str, Any]) -> dict[str, Any]:
    """The core's closed-loop heart run (:func:`heart_model`, 30 cycles, every unknown of the
    last one recorded); the core reads the O2 loop's branch flows from it by unknown name
    (``oxyline_core::transport::closed_loop_heart_series``: on/off valves gated, the shunt
    taking `shunt_fraction` of the lungs' flow), each step's flow the mean of the recorded
    intervals it spans."""
    return {"model": build_model(heart_model(p)).canonical, "dt": p.get("flow_dt", 1e-3),
            "cycles": 30, "newton_atol": heart_run_options(p).get("newton_atol"),
            "series_of": {"heart": p.get("heart", "two-ventricle"), "organs": list(p["organs"]),
                          "shunt_fraction": p["lungs"]["shunt_fraction"],
                          "tree": _has_tree(p)}}


@dataclass
class ArterialTreeO2:
    """The arterial tree's recorded cycle (``ClosedLoopO2Result.tree``): arrays [step] or
    [step, outlet] / [step, segment]."""

    outlets: list[str]         # organ fed by every outlet
    segments: list[str]        # "vessel:k"
    inflow: np.ndarray         # m³/s into the root
    outflow: np.ndarray        # m³/s out of every outlet
    in_flux: np.ndarray        # mol/s into the root
    out_flux: np.ndarray       # mol/s out of every outlet
    wall: np.ndarray           # mol/s wall uptake
    amount: np.ndarray         # mol in the tree at each step end
    po2: np.ndarray            # mmHg per segment
    flow_periodic_error: float

    def po2_along(self, vessels: list[str] | None = None) -> dict[str, np.ndarray]:
        """Cycle-mean PO2 (mmHg) of every segment, per vessel (in flow order)."""
        mean = self.po2.mean(axis=0)
        out: dict[str, list[float]] = {}
        for name, v in zip(self.segments, mean):
            out.setdefault(name.rsplit(":", 1)[0], []).append(float(v))
        return {k: np.asarray(v) for k, v in out.items() if vessels is None or k in vessels}


@dataclass
class ClosedLoopO2Result:
    """The recorded last (periodic) cycle: arrays [step, compartment] or [step, branch]."""

    compartments: list[str]
    branches: list[str]
    time: np.ndarray
    flow: np.ndarray
    volume: np.ndarray
    total: np.ndarray
    po2: np.ndarray          # mmHg
    saturation: np.ndarray
    vo2: np.ndarray          # mol/s per compartment
    flux: np.ndarray         # mol/s per branch
    uptake: np.ndarray       # mol/s per branch (lungs)
    amount: np.ndarray       # mol in the loop at each step end (tree included)
    amount_start: float
    dt: float
    cycles: int
    periodic_error: float
    tree: ArterialTreeO2 | None = None
    #: the closed-loop heart's last cycle when it gave the flows
    heart: HeartRun | None = None

    def _c(self, name: str) -> int:
        return self.compartments.index(name)

    def _b(self, name: str) -> int:
        return self.branches.index(name)

    def flow_weighted(self, var: np.ndarray, branch: str, compartment: str) -> float:
        """Cycle mean of a compartment variable weighted by the flow leaving it by `branch`."""
        q = self.flow[:, self._b(branch)]
        return float(np.sum(q * var[:, self._c(compartment)]) / np.sum(q))

    def arterial_flow(self) -> np.ndarray:
        """The left heart's ejection per step (m³/s): into the tree's root or the pool."""
        if self.tree is not None:
            return self.tree.inflow
        return self.flow[:, self._b("ejection_left")]

    def _arterial(self, var: np.ndarray) -> float:
        q = self.arterial_flow()
        return float(np.sum(q * var[:, self._c("left_heart")]) / np.sum(q))

    def _arterial_content(self) -> float:
        """CaO2 (mol/m³): the net O2 the left heart ejects per volume. Into the tree it is the
        root's flux over its flow: a closing tanh valve leaks back a little blood, which
        carries the root's content, not the left heart's (the left-heart-weighted content is
        off by ~5e-8 of VO2 there)."""
        if self.tree is not None:
            return float(np.sum(self.tree.in_flux) / np.sum(self.tree.inflow))
        return self._arterial(self.total)

    def wall_uptake(self) -> np.ndarray:
        """The arterial tree's wall uptake per step (mol/s; zeros without a tree)."""
        return self.tree.wall if self.tree is not None else np.zeros(len(self.time))

    def summary(self) -> dict[str, Any]:
        """Arterial (left-heart ejection) and mixed-venous (right-heart ejection) PO2 and
        saturation, flow-weighted over the cycle; VO2 per organ and in total (mL/min; the
        total includes the arterial tree's wall uptake, `VO2_tree_wall`); cardiac output
        (L/min); Fick's residual |VO2 − CO (CaO2 − CvO2)| / VO2 and the largest per-step
        mass-balance residual of the loop relative to its O2 amount."""
        to_ml_min = 60.0 / ML_O2
        vo2 = {n: float(self.vo2[:, i].mean()) * to_ml_min
               for i, n in enumerate(self.compartments) if np.any(self.vo2[:, i])}
        wall = self.wall_uptake()
        total_vo2 = float(self.vo2.sum(axis=1).mean() + wall.mean())
        co = float(self.arterial_flow().mean())
        ca = self._arterial_content()
        cv = self.flow_weighted(self.total, "ejection_right", "right_heart")
        fick = abs(total_vo2 - co * (ca - cv)) / total_vo2
        n = np.concatenate([[self.amount_start], self.amount])
        rate = self.uptake.sum(axis=1) - self.vo2.sum(axis=1) - wall
        mass = float(np.max(np.abs(np.diff(n) - self.dt * rate)) / np.max(n))
        out = {
            "SaO2": self._arterial(self.saturation),
            "SvO2": self.flow_weighted(self.saturation, "ejection_right", "right_heart"),
            "PaO2": self._arterial(self.po2),
            "PvO2": self.flow_weighted(self.po2, "ejection_right", "right_heart"),
            "CaO2": ca / ML_O2 * 1e-3, "CvO2": cv / ML_O2 * 1e-3,      # mL O2 per L blood
            "VO2": total_vo2 * to_ml_min, "VO2_organs": vo2,
            "VO2_tree_wall": float(wall.mean()) * to_ml_min,
            "lung_uptake": float(self.uptake.sum(axis=1).mean()) * to_ml_min,
            "cardiac_output": co * 6e4,
            "fick_residual": fick, "mass_balance_residual": mass,
            "cycles": self.cycles, "periodic_error": self.periodic_error,
        }
        if self.tree is not None:
            # O2 delivered to each organ by its outlet, and the outlets' flow-weighted PO2
            t = self.tree
            out["DO2_organs"] = {k: float(t.out_flux[:, i].mean()) * to_ml_min
                                 for i, k in enumerate(t.outlets)}
        return out


def _tree_spec(p: dict[str, Any], idx: dict[str, int]) -> dict[str, Any]:
    """The arterial tree of the core's loop: its model's inlet and outlet tables are those of
    the core's heart run."""
    canonical = build_model(tree_model(p)).canonical
    return {"model": json.dumps(canonical), "inlet": "aorta_in",
            "from": idx["left_heart"], "flow_cycles": int(p["tree"]["flow_cycles"]),
            "outlets": [{"boundary": f"{k}_a", "to": idx[k]} for k in p["organs"]]}


def _flow_table(p: dict[str, Any], flows: np.ndarray | str | None,
                branches: list[dict[str, Any]]) -> tuple[np.ndarray | None, bool]:
    """The loop's flow table and whether the core balances it: the prescribed table is
    periodic by construction; a caller's table is balanced first; None: the core's heart run
    gives it (balanced)."""
    if flows is None:
        flows = p.get("flows", "table")
    if isinstance(flows, str) and flows == "table":
        return flow_table(p), False
    if isinstance(flows, str):
        if flows != "heart":
            raise ModelError(f"closed loop: flows must be a table, 'table' or 'heart', "
                             f"got {flows!r}")
        return None, True
    flows = np.asarray(flows, dtype=float)
    if flows.ndim != 2 or flows.shape[1] != len(branches):
        raise ModelError(f"closed loop: flows must be (steps, {len(branches)}) for the "
                         f"branches {[b['name'] for b in branches]}, got {flows.shape}")
    return flows, True


def simulate_o2(model: str | dict[str, Any] = "closed-loop-o2", max_cycles: int = 400,
                tol: float = 1e-13, flows: np.ndarray | str | None = None,
                shooting: str = "anderson") -> ClosedLoopO2Result:
    """Runs O2 around the closed loop to its periodic steady state (the core's Anderson
    acceleration of the cycle map, or with ``shooting="newton"`` the earlier finite-difference
    Newton shooting; then plain cycles until the start-of-cycle contents repeat to `tol`).
    `flows`: ``"heart"`` takes them from a run of the model's closed-loop heart (`heart`:
    svZeroDSolver's block by default; :func:`heart_spec`: the core runs it, then the O2
    loop, in one call; its last cycle is ``result.heart``), ``"table"``
    is the prescribed table (:func:`flow_table`), None the model's own choice (`flows`); a
    table (steps × branches, m³/s, one row per step of `dt`, branches in the order of
    ``result.branches``), e.g. flows sampled from a flow run, is balanced first by the core:
    the least-norm constant per-branch corrections that make every compartment's volume
    periodic (a linear solve on the loop's graph Laplacian, docs/oxygen.md).

    With ``arteries: "tree"`` (built-in ``closed-loop-o2-tree``) the arterial pool is a
    segment-resolved arterial tree (`tree`) whose O2 runs through the product's transport; its
    flow comes from the closed-loop heart run (always ``flows="heart"``): the tree is driven by
    the heart's aortic outflow and drains through the organ beds to the venous pressure of that
    run; the balance holds the tree's own flows as they are."""
    p = load(model) if isinstance(model, str) else model
    _check_times(p, max_cycles, tol)
    lay, _ = _layout(p)
    comps, branches = lay["compartments"], lay["branches"]
    idx = {c["name"]: i for i, c in enumerate(comps)}
    if shooting not in ("anderson", "newton"):
        raise ModelError(f"closed loop: shooting must be 'anderson' or 'newton', got {shooting!r}")
    spec: dict[str, Any] = {"compartments": comps, "branches": branches,
                            "binding": lay["binding"], "shooting": shooting}
    if _has_tree(p):
        if flows is not None and not (isinstance(flows, str) and flows == "heart"):
            raise ModelError("closed loop: with an arterial tree the flows come from the heart "
                             "run (flows='heart')")
        spec["tree"] = _tree_spec(p, idx)
        flows = "heart"
        # the tree's Hill inversions are warm-started (tolerance 1e-12 mmHg): its cycle map
        # repeats to ~1e-11, so the confirming cycles stop there (Fick then holds to ~2e-12)
        tol = max(tol, 1e-10)
    table, spec["balance"] = _flow_table(p, flows, branches)
    if table is None:   # the core runs the heart, then O2 on its flows: one call
        spec.update(heart=heart_spec(p), period=float(p["period"]))
    with core_errors("closed-loop O2 run"):
        out = _core.closed_loop_o2(json.dumps(spec),
                                   np.ascontiguousarray(table if table is not None
                                                        else np.empty(0)).ravel(),
                                   float(p["dt"]), int(max_cycles), float(tol))
    return _result(p, comps, branches, out, len(out["time"]))


def _check_times(p: dict[str, Any], max_cycles: Any, tol: Any) -> None:
    """The loop's period, step and cycle controls, each named when it is not a usable number
    (before: a period below the step read as "0 recorded intervals", a huge max_cycles as an
    OverflowError)."""
    def number(key: str, value: Any, low: float, high: float) -> float:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)) \
                or not low < float(value) < high:
            raise ModelError(f"closed loop: {key} must be a number in ({low:g}, {high:g}), got "
                             f"{value!r}")
        return float(value)

    period = number("period", p.get("period"), 0.0, math.inf)
    dt = number("dt", p.get("dt"), 0.0, math.inf)
    if dt > period:
        raise ModelError(f"closed loop: dt = {dt:g} s is longer than the period {period:g} s")
    if period / dt > _MOST_STEPS:
        raise ResourceError(f"closed loop: period {period:g} s / dt {dt:g} s = "
                            f"{period / dt:.3g} steps per cycle, more than the {_MOST_STEPS:.0e} "
                            "a run may plan; use a larger dt or a shorter period")
    if isinstance(max_cycles, (bool, np.bool_)) or not isinstance(max_cycles, (int, np.integer)) \
            or not 1 <= max_cycles <= _MOST_STEPS:
        raise ModelError(f"closed loop: max_cycles must be a whole number from 1 to "
                         f"{_MOST_STEPS:.0e}, got {max_cycles!r}")
    number("tol", tol, 0.0, 1.0)


#: Most steps per cycle (and cycles) a run may plan, as the core's run plan.
_MOST_STEPS = 10**9


def _result(p: dict[str, Any], comps: list[dict[str, Any]], branches: list[dict[str, Any]],
            out: dict[str, Any], steps: int) -> ClosedLoopO2Result:
    """The result of a core run's record (flat arrays reshaped)."""
    nc, nb = len(comps), len(branches)

    def rows(key: str, width: int, scale: float = 1.0) -> np.ndarray:
        return np.asarray(out[key]).reshape(steps, width) / scale

    tree = None
    if _has_tree(p):
        segs = list(out["tree_segments"])
        tree = ArterialTreeO2(
            outlets=list(p["organs"]), segments=segs,
            inflow=np.asarray(out["tree_inflow"]), outflow=rows("tree_outflow", len(p["organs"])),
            in_flux=np.asarray(out["tree_in_flux"]),
            out_flux=rows("tree_out_flux", len(p["organs"])),
            wall=np.asarray(out["tree_wall"]), amount=np.asarray(out["tree_amount"]),
            po2=rows("tree_po2", len(segs), MMHG),
            flow_periodic_error=float(out["tree_flow_periodic_error"]))
    return ClosedLoopO2Result(
        compartments=[c["name"] for c in comps], branches=[b["name"] for b in branches],
        time=np.asarray(out["time"]), flow=rows("flow", nb), volume=rows("volume", nc),
        total=rows("total", nc), po2=rows("po2", nc, MMHG), saturation=rows("saturation", nc),
        vo2=rows("vo2", nc), flux=rows("flux", nb), uptake=rows("uptake", nb),
        amount=np.asarray(out["amount"]), amount_start=float(out["amount_start"]),
        dt=float(p["dt"]), cycles=int(out["cycles"]), periodic_error=float(out["periodic_error"]),
        tree=tree, heart=HeartRun(np.asarray(out["heart_time"]),
                                  {k: np.asarray(v) for k, v in out["heart_series"].items()})
        if out["heart_series"] else None)
