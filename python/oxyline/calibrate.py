"""Exact parameter sensitivities of a model's periodic state, and calibration to targets.

:func:`sensitivities` asks the core for the tangent-linear generalized-α run to the periodic
state (one extra solve per parameter and step on the run's own factorisation) and reduces
the signals to the named outputs of :mod:`oxyline.targets`. :func:`calibrate` fits
parameters to targets with ``scipy.optimize.least_squares`` on that Jacobian, each parameter
as the logarithm of its factor over the start (so positive parameters stay positive and
their steps are relative), and returns the calibrated native model dict with the
Gauss–Newton covariance and a convergence report. Parameters are named by the ensemble patch
paths (docs/calibration.md).
"""

from __future__ import annotations

import contextlib
import copy
import json
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oxyline import _core, closed_loop, memory
from oxyline.description import copy_description
from oxyline.errors import ModelError, ResourceError, core_errors
from oxyline.io import dump_native
from oxyline.loader import load_model
from oxyline.model import Model, build_model
from oxyline.targets import (
    CalibrationError,
    Target,
    _finite,
    _sigma,
    parse_targets,
    signals_for,
)

__all__ = ["CalibrationError", "CalibrationResult", "Sensitivities", "calibrate",
           "sensitivities"]

#: two-sided 95 % quantile of the normal distribution (the intervals of the report)
Z95 = 1.959963984540054


@dataclass
class Sensitivities:
    """The outputs of a model's periodic cycle and their derivatives: ``jacobian[i, j]`` is
    d ``values[i]`` / d parameter j, both in SI (a scale factor is dimensionless)."""

    outputs: list[str]
    parameters: list[str]
    #: the parameters' values (SI; 1 for a scale)
    parameter_values: np.ndarray
    values: np.ndarray
    jacobian: np.ndarray
    #: cycles run to the periodic state and the last cycle's relative change
    cycles: int
    periodic_change: float
    #: rows of ``values`` per output (a series has one per time)
    rows: dict[str, slice] = field(default_factory=dict)
    #: cycles of the tangents alone, after the forward run, to their periodic state
    tangent_cycles: int = 0


#: Most steps per cycle or cycles a tangent run may plan (as many as a run: `simulate`'s plan).
_MOST = 10**9


def _count(name: str, value: Any) -> int:
    """A whole number from 1 to ``_MOST`` (a bool, 2.5, 0 or 1e12 is refused, naming it)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer, float)) \
            or not float(value).is_integer() or not 1 <= value <= _MOST:
        raise CalibrationError(f"{name}: expected a whole number from 1 to {_MOST:.0e}, "
                               f"got {value!r}")
    return int(value)


def _fraction(name: str, value: Any) -> None:
    """A number in (0, 1) (a tolerance), else an error naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) \
            or not 0.0 < float(value) < 1.0:
        raise CalibrationError(f"{name}: expected a number in (0, 1), got {value!r}")


def _run_args(model: Model, parameters: Sequence[str], signals: Sequence[Any],
              steps_per_cycle: int | None, tol: Any, max_cycles: Any
              ) -> tuple[float, int, float, int, float]:
    """(period, steps, rho_infty, max_cycles, tol) of a tangent or adjoint run of ``model``,
    its controls checked, and its stored derivatives against the memory allowed."""
    period = model.period
    if period is None:
        raise CalibrationError(f"model '{model.name}': sensitivities need a periodic model "
                               "(a period or periodic waveforms)")
    # the model's dt and rho_infty with the core's defaults (the run's own settings)
    s = _core.resolve_settings(model.simulation, {}, period)
    if steps_per_cycle is None:  # a fixed dt's steps, else ("auto"): 400 steps a cycle
        steps_per_cycle = round(period / s["dt"]) if s["dt"] is not None else 400
    steps = _count("steps_per_cycle", steps_per_cycle)
    _fraction("tol", tol)
    _count("max_cycles", max_cycles)
    need = 8.0 * steps * max(len(signals), 1) * (len(parameters) + 1)
    limit = memory.limit(None, "sensitivities: max_memory")
    if limit is not None and need > limit:
        raise ResourceError(
            f"steps_per_cycle = {steps}: the derivatives of {len(signals)} signal(s) by "
            f"{len(parameters)} parameter(s) at every step need about {memory.human(need)} "
            f"(estimate), above the {memory.human(limit)} allowed; use fewer steps_per_cycle")
    return float(period), steps, float(s["rho_infty"]), max_cycles, tol


def _reads(targets: Sequence[Target], series_at_steps: bool
           ) -> tuple[list[tuple[str, str]], list[tuple[str, list[int], Any]]]:
    """The signals a run records (each once) and each target as the core reads it: its
    output, its signals' columns and a series' times (None: the cycle's steps, as
    :func:`sensitivities` reads a series; else its data's times, as :func:`calibrate`)."""
    signals = sorted({s for t in targets for s in t.signals})
    return signals, [(t.output, [signals.index(s) for s in t.signals],
                      None if series_at_steps or t.times is None
                      else np.asarray(t.times, dtype=float).tolist())
                     for t in targets]


