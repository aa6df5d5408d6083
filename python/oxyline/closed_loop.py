"""Oxygen around a closed circulation (docs/oxygen.md "Oxygen around a closed
loop"): heart chambers, systemic arteries, organ beds consuming O2, systemic veins and the lungs
as well-mixed compartments joined by the circulation's flows. The physics (compartments,
Michaelis–Menten VO2, diffusion-limited lung exchange with Hill binding, the periodic steady
state) lives in the core (``oxyline_core::transport::closed_loop``); this module loads the
built-in parameter sets ``closed-loop-o2`` and ``closed-loop-o2-tree`` (the data file
``models_data/closed-loop-o2.yaml``), has the core convert
them to SI (``oxyline_core::transport::closed_loop_params``: compartments, branches, binding,
organ resistances, the prescribed flow table) and presents the result. The core builds the
circulation (``oxyline_core::transport::closed_loop_circulation``: the heart, the arterial pool
or tree, the organ beds, the veins), checks the run settings, runs the heart and the O2 loop
and summarises the recorded cycle in one call (``oxyline_core::transport::closed_loop_run``,
``closed_loop_summary``).

    from oxyline import closed_loop
    res = closed_loop.simulate_o2("closed-loop-o2")
    print(res.summary())     # SaO2, SvO2, PO2s, VO2 per organ, Fick and mass-balance residuals

The flows come from a closed-loop heart the core runs first (:func:`heart_model`): by default svZeroDSolver's
ClosedLoopHeartAndPulmonary block (`heart: "svzerod-block"`, docs/physics.md §1.10), or the
native two-ventricle heart (`heart: "two-ventricle"`), or a prescribed table (`flows:
"table"`: a pulsatile ejection of both ventricles, steady organ flows and venous return).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.catalogue import shipped_data
from oxyline.errors import ModelError, core_errors
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
SVZEROD_HEART: dict[str, float] = _DATA["svzerod_heart"]  # a set's default `heart_block`

STANDARD_TREE: dict[str, Any] = {**copy.deepcopy(STANDARD), "name": "closed-loop-o2-tree",
                                 "arteries": "tree", "tree": TREE}

BUILTINS = {"closed-loop-o2": STANDARD, "closed-loop-o2-tree": STANDARD_TREE}


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
        text, flows = _core.closed_loop_layout(json.dumps(_with_block(p)), table)
    return json.loads(text), flows


def flow_table(p: dict[str, Any]) -> np.ndarray:
    """Branch flows (m³/s) for each step of one cycle, branches in the order of
    ``result.branches`` (the core's): half-sine ejections of both ventricles (duration
    `ejection_time`), steady organ flows, venous return, pulmonary and filling flows. The
    ejection is scaled so that its discrete cycle mean equals the cardiac output exactly
    (periodic chamber volumes, which the core checks)."""
    return np.asarray(_layout(p, table=True)[1])


def _with_block(p: dict[str, Any]) -> dict[str, Any]:
    """The parameter set as the core reads it: its own heart block, else `SVZEROD_HEART`."""
    return p if "heart_block" in p else {**p, "heart_block": SVZEROD_HEART}


def heart_model(p: dict[str, Any]) -> dict[str, Any]:
    """The native closed-loop circulation (no boundary condition) whose flows drive the O2 loop,
    as the core builds it (``oxyline_core::transport::closed_loop_circulation``): the heart
    `p["heart"]` between the venous return (node ``venous_return``) and the aorta
    (``aorta_in``): svZeroDSolver's ClosedLoopHeartAndPulmonary block (``svzerod-block``,
    docs/physics.md §1.10, with `heart_block` or `SVZEROD_HEART` in mmHg and mL and half the
    `stressed_volume` added to each ventricle's start volume) or the native two-ventricle heart
    (``two-ventricle``, docs/physics.md §1.8: chambers, tanh valves, pulmonary arteries, lungs,
    pulmonary veins); the systemic arteries (a pool of 1.5 mL/mmHg, or the tree `p["tree"]`
    with ``arteries: "tree"``, each vessel cut into ceil(length / max_segment_length)
    segments), the organs as parallel resistances sharing the cardiac output by
    `flow_fraction` at a mean arterial pressure of 93 mmHg, and the systemic veins (100
    mL/mmHg); SI units. Measured: see docs/oxygen.md "Oxygen around a closed loop"."""
    with core_errors("closed-loop heart model"):
        return _core.closed_loop_heart_model(json.dumps(_with_block(p)))


def heart_run_options(p: dict[str, Any]) -> dict[str, Any]:
    """Run options of :func:`heart_model`'s model, as the core's loop runs it: svZeroDSolver's
    block needs an absolute Newton tolerance (its on/off valves, docs/physics.md §1.10); Pa,
    m³/s and m³ residuals here, 1e-10 is far below their discretisation error."""
    with core_errors("closed-loop heart model"):
        return _core.closed_loop_heart_run_options(json.dumps(p))


@dataclass
class HeartRun:
    """The last cycle of the closed-loop heart's run (``ClosedLoopO2Result.heart``): the
    recorded times (s, from 0) and, by name, what the O2 loop reads: the flows (m³/s)
    ``aortic`` (ejection through the aortic valve), ``aortic_outflow`` (into the arteries or
    the tree's root), ``tricuspid``, ``pulmonary`` (the right ventricle's ejection), ``lungs``,
    ``mitral``, every organ's, and the pressure ``veins`` (Pa) at the systemic veins' inlet;
    the run's ``cycles``, its last cycle-to-cycle change ``periodic_error`` and whether that
    met its periodicity tolerance (``periodic``; the run stops at its most cycles otherwise,
    with a :class:`~oxyline.errors.PeriodicityWarning`)."""

    time: np.ndarray
    series: dict[str, np.ndarray]
    cycles: int = 0
    periodic_error: float = 0.0
    periodic: bool = True


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
    #: the core's cycle-mean PO2 (mmHg) of every segment, by vessel (:meth:`po2_along`)
    along: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def po2_along(self, vessels: list[str] | None = None) -> dict[str, np.ndarray]:
        """Cycle-mean PO2 (mmHg) of every segment, per vessel (in flow order), as the core
        computed it; ``vessels`` selects some of them."""
        return {k: v.copy() for k, v in self.along.items() if vessels is None or k in vessels}


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

    #: the core's summary of the cycle (:meth:`summary`)
    summary_values: dict[str, Any] = field(default_factory=dict, repr=False)
    #: the core's flow-weighted cycle means (:meth:`flow_weighted`): per recorded variable
    #: (``volume``, ``total``, ``po2`` in mmHg, ``saturation``, ``vo2``), [branch, compartment]
    weighted: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def flow_weighted(self, var: np.ndarray | str, branch: str, compartment: str) -> float:
        """Cycle mean of a compartment variable weighted by the flow leaving it by `branch`, as
        the core computed it: `var` is one of this result's ``volume``, ``total``, ``po2``,
        ``saturation``, ``vo2`` arrays (or its name)."""
        name = var if isinstance(var, str) else next(
            (k for k in self.weighted if getattr(self, k) is var), None)
        if name not in self.weighted:
            raise ValueError(f"flow_weighted: var must be one of the result's "
                             f"{', '.join(self.weighted)} (or its name), got {var!r:.60}")
        table = self.weighted[name]
        return float(table[self.branches.index(branch), self.compartments.index(compartment)])

    def arterial_flow(self) -> np.ndarray:
        """The left heart's ejection per step (m³/s): into the tree's root or the pool."""
        if self.tree is not None:
            return self.tree.inflow
        return self.flow[:, self.branches.index("ejection_left")]

    def wall_uptake(self) -> np.ndarray:
        """The arterial tree's wall uptake per step (mol/s; zeros without a tree)."""
        return self.tree.wall if self.tree is not None else np.zeros(len(self.time))

    def summary(self) -> dict[str, Any]:
        """The core's summary of the cycle (``oxyline_core::transport::closed_loop_summary``):
        arterial (left-heart ejection) and mixed-venous (right-heart ejection) PO2 (mmHg),
        saturation and content (``CaO2``, ``CvO2``: mL O2 per L blood), flow-weighted over the
        cycle (into a tree the arterial content is the root's flux over its flow); VO2 per
        organ and in total (mL/min; the total includes the arterial tree's wall uptake,
        `VO2_tree_wall`); the lungs' uptake (mL/min); cardiac output (L/min); Fick's residual
        |VO2 − CO (CaO2 − CvO2)| / VO2 and the largest per-step mass-balance residual of the
        loop relative to its O2 amount; ``cycles``, ``periodic_error``; with a tree the O2
        each outlet delivers to its organ (``DO2_organs``, mL/min)."""
        return copy.deepcopy(self.summary_values)


