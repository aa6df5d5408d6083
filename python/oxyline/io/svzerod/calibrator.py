"""svZeroDSolver's calibrator as a drop-in: :func:`calibrate` reads an svZeroDCalibrator
configuration (the model's ``vessels`` and ``junctions``, the observations ``y`` and ``dy``
of every connection's pressure and flow, and ``calibration_parameters``) and returns the
calibrated configuration ``svzerod.calibrate`` returns.

The element values α (each BloodVessel's R, C, L and stenosis coefficient, each junction
outlet's R, L and stenosis coefficient) are fitted by least squares on the DAE residual
E(α) ẏ + F(α) y + c(α, y) at the observed states: no forward simulation. The residual and
its derivatives come from the core (:class:`oxyline._core.CalibrationProblem`); this module
reads and writes the JSON; the core also runs svZeroDSolver's own Levenberg–Marquardt
iteration (``CalibrationProblem.fit``: the damping scaled by the ratio of successive gradient
norms, every step taken, a stop when both the gradient and the step are below their
tolerances or after ``maximum_iterations``).
The same iteration, not another optimiser, because the calibrator's files stop it early
(``maximum_iterations: 20`` in the VMR cases): the answer to reproduce is that iterate, not
the least-squares minimum. Values are fitted in the file's units, as svZeroDSolver does (the
weighting of pressure rows against flow rows depends on them).

Two selections of the fitted values:

* without ``calibrate`` lists (the calibrator's classic input): every R, C and L, and the
  stenosis coefficients unless ``calibrate_stenosis_coefficient`` is false (they are then 0);
  the written C and L are clipped at 0 (R and the stenosis coefficient keep their sign), and
  ``set_capacitance_to_zero`` writes C = 0;
* with a ``calibrate`` list on a vessel or junction, or in ``calibration_parameters`` for the
  blocks without one (svZeroDSolver 3.2's input): only the listed values; the others keep
  their input values, and every value is written as fitted.
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import ModelError

__all__ = ["calibrate"]

log = logging.getLogger(__name__)

#: the fitted values of a BloodVessel and of one junction outlet, in the core's slot order
VESSEL_VALUES = ("R_poiseuille", "C", "L", "stenosis_coefficient")
BRANCH_VALUES = ("R_poiseuille", "L", "stenosis_coefficient")

#: calibration_parameters and their defaults (svZeroDSolver's)
SETTINGS = {"tolerance_gradient": 1e-5, "tolerance_increment": 1e-10,
            "maximum_iterations": 100, "calibrate_stenosis_coefficient": True,
            "set_capacitance_to_zero": False, "initial_damping_factor": 1.0}


@dataclass
class _Problem:
    """The blocks as the core takes them, the start values and which of them are fitted."""

    vessels: list[tuple[str, tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)
    branches: list[tuple[str, tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)
    #: name of each observed variable, in the core's variable order
    variables: list[str] = field(default_factory=list)
    start: list[float] = field(default_factory=list)
    active: list[bool] = field(default_factory=list)
    #: junction name -> its branches' slots (R, L, S) by outlet
    junction_slots: dict[str, list[tuple[int, ...]]] = field(default_factory=dict)

    #: variable name -> its index
    index: dict[str, int] = field(default_factory=dict)

    def variable(self, name: str) -> int:
        """The index of observed variable `name` (registered on first use)."""
        if name not in self.index:
            self.index[name] = len(self.variables)
            self.variables.append(name)
        return self.index[name]

    def slots(self, values: Mapping[str, Any], names: tuple[str, ...], fitted: set[str],
              where: str) -> tuple[int, ...]:
        out = []
        for name in names:
            value = values.get(name, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value):
                raise ModelError(f"{where}: '{name}' must be a finite number, got {value!r}")
            out.append(len(self.start))
            self.start.append(float(value))
            self.active.append(name in fitted)
        return tuple(out)


def _fitted(block: Mapping[str, Any], names: tuple[str, ...], settings: Mapping[str, Any],
            where: str) -> set[str]:
    """The names of `block`'s values to fit (see the module docstring)."""
    if not settings["lists"]:
        every = set(names)
        return every if settings["calibrate_stenosis_coefficient"] else every - {
            "stenosis_coefficient"}
    if "calibrate" not in block:  # the global list, as far as this block has those values
        return {n for n in settings.get("calibrate", []) if n in names}
    chosen = block["calibrate"]
    if not isinstance(chosen, list) or not all(isinstance(c, str) for c in chosen):
        raise ModelError(f"{where}: 'calibrate' must be a list of value names, got {chosen!r}")
    unknown = sorted(set(chosen) - set(names))
    if unknown:
        raise ModelError(f"{where}: cannot calibrate {unknown}; its values are {list(names)}")
    return set(chosen)


