"""The keyword arguments of :func:`oxyline.simulate` and :func:`oxyline.simulate_to_zarr`, typed
so that editors and type checkers show and check them. Each overrides the model's
``simulation:`` setting of the same meaning and is checked like the model itself (a bad value
is a :class:`~oxyline.ModelError` naming the setting)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import Any, Literal, TypedDict

from oxyline.errors import ModelError


class SimulateOptions(TypedDict, total=False):
    """Options of :func:`oxyline.simulate` (all optional; units SI)."""

    #: cardiac cycles to run (with ``until_periodic``: at least this many)
    cycles: int
    #: a fixed time step, s; ``"auto"`` (the default): error control at ``rtol`` (1e-3 unless
    #: given), or RK4's automatic step (half its stability limit) with ``method="rk4"``
    dt: float | Literal["auto"]
    #: time integrator
    method: Literal["auto", "rk4", "generalized-alpha", "dopri5"]
    #: output interval, s
    output_every: float
    #: keep the last cycle (time from 0) or every cycle
    output_cycles: Literal["last", "all"]
    #: stop when the cycle-to-cycle change of the state is below this relative tolerance
    until_periodic: float | None
    #: the most cycles a run ``until_periodic`` may take
    max_cycles: int
    #: generalized-α spectral radius at infinity (default 0.5)
    rho_infty: float
    #: initial state: the steady solution of the mean conditions, the periodic state of a
    #: linear circuit, zero, or svZeroDSolver's starts
    start: Literal["steady", "periodic", "zero", "svzerod-steady", "svzerod-zero"]
    #: record the per-segment variables (default True)
    segments: bool
    #: a progress bar (True) on runs longer than a second, or a callback ``f(t, t_end)``
    progress: bool | Callable[[float, float], object]
    #: Newton's absolute tolerance of the generalized-α step
    newton_atol: float
    #: Newton's iteration limit of the generalized-α step
    max_iterations: int
    #: run the species transport (default True when the model has species)
    transport: bool
    #: the variables to record: names of ``oxyline._core.VESSEL_VARIABLES`` etc., or ``"all"``
    variables: Sequence[str] | Literal["all"] | None
    #: the vessels to record: names, ``"all"`` or ``"none"``
    vessels: Sequence[str] | Literal["all", "none"] | None
    #: refuse a model and output estimated above this many bytes (or e.g. ``"8 GB"``)
    max_memory: int | float | str
    #: a file the run's state is written to at cycle ends, for :func:`oxyline.resume`
    checkpoint: str | None
    #: how often to checkpoint: seconds of wall time, or ``"N cycles"``
    checkpoint_every: float | str
    #: setting this event stops the run with :class:`~oxyline.SimulationCancelled`
    cancel: threading.Event | None
    #: error control: the relative tolerance of every unknown's local error per step
    #: (generalized-α or the explicit pair with a variable step and dense output; excludes
    #: ``dt`` and ``"rk4"``). Default 1e-3 when no ``dt`` is given (the default run is
    #: error-controlled; ``result.settings["step_control"]`` says how the steps were chosen)
    rtol: float | None
    #: error control's absolute tolerance per kind of unknown, SI: ``{"pressure": Pa, "flow":
    #: m^3/s, "volume": m^3, "species": mol/m^3}`` (defaults 1, 1e-9, 1e-9, 1e-6; without
    #: ``rtol`` it joins the default rtol, and is refused with a fixed ``dt``)
    atol: dict[str, float] | None
    #: threads of this run (default: every core; 1: serial); the results are the same bits
    #: on any number of threads (docs/performance.md)
    threads: int | None
    #: add a spatial error estimate (one refinement of every vessel's segments) to
    #: ``result.error_estimate["space"]``
    estimate_space_error: bool
    #: estimate the accumulated time-integration error of every vessel (the last cycle again
    #: at rtol/4): ``result.error_estimate`` then holds it, ``result.time_error`` per vessel
    estimate_time_error: bool
    #: run again at the tolerance the accumulated-error estimate asks until every vessel
    #: meets ``rtol`` (at most 3 runs; the result is the last one's)
    meet_rtol: bool


def output_names(value: Any, key: str) -> list[str] | None:
    """An output selection list of names (None, or ``all``: everything); a single name is a
    list of one."""
    if value is None or value == "all":
        return None
    if isinstance(value, str):
        return [value]
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise ModelError(f"simulation output: {key} must be a list of names, got {value!r}")
    return list(value)


def output_vessels(value: Any) -> list[str] | None:
    """Output ``vessels``: ``all`` (None: every vessel with output), ``none`` (no vessel) or a
    list of vessel names."""
    return [] if value == "none" else None if value == "all" else output_names(value, "vessels")