def simulate_o2(model: str | dict[str, Any] = "closed-loop-o2", max_cycles: int = 400,
                tol: float = 1e-13, flows: np.ndarray | str | None = None,
                shooting: str = "anderson") -> ClosedLoopO2Result:
    """Runs O2 around the closed loop to its periodic steady state (the core's Anderson
    acceleration of the cycle map, or with ``shooting="newton"`` the earlier finite-difference
    Newton shooting; then plain cycles until the start-of-cycle contents repeat to `tol`).
    `flows`: ``"heart"`` takes them from a run of the model's closed-loop heart
    (:func:`heart_model`, 30 cycles; the native ``two-ventricle`` heart on to its periodic
    state: until the cycle-to-cycle change of its state is below 1e-10, at most 500 cycles or
    the set's ``heart_max_cycles``, else a :class:`~oxyline.errors.PeriodicityWarning` and
    ``result.heart.periodic`` False; the set's ``heart_values`` written over the heart's
    values; its last cycle read by unknown name: `heart`: svZeroDSolver's
    block by default; the core runs it, then the O2 loop, in one call; its last cycle is
    ``result.heart``), ``"table"`` is the prescribed table (:func:`flow_table`), None the
    model's own choice (`flows`); a table (steps × branches, m³/s, one row per step of `dt`,
    branches in the order of ``result.branches``), e.g. flows sampled from a flow run, is
    balanced first by the core: the least-norm constant per-branch corrections that make every
    compartment's volume periodic (a linear solve on the loop's graph Laplacian,
    docs/oxygen.md). The core checks the period, `dt`, `max_cycles`, `tol` and `shooting`
    (a ModelError naming the key and value).

    With ``arteries: "tree"`` (built-in ``closed-loop-o2-tree``) the arterial pool is a
    segment-resolved arterial tree (`tree`) whose O2 runs through the product's transport; its
    flow comes from the closed-loop heart run (always ``flows="heart"``): the tree is driven by
    the heart's aortic outflow and drains through the organ beds to the venous pressure of that
    run; the balance holds the tree's own flows as they are. Its confirming cycles stop at a
    tolerance of at least 1e-10 (its warm-started Hill inversions repeat to ~1e-11)."""
    p = _with_block(load(model) if isinstance(model, str) else model)
    with core_errors("closed-loop O2 run"):
        out = _core.closed_loop_run(p, flows, max_cycles, tol, shooting)
    return _result(p, out, len(out["time"]))