def _evaluate(model: Model, parameters: Sequence[str], targets: Sequence[Target],
              steps_per_cycle: int | None, tol: float, max_cycles: int,
              series_at_steps: bool = False
              ) -> tuple[list[np.ndarray], list[np.ndarray], dict[str, Any]]:
    """Every target's value(s) and Jacobian rows (d/d SI parameter) at ``model`` by the
    tangents, reduced by the core (:func:`oxyline._core.target_tangents`,
    ``oxyline_core::sensitivity::target_runs``); ``series_at_steps`` as :func:`_reads`."""
    signals, reads = _reads(targets, series_at_steps)
    args = _run_args(model, parameters, signals, steps_per_cycle, tol, max_cycles)
    with core_errors(f"model '{model.name}'"):  # flow and oxygen signals alike
        raw = _core.target_tangents(json.dumps(model.canonical), list(parameters), signals,
                                    reads, *args)
    values = [v for v, _ in raw["outputs"]]
    jac = [j.reshape(len(v), len(parameters)) for v, j in raw["outputs"]]
    return values, jac, raw


def _adjoint(m: Model, parameters: Sequence[str], targets: Sequence[Target],
             steps_per_cycle: int | None, tol: float, max_cycles: int, series_at_steps: bool
             ) -> tuple[list[np.ndarray], list[np.ndarray], dict[str, Any]]:
    """The outputs and their Jacobian rows by the core's adjoint, in one primal run: the core
    builds each output's weights on the periodic cycle's signals (its derivative is a fixed
    linear functional of theirs) and runs one backward sweep per output row
    (:func:`oxyline._core.target_gradients`, ``oxyline_core::sensitivity::target_runs``);
    ``series_at_steps`` as :func:`_reads`."""
    signals, reads = _reads(targets, series_at_steps)
    args = _run_args(m, [], signals, steps_per_cycle, tol, max_cycles)
    with core_errors(f"model '{m.name}'"):  # flow and oxygen signals alike
        out = _core.target_gradients(json.dumps(m.canonical), list(parameters), signals,
                                     reads, *args)
    values = list(out["outputs"])
    ends = np.cumsum([len(v) for v in values])
    jac = [out["gradients"][e - len(v):e] for v, e in zip(values, ends, strict=True)]
    raw = {"values": out["values"], "cycles": out["cycles"],
           "tangent_cycles": max(out["adjoint_cycles"], default=0),
           "periodic_change": float(out["periodic_change"])}
    return values, jac, raw


def sensitivities(model: Model | Mapping[str, Any] | str, parameters: Sequence[str],
                  outputs: Sequence[str], *, steps_per_cycle: int | None = None,
                  tol: float = 1e-12, max_cycles: int = 2000,
                  mode: str = "forward") -> Sensitivities:
    """The Jacobian of ``outputs`` (names, :mod:`oxyline.targets`) with respect to
    ``parameters`` (patch paths) at the periodic state of ``model``, exact for the
    generalized-α discretisation (the model's ``dt``, or 400 steps a cycle). A ``series``
    output has one row per step of the cycle.

    Oxygen outputs (``SvO2.<vessel>``, ``VO2``, ``<vessel>.po2_out.<statistic>``, …) are
    differentiated by oxygen parameters (``oxygen.wall.k``, ``oxygen.hill.p50``, …) through
    the species transport's tangent (docs/calibration.md, "Oxygen"), and by flow parameters
    through the flow's tangent; oxygen parameters leave flow outputs unchanged (zero rows).
    With ``mode="adjoint"`` oxygen outputs take oxygen and flow parameters alike (the flow's
    tangent by each flow parameter forward, the species transport's adjoint backward: one
    sweep per output row); flow outputs beside them take the flow parameters' tangents.

    ``mode="forward"``: tangents, one per parameter (few parameters); ``"adjoint"``: one
    backward sweep per output row, whatever the number of parameters (many parameters, few
    outputs). Both give the same Jacobian (to the periodic tolerance); ``tangent_cycles``
    counts the tangent cycles, or the most backward cycles of an output.

    >>> s = sensitivities("bifurcation", ["scale.resistance"], ["parent.pressure_in.mean"])
    >>> bool(s.jacobian[0, 0] > 0)
    True
    """
    if isinstance(outputs, str) or isinstance(parameters, str):
        raise CalibrationError("parameters and outputs: expected lists of names")
    if _is_loop(model):
        return _loop_sensitivities(model, parameters, outputs, tol, max_cycles)
    m = load_model(model)
    if mode not in ("forward", "adjoint"):
        raise CalibrationError(f"mode: expected 'forward' or 'adjoint', got {mode!r}")
    targets = [Target(o, None, signals=s)
               for o, s in zip(outputs, signals_for(outputs, m), strict=True)]
    run = _adjoint if mode == "adjoint" else _evaluate
    values, jac, raw = run(m, parameters, targets, steps_per_cycle, tol, max_cycles,
                           series_at_steps=True)
    ends = np.cumsum([len(v) for v in values]).tolist()
    rows = {t.output: slice(e - len(v), e) for t, v, e in zip(targets, values, ends, strict=True)}
    return Sensitivities(list(outputs), list(parameters), np.asarray(raw["values"]),
                         np.concatenate(values), np.concatenate(jac), int(raw["cycles"]),
                         float(raw["periodic_change"]), rows, int(raw["tangent_cycles"]))