def _settings(cfg: Mapping[str, Any]) -> dict[str, Any]:
    given = cfg.get("calibration_parameters", {})
    if not isinstance(given, Mapping):
        raise ModelError("calibration_parameters must be an object")
    unknown = sorted(set(given) - set(SETTINGS) - {"calibrate"})
    if unknown:
        raise ModelError(f"calibration_parameters: unknown key(s) {unknown}; known: "
                         f"{sorted(SETTINGS)}")
    out = {**SETTINGS, **given}
    if "calibrate" in given:
        chosen = given["calibrate"]
        known = set(VESSEL_VALUES) | set(BRANCH_VALUES)
        if not isinstance(chosen, list) or not all(isinstance(c, str) for c in chosen) \
                or not set(chosen) <= known:
            raise ModelError(f"calibration_parameters: 'calibrate' must be a list of value "
                             f"names ({sorted(known)}), got {chosen!r}")
    blocks = [*cfg.get("vessels", []), *cfg.get("junctions", [])]
    out["lists"] = "calibrate" in given or any(
        isinstance(b, Mapping) and "calibrate" in b for b in blocks)
    for key in ("tolerance_gradient", "tolerance_increment", "initial_damping_factor"):
        v = out[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0 \
                or not math.isfinite(v):
            raise ModelError(f"calibration_parameters: '{key}' must be a finite number >= 0, "
                             f"got {v!r}")
    if isinstance(out["maximum_iterations"], bool) or not isinstance(
            out["maximum_iterations"], int) or out["maximum_iterations"] < 1:
        raise ModelError("calibration_parameters: 'maximum_iterations' must be an integer "
                         f">= 1, got {out['maximum_iterations']!r}")
    return out


def _ends(cfg: Mapping[str, Any]) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """Each block's inlet and outlet connection names, as svZeroDSolver names its nodes
    (``<upstream block>:<downstream block>``, a boundary condition's name standing for the
    block at a free end)."""
    inlets: dict[str, list[str]] = {}
    outlets: dict[str, list[str]] = {}
    by_id: dict[Any, str] = {}
    for v in cfg["vessels"]:
        name = v["vessel_name"]
        by_id[v["vessel_id"]] = name
        bcs = v.get("boundary_conditions", {})
        if "inlet" in bcs:
            inlets.setdefault(name, []).append(f"{bcs['inlet']}:{name}")
        if "outlet" in bcs:
            outlets.setdefault(name, []).append(f"{name}:{bcs['outlet']}")
    for j in cfg.get("junctions", []):
        name = j["junction_name"]
        for side, key in ((inlets, "inlet_vessels"), (outlets, "outlet_vessels")):
            if key not in j:
                raise ModelError(f"junction '{name}': no '{key}' (the calibrator connects "
                                 "junctions by vessel ids)")
            for vid in j[key]:
                if vid not in by_id:
                    raise ModelError(f"junction '{name}': {key} names vessel id {vid!r}, "
                                     "which no vessel has")
                vessel = by_id[vid]
                if side is inlets:  # the vessel flows into the junction
                    node = f"{vessel}:{name}"
                    outlets.setdefault(vessel, []).append(node)
                else:
                    node = f"{name}:{vessel}"
                    inlets.setdefault(vessel, []).append(node)
                side.setdefault(name, []).append(node)
    return inlets, outlets


def _read_blocks(cfg: Mapping[str, Any], settings: Mapping[str, Any]) -> _Problem:
    """The vessels and junction branches of `cfg` with their variables and value slots."""
    for key in ("vessels", "y", "dy"):
        if key not in cfg:
            raise ModelError(f"svZeroDCalibrator input: no '{key}'")
    for key in ("vessels", "junctions"):
        seq = cfg.get(key, [])
        if not isinstance(seq, list) or not all(isinstance(b, Mapping) for b in seq):
            raise ModelError(f"svZeroDCalibrator input: '{key}' must be a list of objects")
    lists = settings["lists"]
    stenosis = settings["calibrate_stenosis_coefficient"]
    inlets, outlets = _ends(cfg)
    pb = _Problem()
    for v in cfg["vessels"]:
        name = v["vessel_name"]
        where = f"vessel '{name}'"
        if v.get("zero_d_element_type") != "BloodVessel":
            raise ModelError(f"{where}: the calibrator fits BloodVessel blocks, not "
                             f"{v.get('zero_d_element_type')!r}")
        ins, outs = inlets.get(name, []), outlets.get(name, [])
        if len(ins) != 1 or len(outs) != 1:
            raise ModelError(f"{where}: needs one inlet and one outlet connection, has "
                             f"{len(ins)} and {len(outs)}")
        nodes = (f"pressure:{ins[0]}", f"flow:{ins[0]}", f"pressure:{outs[0]}", f"flow:{outs[0]}")
        fitted = _fitted(v, VESSEL_VALUES, settings, where)
        values = dict(v.get("zero_d_element_values", {}))
        if not lists and not stenosis:
            values["stenosis_coefficient"] = 0.0  # not a value of the fit: no stenosis
        slots = pb.slots(values, VESSEL_VALUES, fitted, where)
        pb.vessels.append((name, tuple(pb.variable(n) for n in nodes), slots))
    for j in cfg.get("junctions", []):
        name = j["junction_name"]
        outs = outlets.get(name, [])
        if len(outs) < 2:
            continue  # one outlet: a plain junction, no values
        where = f"junction '{name}'"
        ins = inlets.get(name, [])
        if len(ins) != 1:
            raise ModelError(f"{where}: a junction with {len(outs)} outlets is fitted as a "
                             f"BloodVesselJunction, which has one inlet, not {len(ins)}")
        fitted = _fitted(j, BRANCH_VALUES, settings, where)
        given = j.get("junction_values", {})
        pb.junction_slots[name] = []
        for i, out in enumerate(outs):
            values = {}
            for key in BRANCH_VALUES:
                seq = given.get(key)
                values[key] = seq[i] if isinstance(seq, list) and i < len(seq) else 0.0
            if not lists and not stenosis:
                values["stenosis_coefficient"] = 0.0
            slots = pb.slots(values, BRANCH_VALUES, fitted, f"{where} outlet {i}")
            nodes = (f"pressure:{ins[0]}", f"pressure:{out}", f"flow:{out}")
            pb.branches.append((f"{name}:{out.split(':', 1)[1]}",
                                tuple(pb.variable(n) for n in nodes), slots))
            pb.junction_slots[name].append(slots)
    if not any(pb.active):
        raise ModelError("svZeroDCalibrator input: no value is selected for calibration "
                         "(add a 'calibrate' list to a vessel or junction)")
    return pb


def _observations(cfg: Mapping[str, Any], variables: list[str]) -> tuple[np.ndarray, ...]:
    """``y`` and ``dy`` of `variables` as (n_var × n_obs) arrays, checked."""
    rows: dict[str, list[np.ndarray]] = {"y": [], "dy": []}
    for key in ("y", "dy"):
        table = cfg[key]
        if not isinstance(table, Mapping):
            raise ModelError(f"svZeroDCalibrator input: '{key}' must map variable names to "
                             "lists of values")
        for name in variables:
            if name not in table:
                raise ModelError(f"{key}: no observations of '{name}'")
            try:
                a = np.asarray(table[name], dtype=np.float64)
            except (TypeError, ValueError) as e:
                raise ModelError(f"{key}['{name}']: not a list of numbers ({e})") from None
            if a.ndim != 1:
                raise ModelError(f"{key}['{name}']: not a list of numbers")
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise ModelError(f"{key}['{name}'][{bad[0]}] is not finite ({a[bad[0]]})")
            rows[key].append(a)
    n_obs = {len(a) for a in rows["y"] + rows["dy"]}
    if len(n_obs) != 1 or 0 in n_obs:
        lengths = {name: len(a) for name, a in zip(variables, rows["y"])}
        raise ModelError(f"y and dy: every variable needs the same number (> 0) of "
                         f"observations, got {sorted(n_obs)} (y lengths {lengths})")
    return np.stack(rows["y"]), np.stack(rows["dy"])


def _fit(problem: Any, pb: _Problem, settings: Mapping[str, Any]) -> np.ndarray:
    """svZeroDSolver's Levenberg–Marquardt iteration from the start values, run by the core
    (``oxyline_core::calibration::fit``)."""
    alpha, iterations, converged = problem.fit(
        np.asarray(pb.start, dtype=np.float64), [bool(a) for a in pb.active],
        settings["maximum_iterations"], float(settings["initial_damping_factor"]),
        float(settings["tolerance_gradient"]), float(settings["tolerance_increment"]))
    log.debug("svZeroD calibration: %d iterations", iterations)
    if not converged:
        log.info("svZeroD calibration: maximum_iterations (%d) reached",
                 settings["maximum_iterations"])
    return alpha


def _write(cfg: Mapping[str, Any], pb: _Problem, alpha: np.ndarray,
           settings: Mapping[str, Any]) -> dict[str, Any]:
    """`cfg` with the fitted values, without the calibrator's keys."""
    out = {k: copy.deepcopy(v) for k, v in cfg.items()
           if k not in ("y", "dy", "calibration_parameters")}
    lists = settings["lists"]
    zero_c = not lists and settings["set_capacitance_to_zero"]
    clip = (lambda x: max(float(x), 0.0)) if not lists else float
    for v, (_, _, slots) in zip(out["vessels"], pb.vessels):
        r, c, ind, s = (float(alpha[i]) for i in slots)
        v["zero_d_element_values"] = {"C": 0.0 if zero_c else clip(c), "L": clip(ind),
                                      "R_poiseuille": r, "stenosis_coefficient": s}
    for j in out.get("junctions", []):
        slots = pb.junction_slots.get(j["junction_name"])
        if slots is None:
            continue
        j["junction_type"] = "BloodVesselJunction"
        j["junction_values"] = {
            "L": [clip(alpha[s[1]]) for s in slots],
            "R_poiseuille": [float(alpha[s[0]]) for s in slots],
            "stenosis_coefficient": [float(alpha[s[2]]) for s in slots]}
    return out


def calibrate(config: Mapping[str, Any]) -> dict[str, Any]:
    """Calibrate an svZeroDCalibrator configuration, as ``svzerod.calibrate(config)``.

    ``config`` holds the model (``vessels``, ``junctions``, and whatever else the file has,
    returned unchanged), ``y`` and ``dy`` (each connection's ``pressure:<up>:<down>`` and
    ``flow:<up>:<down>`` observations, one list per variable, the same length for all) and
    ``calibration_parameters`` (``tolerance_gradient``, ``tolerance_increment``,
    ``maximum_iterations``, ``initial_damping_factor``, ``calibrate_stenosis_coefficient``,
    ``set_capacitance_to_zero``). Returns the configuration with the fitted vessel and junction
    values (junctions with several outlets become ``BloodVesselJunction``) and without ``y``,
    ``dy`` and ``calibration_parameters``. Raises :class:`~oxyline.errors.ModelError` naming
    the block or key of a bad input, :class:`~oxyline.errors.SolverError` if a step is
    singular.
    """
    if not isinstance(config, Mapping):
        raise ModelError(f"svZeroDCalibrator input must be a JSON object, got "
                         f"{type(config).__name__}")
    settings = _settings(config)
    try:
        pb = _read_blocks(config, settings)
    except KeyError as e:
        raise ModelError(f"svZeroDCalibrator input: a vessel or junction has no {e}") from None
    y, dy = _observations(config, pb.variables)
    problem = _core.CalibrationProblem(pb.vessels, pb.branches, np.ascontiguousarray(y).ravel(),
                                       np.ascontiguousarray(dy).ravel(), y.shape[1])
    alpha = _fit(problem, pb, settings)
    return _write(config, pb, alpha, settings)