def _result(p: dict[str, Any], out: dict[str, Any], steps: int) -> ClosedLoopO2Result:
    """The result of a core run's record (flat arrays reshaped)."""
    comps, branches = list(out["compartments"]), list(out["branches"])

    def rows(key: str, width: int, scale: float = 1.0) -> np.ndarray:
        return np.asarray(out[key]).reshape(steps, width) / scale

    tree = None
    if out["tree_segments"]:
        segs = list(out["tree_segments"])
        tree = ArterialTreeO2(
            outlets=list(p["organs"]), segments=segs,
            inflow=np.asarray(out["tree_inflow"]), outflow=rows("tree_outflow", len(p["organs"])),
            in_flux=np.asarray(out["tree_in_flux"]),
            out_flux=rows("tree_out_flux", len(p["organs"])),
            wall=np.asarray(out["tree_wall"]), amount=np.asarray(out["tree_amount"]),
            po2=rows("tree_po2", len(segs), MMHG),
            flow_periodic_error=float(out["tree_flow_periodic_error"]),
            along=dict(out["tree_po2_along"]))
    nc, nb = len(comps), len(branches)
    return ClosedLoopO2Result(
        compartments=comps, branches=branches,
        time=np.asarray(out["time"]), flow=rows("flow", nb), volume=rows("volume", nc),
        total=rows("total", nc), po2=rows("po2", nc, MMHG),
        saturation=rows("saturation", nc), vo2=rows("vo2", nc), flux=rows("flux", nb),
        uptake=rows("uptake", nb), amount=np.asarray(out["amount"]),
        amount_start=float(out["amount_start"]), dt=float(p["dt"]), cycles=int(out["cycles"]),
        periodic_error=float(out["periodic_error"]), tree=tree,
        summary_values=out["summary"], weighted=dict(out["weighted"]),
        heart=HeartRun(np.asarray(out["heart_time"]),
                       {k: np.asarray(v) for k, v in out["heart_series"].items()},
                       int(out["heart_cycles"]), float(out["heart_periodic_error"]),
                       bool(out["heart_periodic"]))
        if out["heart_series"] else None)