# ---- the native model at a parameter point --------------------------------------------------

@contextlib.contextmanager
def _parameter_errors() -> Iterator[None]:
    """A parameter path the core cannot resolve or set, as :class:`CalibrationError`."""
    try:
        yield
    except ModelError as e:
        raise CalibrationError(str(e)) from None


def _base_value(source: Mapping[str, Any], path: str) -> float:
    """The number ``path`` names in the native dict (in its own units; 1 for a scale): the
    core's reading (``oxyline_core::model::parameters``)."""
    with _parameter_errors():
        return float(_core.parameter_value(source, path))


def native_model(source: Mapping[str, Any], parameters: Sequence[str],
                 values: Sequence[float]) -> dict[str, Any]:
    """The native model dict ``source`` with each parameter set to its value (native units;
    a scale to its factor), set by the core (``oxyline_core::model::parameters``:
    ``scale.inflow`` scales the flow waveforms, an intramyocardial pressure's ``scale`` its
    waveform, a heart element's value is set where the element holds it, every other path as
    an ensemble patch's)."""
    with _parameter_errors():
        data = _core.set_parameters(dict(source), list(parameters),
                                    [float(x) for x in values])
    return copy_description(data)


# ---- calibration ----------------------------------------------------------------------------

@dataclass
class CalibrationResult:
    """A fit: the calibrated native ``model`` dict (loads and runs), the parameters' values
    (native units), the weighted residuals (r = (output − target)/sigma), the Gauss–Newton
    covariance of the log factors and the report of the optimiser."""

    model: dict[str, Any]
    parameters: dict[str, float]
    start: dict[str, float]
    residuals: np.ndarray
    cost: float
    #: covariance of log(parameter) (the fit's variables): (JᵀJ)⁻¹ with J of the weighted
    #: residuals, so the sigmas are read as the data's standard deviations
    covariance: np.ndarray
    #: 95 % intervals of each parameter (native units, from the log-normal approximation)
    intervals: dict[str, tuple[float, float]]
    success: bool
    report: dict[str, Any]
    #: ``method="bayes"``: posterior samples of the parameters (native units), one row each
    samples: np.ndarray | None = None


def _bounds(parameters: Sequence[str], start: np.ndarray, bounds: Any
            ) -> tuple[np.ndarray, np.ndarray]:
    lo = np.full(len(parameters), -np.inf)
    hi = np.full(len(parameters), np.inf)
    if bounds is None:
        return lo, hi
    if not isinstance(bounds, Mapping):
        raise CalibrationError("bounds: expected a mapping {parameter: (low, high)}")
    for path, b in bounds.items():
        if path not in parameters:
            raise CalibrationError(f"bounds: {path!r} is not one of the parameters")
        k = list(parameters).index(path)
        try:
            a, c = (float(x) for x in b)
        except (TypeError, ValueError):
            raise CalibrationError(f"bounds of '{path}': expected (low, high), got {b!r}"
                                   ) from None
        if not (0 < a < c) or np.isnan(c):
            raise CalibrationError(f"bounds of '{path}': need 0 < low < high, got {b!r}")
        if not a <= start[k] <= c:
            raise CalibrationError(f"bounds of '{path}': ({a:g}, {c:g}) exclude the start "
                                   f"{start[k]:g}")
        lo[k], hi[k] = np.log(a / start[k]), np.log(c / start[k])
    return lo, hi


class _Stop(Exception):
    """An evaluation failed at a trial point: the fit stops at the best point so far."""


@dataclass
class Derived:
    """Quantities fitted in place of the targets' own outputs (e.g. a population's
    characteristics made of pressures and pulse-wave velocities): ``of(values)`` gives them
    and their derivatives by the outputs (m × n_outputs) from the outputs' values (SI, the
    targets' order), compared with ``data`` weighed by ``1/sigma``."""

    of: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    data: np.ndarray
    sigma: np.ndarray