def o2_sensitivities(model: str | dict[str, Any], parameters: list[str], outputs: list[str],
                     max_cycles: int = 400, tol: float = 1e-13,
                     flows: np.ndarray | str | None = None,
                     shooting: str = "anderson") -> dict[str, Any]:
    """The loop's outputs at its periodic state and their exact derivatives by parameters of
    the set, by the core (``oxyline_core::transport::closed_loop_sensitivity``: the tangent of
    every step, the implicit function theorem on the periodic fixed point; docs/calibration.md
    "A closed loop's oxygen"). `parameters`: ``organs.<organ>.vo2``, ``km``,
    ``lungs.diffusing_capacity``, ``lungs.alveolar_po2``, ``blood.p50``, ``blood.hemoglobin``
    and, with the prescribed
    flow table (``flows: table``), ``cardiac_output``; with the heart run's flows
    (``flows="heart"``) the heart model's parameters by their paths in :func:`heart_model`
    (``vessels.lv.chamber.max_elastance``, ``vessels.aortic_valve.valve.min_resistance``,
    ``vessels.lungs.lumped.resistance``, ``vessels.heart_pulmonary.heart_pulmonary.<key>``
    ...; their values are the set's ``heart_values`` where it gives them): the heart run's
    exact flow tangent at its periodic state, through its valves at their states in that
    run, into the loop's flow table (docs/calibration.md "A closed loop's oxygen");
    `outputs`: ``SaO2``, ``SvO2``, ``PaO2``, ``PvO2``, ``VO2``, ``VO2.<organ>``,
    ``cardiac_output``. SI throughout: a dict of ``parameter_values``, ``values``,
    ``jacobian`` (outputs × parameters), ``cycles``, ``periodic_error``, ``heart_cycles`` and
    ``heart_periodic``; a ModelError names an unknown parameter (with the nearest key of the
    heart model) or output."""
    p = _with_block(load(model) if isinstance(model, str) else model)
    with core_errors("closed-loop sensitivities"):
        return _core.closed_loop_sensitivities(p, flows, max_cycles, tol, shooting,
                                               list(parameters), list(outputs))