class _Problem:
    """The weighted residuals and their Jacobian in the log factors, cached per point (scipy
    asks for them separately) and the best point reached. A fit variable is a path, or a
    group's name: one factor on every path of the group (their ratios kept). ``derived``:
    quantities of the outputs fitted in their place; ``prior``: the SD of a Gaussian prior
    on every log factor around the start (one more residual each, θ/prior)."""

    def __init__(self, source: dict[str, Any], parameters: list[str], start: np.ndarray,
                 targets: list[Target], options: dict[str, Any], exact: bool = True,
                 groups: Mapping[str, Sequence[str]] | None = None,
                 gradient: str = "forward", derived: Derived | None = None,
                 prior: float | None = None) -> None:
        self.source, self.parameters, self.start = source, parameters, start
        self.exact, self.gradient = exact, gradient
        self.targets, self.options = targets, options
        self.derived, self.prior = derived, prior
        groups = groups or {}
        # the model's paths the variables move, and which variable moves each
        self.paths = [p for p in parameters if p not in groups] + \
            [q for g in parameters if g in groups for q in groups[g]]
        self.members = np.zeros((len(self.paths), len(parameters)))
        for k, name in enumerate(parameters):
            for q in groups.get(name, [name]):
                self.members[self.paths.index(q), k] = 1.0
        self.path_start = np.array([_base_value(source, q) for q in self.paths])
        if derived is None:
            self.data = np.concatenate([t.value for t in targets])
            self.sigma = np.concatenate([t.sigma for t in targets])
        else:
            self.data, self.sigma = derived.data, derived.sigma
        #: (point, residuals, their Jacobian, the fitted quantities' values)
        self.cache: tuple[bytes, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.best: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.error: str | None = None
        self.evaluations = 0
        #: the fit's end point (θ), once :func:`_least_squares` has one
        self.end: np.ndarray | None = None

    def values(self, theta: np.ndarray) -> np.ndarray:
        return self.start * np.exp(theta)

    def model(self, theta: np.ndarray) -> dict[str, Any]:
        return native_model(self.source, self.paths,
                            self.path_start * np.exp(self.members @ theta))

    def _at(self, theta: np.ndarray) -> Any:
        """What :meth:`_outputs` evaluates: the model at ``theta``."""
        return build_model(self.model(theta))

    def _outputs(self, m: Model) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
        """The targets' values and their Jacobian by the model's paths (SI) at ``m``."""
        run = _adjoint if self.exact and self.gradient == "adjoint" else _evaluate
        # without the exact Jacobian the core runs the primal only
        v, j, raw = run(m, self.paths if self.exact else [], self.targets,
                        series_at_steps=False, **self.options)
        return np.concatenate(v), np.concatenate(j), raw

    def _eval(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = theta.tobytes()
        if self.cache is None or self.cache[0] != key:
            try:
                v, j_si, raw = self._outputs(self._at(theta))
            except Exception as e:
                self.error = f"{type(e).__name__}: {e}"
                raise _Stop from e
            self.evaluations += 1
            if self.derived is not None:  # the chain rule through the derived quantities
                v, dv = self.derived.of(v)
                j_si = dv @ j_si
            r = (v - self.data) / self.sigma
            # d r / d log(p) = d r / d p · p (p in SI: the core's values), then by variable
            j = (j_si * np.asarray(raw["values"])[None, :] / self.sigma[:, None]) \
                @ self.members if self.exact else np.zeros((len(r), 0))
            if self.prior is not None:
                r = np.concatenate([r, theta / self.prior])
                j = np.vstack([j, np.eye(len(theta)) / self.prior]) if self.exact else \
                    np.zeros((len(r), 0))
            self.cache = (key, r, j, v)
            cost = 0.5 * float(r @ r)
            if self.best is None or cost < self.best[0]:
                self.best = (cost, theta.copy(), r, j)
        return self.cache[1], self.cache[2]

    def fitted(self, theta: np.ndarray) -> np.ndarray:
        """The fitted quantities' values at ``theta`` (the targets' outputs, or the derived
        quantities)."""
        self._eval(theta)
        assert self.cache is not None
        return self.cache[3]

    def fun(self, theta: np.ndarray) -> np.ndarray:
        return self._eval(theta)[0]

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self._eval(theta)[1]


def calibrate(model: Model | Mapping[str, Any] | str, targets: Any,
              parameters: Sequence[str], *, bounds: Mapping[str, Any] | None = None,
              method: str = "lm", max_evaluations: int = 100, xtol: float = 1e-10,
              jacobian: str = "exact", posterior: Mapping[str, Any] | None = None,
              steps_per_cycle: int | None = None, tol: float = 1e-12,
              max_cycles: int = 2000, gradient: str = "auto",
              groups: Mapping[str, Sequence[str]] | None = None,
              ftol: float = 1e-12) -> CalibrationResult:
    """Fit ``parameters`` (patch paths) of ``model`` to ``targets`` (see
    :func:`oxyline.targets.parse_targets`) by ``scipy.optimize.least_squares`` with the
    core's exact Jacobian: ``method="lm"`` (Levenberg–Marquardt, no bounds) or ``"trf"``
    (trust-region reflective, ``bounds`` {path: (low, high)} in the model's units).

    ``method="bayes"``: the posterior by emcee's affine-invariant ensemble sampler (the
    ``bayes`` extra), started around the gradient-based fit (trf with bounds, else lm), with a
    Gaussian likelihood of the weighted residuals and a flat prior in log(parameter) within the
    bounds; ``posterior`` sets ``walkers`` (default 4 per parameter, at least 8), ``steps``
    (500), ``burn`` (half) and ``seed`` (0). ``samples`` holds the draws after the burn-in.

    ``jacobian="2-point"``: scipy's forward differences instead, for comparison
    (docs/calibration.md, "Cost"; the covariance is still the exact one at the end point).

    ``gradient``: how the core computes the exact Jacobian: ``"forward"`` (one tangent per
    parameter), ``"adjoint"`` (one backward sweep per target value, whatever the number of
    parameters) or ``"auto"`` (the adjoint when the parameters outnumber the target values).

    ``xtol``, ``ftol``: least_squares' relative tolerances on the step and the cost. With noisy
    data (Gauss-Newton converges linearly where residuals are not zero) an ``ftol`` of 1e-8
    stops where a further step moves the parameters by a small fraction of their errors.

    ``groups`` {name: [paths]}: each name is one more fitted variable, a factor (starting at
    1) on every path of the group at once (their ratios kept: e.g. the wall stiffness of a
    region's vessels); its bounds, value and interval are the factor's.

    A fit that fails at a trial point (a model the core refuses, a diverged run) returns the
    best point reached with ``success=False`` and the failure in ``report["error"]``.

    >>> path = "boundary_conditions.ica_out.resistance"
    >>> truth = native_model(load_model("bifurcation").source, [path], [3.5e9])
    >>> out = ["parent.pressure_in.mean", "flow_split.daughter1.parent"]
    >>> measured = sensitivities(truth, [], out).values
    >>> fit = calibrate("bifurcation", dict(zip(out, measured)), [path])
    >>> bool(fit.success), round(fit.parameters[path] / 3.5e9, 6)
    (True, 1.0)
    """
    if method not in ("lm", "trf", "bayes"):
        raise CalibrationError(f"method: expected 'lm', 'trf' or 'bayes', got {method!r}")
    _count("max_evaluations", max_evaluations)
    _fraction("xtol", xtol)
    _fraction("ftol", ftol)
    # ``bayes`` starts its sampler around the gradient-based fit
    fit_method = ("trf" if bounds else "lm") if method == "bayes" else method
    if method == "bayes":
        if _is_loop(model):
            raise CalibrationError("method 'bayes' is not available for a closed loop's "
                                   "oxygen: use 'lm' or 'trf'")
        emcee, opts = _emcee(posterior, len(parameters) + len(groups or {}))
    if jacobian not in ("exact", "2-point"):
        raise CalibrationError(f"jacobian: expected 'exact' or '2-point', got {jacobian!r}")
    problem, (lo, hi) = _problem(model, targets, parameters, bounds, fit_method, jacobian,
                                 {"steps_per_cycle": steps_per_cycle, "tol": tol,
                                  "max_cycles": max_cycles}, gradient, groups)
    fit = _least_squares(problem, lo, hi, fit_method, max_evaluations, xtol, ftol)
    if method == "bayes":
        _sample(fit, problem, lo, hi, emcee, opts)
    return fit


def _least_squares(problem: _Problem, lo: np.ndarray, hi: np.ndarray, method: str,
                   max_evaluations: int, xtol: float, ftol: float, gtol: float = 1e-12
                   ) -> CalibrationResult:
    """The fit of ``problem`` by ``scipy.optimize.least_squares`` from the start (θ = 0)."""
    from scipy.optimize import least_squares

    report: dict[str, Any] = {"method": method, "gradient": problem.gradient}
    try:
        fit = least_squares(problem.fun, np.zeros(len(problem.parameters)),
                            jac=problem.jac if problem.exact else "2-point",
                            bounds=(lo, hi) if method == "trf" else (-np.inf, np.inf),
                            method=method, x_scale=1.0, xtol=xtol, ftol=ftol, gtol=gtol,
                            max_nfev=max_evaluations)
        theta, success = fit.x, bool(fit.success)
        report.update(status=int(fit.status), message=str(fit.message), nfev=int(fit.nfev),
                      njev=int(fit.njev or 0), optimality=float(fit.optimality))
    except _Stop:
        assert problem.best is not None
        theta, success = problem.best[1], False
        report.update(status=-1, message="an evaluation failed; the best point reached is "
                      "returned", error=problem.error)
    problem.end = theta
    r, j = _end_point(problem, theta)
    return _result(problem, theta, r, j, success, report)


def _end_point(problem: _Problem, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The residuals and exact Jacobian (the covariance's) at the fit's end point, NaN if they
    cannot be had."""
    best = problem.best
    if best is not None and best[1].tobytes() == theta.tobytes() and best[3].shape[1]:
        return best[2], best[3]
    problem.exact, problem.cache = True, None
    try:
        return problem._eval(theta)
    except _Stop:
        rows = len(problem.data) + (len(theta) if problem.prior is not None else 0)
        r = best[2] if best is not None else np.full(rows, np.nan)
        return r, np.full((len(r), len(problem.parameters)), np.nan)


def _groups(parameters: Sequence[str], groups: Any) -> dict[str, list[str]]:
    """The groups {name: [paths]}, checked: a name is no path, a path in one place only."""
    if isinstance(parameters, str):
        raise CalibrationError("parameters: expected a list of parameter paths")
    if groups is None:
        return {}
    if not isinstance(groups, Mapping):
        raise CalibrationError(f"groups: expected a mapping {{name: [paths]}}, got {groups!r}")
    out: dict[str, list[str]] = {}
    seen = set(parameters)
    for name, paths in groups.items():
        if isinstance(paths, str) or not isinstance(paths, Sequence) or not paths:
            raise CalibrationError(f"group {name!r}: expected a non-empty list of paths, got "
                                   f"{paths!r}")
        twice = [q for q in paths if q in seen or q == name]
        if twice or name in seen:
            raise CalibrationError(f"group {name!r}: {twice[0] if twice else name!r} is "
                                   "already a parameter or in another group")
        seen.update(paths)
        out[str(name)] = [str(q) for q in paths]
    return out


def _problem(model: Model | Mapping[str, Any] | str, targets: Any, parameters: Sequence[str],
             bounds: Mapping[str, Any] | None, method: str, jacobian: str,
             options: dict[str, Any], gradient: str = "auto", groups: Any = None
             ) -> tuple[_Problem, tuple[np.ndarray, np.ndarray]]:
    """The least-squares problem of :func:`calibrate` and its bounds in log space, every input
    checked (paths, targets, start, bounds, sizes) before the fit starts; a closed loop's
    oxygen is :func:`_loop_problem`'s."""
    if _is_loop(model):
        return _loop_problem(model, targets, parameters, bounds, method, jacobian,
                             {"tol": options["tol"], "max_cycles": options["max_cycles"]})
    base = load_model(model)
    grouped = _groups(parameters, groups)
    params = list(parameters) + list(grouped)
    if not params:
        raise CalibrationError("parameters: expected a non-empty list of parameter paths")
    if len(set(params)) != len(params):
        raise CalibrationError(f"parameters: given twice in {params}")
    if gradient not in ("auto", "forward", "adjoint"):
        raise CalibrationError(f"gradient: expected 'auto', 'forward' or 'adjoint', got "
                               f"{gradient!r}")
    tlist = parse_targets(targets, base)
    start = np.array([1.0 if p in grouped else _base_value(base.source, p) for p in params])
    starts = [(q, _base_value(base.source, q)) for p in params for q in grouped.get(p, [p])]
    bad = [q for q, x in starts if not x > 0]
    if bad:
        raise CalibrationError(f"parameter '{bad[0]}': the start must be positive (fitted in "
                               "log space)")
    lo, hi = _bounds(params, start, bounds)
    if method == "lm" and (np.isfinite(lo).any() or np.isfinite(hi).any()):
        raise CalibrationError("method 'lm' takes no bounds: use method='trf'")
    if gradient == "auto":  # one sweep per target value, or one tangent per parameter
        rows = sum(t.size for t in tlist)
        gradient = "adjoint" if len(starts) > rows else "forward"
    problem = _Problem(copy.deepcopy(base.source), params, start, tlist, options,
                       groups=grouped, gradient=gradient)
    problem.jac(np.zeros(len(params)))  # paths and targets are checked here, before the fit
    if jacobian != "exact":
        problem.exact, problem.cache = False, None
    n_res = len(problem.data)
    if method == "lm" and n_res < len(params):
        raise CalibrationError(f"method 'lm' needs at least as many target values ({n_res}) "
                               f"as parameters ({len(params)}): use method='trf'")
    return problem, (lo, hi)


def _result(problem: _Problem, theta: np.ndarray, r: np.ndarray, j: np.ndarray,
            success: bool, report: dict[str, Any]) -> CalibrationResult:
    params = problem.parameters
    if not np.isfinite(j).all():  # no Jacobian at the end point: no covariance
        j = np.zeros_like(j)
    jtj = j.T @ j
    sv = np.linalg.svd(j, compute_uv=False) if j.size else np.zeros(0)
    rank_tol = sv.max(initial=0.0) * max(j.shape) * np.finfo(float).eps
    rank = int((sv > rank_tol).sum())
    cov = np.linalg.pinv(jtj)
    report.update(evaluations=problem.evaluations, rank=rank,
                  condition=float(sv.max() / sv.min()) if rank == len(params) else np.inf)
    if rank < len(params):
        # the directions the data do not see: parameters with a share of the null space
        _, _, vt = np.linalg.svd(j)
        null = np.abs(vt[rank:]).max(axis=0)
        report["unidentifiable"] = [p for p, w in zip(params, null, strict=True) if w > 0.1]
    values = problem.values(theta)
    # (an unidentified direction's sd is huge: the interval is then (0, inf), not an overflow)
    sd = np.minimum(np.sqrt(np.clip(np.diag(cov), 0.0, None)), 700.0 / Z95)
    intervals = {p: (float(v * np.exp(-Z95 * s)), float(v * np.exp(Z95 * s)))
                 for p, v, s in zip(params, values, sd, strict=True)}
    return CalibrationResult(
        model=problem.model(theta), parameters=dict(zip(params, map(float, values),
                                                        strict=True)),
        start=dict(zip(params, map(float, problem.start), strict=True)), residuals=r,
        cost=0.5 * float(r @ r), covariance=cov, intervals=intervals, success=success,
        report=report)


# ---- a closed loop's oxygen (oxyline.closed_loop) -------------------------------------------

def _is_loop(model: Any) -> bool:
    """Whether ``model`` names or is a closed-loop O2 parameter set (:mod:`oxyline.closed_loop`;
    its targets and parameters are the core's ``closed_loop_sensitivity`` names)."""
    if isinstance(model, str):
        return model in closed_loop.BUILTINS
    return isinstance(model, Mapping) and "organs" in model and "pools" in model


def _loop_sensitivities(model: Any, parameters: Sequence[str], outputs: Sequence[str],
                        tol: float, max_cycles: int) -> Sensitivities:
    """:func:`sensitivities` of a closed loop's O2 outputs (SvO2, VO2.<organ>, ...) at its
    periodic state, by the core's tangent and the implicit function theorem on the fixed
    point (:func:`oxyline.closed_loop.o2_sensitivities`)."""
    raw = closed_loop.o2_sensitivities(model, list(parameters), list(outputs),
                                       max_cycles=max_cycles, tol=tol)
    rows = {o: slice(i, i + 1) for i, o in enumerate(outputs)}
    return Sensitivities(list(outputs), list(parameters), np.asarray(raw["parameter_values"]),
                         np.asarray(raw["values"]), np.asarray(raw["jacobian"]),
                         int(raw["cycles"]), float(raw["periodic_error"]), rows)


def _is_heart(path: str) -> bool:
    """Whether ``path`` names a value of the loop's heart model (kept in ``heart_values``)."""
    return path.startswith(("vessels.", "boundary_conditions."))


def _loop_key(source: dict[str, Any], path: str) -> tuple[dict[str, Any], str]:
    """The dict holding ``path``'s number in the parameter set, and its key: a heart model's
    value is the set's ``heart_values[path]``, taken from the model the core builds
    (:func:`oxyline.closed_loop.heart_model`) when the set does not give it yet."""
    if _is_heart(path):
        values = source.setdefault("heart_values", {})
        if path not in values:
            with core_errors("closed-loop heart model"):
                values[path] = float(_core.closed_loop_heart_value(
                    json.dumps(closed_loop._with_block(source)), path))
        return values, path
    *head, last = path.split(".")
    node: Any = source
    for k in head:
        node = node.get(k) if isinstance(node, Mapping) else None
    if not isinstance(node, Mapping) or not isinstance(node.get(last), (int, float)):
        raise CalibrationError(f"parameter '{path}': not a number of the closed loop's "
                               "parameter set")
    return node, last  # type: ignore[return-value]


class _LoopProblem(_Problem):
    """:class:`_Problem` of a closed loop's O2: its parameter set's numbers by key, its
    outputs by name (one value each), the exact Jacobian of the core's loop tangent."""

    def __init__(self, source: dict[str, Any], parameters: list[str], targets: list[Target],
                 options: dict[str, Any]) -> None:
        start = np.array([float(node[k]) for node, k in
                          (_loop_key(source, q) for q in parameters)])
        self.source, self.parameters, self.paths, self.start = source, parameters, parameters, \
            start
        self.path_start, self.members = start, np.eye(len(parameters))
        self.exact, self.gradient, self.targets, self.options = True, "forward", targets, options
        self.data = np.concatenate([t.value for t in targets])
        self.sigma = np.concatenate([t.sigma for t in targets])
        self.cache, self.best, self.error, self.evaluations = None, None, None, 0
        self.derived, self.prior, self.end = None, None, None

    def model(self, theta: np.ndarray) -> dict[str, Any]:
        p = copy.deepcopy(self.source)
        for q, v in zip(self.parameters, self.values(theta), strict=True):
            node, k = _loop_key(p, q)
            node[k] = float(v)
        return p

    def _at(self, theta: np.ndarray) -> Any:
        return self.model(theta)

    def _outputs(self, m: Any) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
        raw = closed_loop.o2_sensitivities(m, self.parameters if self.exact else [],
                                           [t.output for t in self.targets], **self.options)
        # ``values`` of the raw result are the parameters' SI values (as the model's tangent)
        return np.asarray(raw["values"]), np.asarray(raw["jacobian"]), \
            {**raw, "values": raw["parameter_values"]}


def _loop_problem(model: Any, targets: Any, parameters: Sequence[str], bounds: Any,
                  method: str, jacobian: str, options: dict[str, Any]
                  ) -> tuple[_Problem, tuple[np.ndarray, np.ndarray]]:
    """:func:`_problem` of a closed loop's O2: targets ``{output: value | {value, sigma |
    weight}}``, every input checked (the core names an unknown output or parameter) before
    the fit starts."""
    source = closed_loop.load(model) if isinstance(model, str) else copy.deepcopy(dict(model))
    _groups(parameters, None)  # a string is refused
    params = [str(p) for p in parameters]
    if not params or len(set(params)) != len(params):
        raise CalibrationError(f"parameters: expected distinct parameter keys, got {params}")
    if not isinstance(targets, Mapping) or not targets:
        raise CalibrationError("targets: expected a mapping {output: value} for a closed loop")
    tlist = []
    for name, item in targets.items():
        item = dict(item) if isinstance(item, Mapping) else {"value": item}
        value = _finite(str(name), "value", item.get("value"), False)
        tlist.append(Target(str(name), value, _sigma(str(name), item, value)))
    problem = _LoopProblem(source, params, tlist, options)
    if not (problem.start > 0).all():
        raise CalibrationError(f"parameter '{params[int(np.argmin(problem.start > 0))]}': the "
                               "start must be positive (fitted in log space)")
    lo, hi = _bounds(params, problem.start, bounds)
    if method == "lm" and (np.isfinite(lo).any() or np.isfinite(hi).any()):
        raise CalibrationError("method 'lm' takes no bounds: use method='trf'")
    try:  # outputs and parameters are checked by the core here, before the fit
        problem.jac(np.zeros(len(params)))
    except _Stop as e:
        raise CalibrationError(str(e.__cause__)) from None
    if jacobian != "exact":
        problem.exact, problem.cache = False, None
    return problem, (lo, hi)


# ---- command line ---------------------------------------------------------------------------

def read_problem(path: str) -> dict[str, Any]:
    """A calibration problem file (YAML or JSON): ``parameters`` (a list of paths, or a
    mapping {path: {bounds: [low, high]}}), ``targets`` (as :func:`calibrate` takes them) and
    optionally ``method``, ``groups`` ({name: [paths]}) and ``gradient``."""
    import yaml

    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except yaml.YAMLError as e:
        raise CalibrationError(f"{path}: not a YAML or JSON file ({e})") from None
    if not isinstance(data, Mapping):
        raise CalibrationError(f"{path}: expected a mapping with 'parameters' and 'targets'")
    unknown = set(data) - {"parameters", "targets", "method", "groups", "gradient"}
    if unknown or not {"parameters", "targets"} <= set(data):
        raise CalibrationError(f"{path}: needs 'parameters' and 'targets' (and optionally "
                               f"'method', 'groups', 'gradient'); unknown keys "
                               f"{sorted(unknown)}")
    params = data["parameters"]  # a mapping's keys are the paths
    bounds = {p: o["bounds"] for p, o in params.items() if isinstance(o, Mapping)
              and "bounds" in o} if isinstance(params, Mapping) else {}
    method = str(data.get("method", "trf" if bounds else "lm"))
    return {"parameters": list(params), "targets": data["targets"],
            "bounds": bounds or None, "method": method, "groups": data.get("groups"),
            "gradient": str(data.get("gradient", "auto"))}


def main_cli(model: str, problem_file: str, output: str, quiet: bool = False) -> int:
    """``oxyline calibrate MODEL TARGETS.yaml -o OUT``: fit, write the calibrated model, print
    the parameters with their 95 % intervals and the report. Exit 0 on convergence, 1 if the
    fit failed (the best point is written all the same)."""
    problem = read_problem(problem_file)
    res = calibrate(model, problem["targets"], problem["parameters"],
                    bounds=problem["bounds"], method=problem["method"],
                    groups=problem["groups"], gradient=problem["gradient"])
    path = dump_native(res.model, output)
    if not quiet:
        for p, v in res.parameters.items():
            lo, hi = res.intervals[p]
            print(f"{p:<48} {res.start[p]:.6g} -> {v:.6g}   95 %: [{lo:.6g}, {hi:.6g}]")
        print(f"cost {res.cost:.6g}, {res.report.get('nfev', '?')} evaluations: "
              f"{res.report.get('message')}")
        print(f"calibrated model written to {path}")
    return 0 if res.success else 1


def _emcee(posterior: Mapping[str, Any] | None, n: int) -> tuple[Any, dict[str, Any]]:
    """emcee and the sampler's options of ``method="bayes"`` for ``n`` fitted variables."""
    try:
        import emcee
    except ImportError:
        raise CalibrationError("method 'bayes' needs emcee: pip install oxyline[bayes]"
                               ) from None
    opts = {"walkers": max(8, 4 * n), "steps": 500, "burn": None, "seed": 0,
            **(posterior or {})}
    unknown = set(opts) - {"walkers", "steps", "burn", "seed"}
    if unknown:
        raise CalibrationError(f"posterior: unknown options {sorted(unknown)}")
    return emcee, opts


def _sample(fit: CalibrationResult, problem: _Problem, lo: np.ndarray, hi: np.ndarray,
            emcee: Any, opts: Mapping[str, Any]) -> None:
    """``method="bayes"``: emcee from around the gradient fit ``fit`` of ``problem`` (see
    :func:`calibrate`), its samples and report put into ``fit``."""
    params, start = problem.parameters, problem.start
    # the likelihood needs the residuals only, each trial point's evaluations counted anew
    problem.exact, problem.cache, problem.evaluations = False, None, 0

    def log_prob(theta: np.ndarray) -> float:
        if (theta < lo).any() or (theta > hi).any():
            return -np.inf
        try:
            r = problem.fun(theta)
        except _Stop:  # a point the model refuses has no likelihood
            return -np.inf
        return -0.5 * float(r @ r)

    theta_fit = np.log(np.array([fit.parameters[p] for p in params]) / start)
    rng = np.random.default_rng(int(opts["seed"]))
    cov = fit.covariance if np.isfinite(fit.covariance).all() else np.eye(len(params)) * 1e-4
    # walkers in a small ball around the fit (a tenth of its Gauss-Newton spread), in bounds
    p0 = rng.multivariate_normal(theta_fit, 0.01 * cov, size=int(opts["walkers"]))
    p0 = np.clip(p0, lo + 1e-12, hi - 1e-12)
    sampler = emcee.EnsembleSampler(int(opts["walkers"]), len(params), log_prob)
    # the sampler's own stream, seeded: the same samples on every call
    sampler.random_state = np.random.RandomState(int(opts["seed"])).get_state()
    steps = int(opts["steps"])
    burn = steps // 2 if opts["burn"] is None else int(opts["burn"])
    sampler.run_mcmc(p0, steps, progress=False)
    chain = sampler.get_chain(discard=burn, flat=True)
    fit.samples = problem.values(chain)  # each row's factors of the start
    fit.report.update(method="bayes", fit_method=fit.report["method"],
                      acceptance=float(np.mean(sampler.acceptance_fraction)),
                      posterior_evaluations=problem.evaluations)
