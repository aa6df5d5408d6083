"""svZeroDSolver's ``use_cycle_to_cycle_error`` without RCR boundary conditions.

Without a Windkessel svZeroDSolver (``Solver::run_integration``) runs the file's cycles, then
extra cycles until, at every vessel cap, the means of the flow and of the pressure over the
last cycle differ from those over the cycle before by at most ``sim_cycle_to_cycle_percent_error``
percent (relative to the earlier mean; each mean over the cycle's points, both ends included).
The caps are the vessels with a boundary condition: the outlet node of a vessel with an outlet
condition (also one with both), else the inlet node. Its output rows go on with the extra
cycles, their times restarting at Δt each cycle (with last-cycle output only the file's last
cycle is kept, plus, for a 2-cycle file, each extra cycle's end). The drop-in does the same:
the run is deterministic, so a run of N + K cycles holds every shorter one; K grows until the
rule stops inside it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from oxyline.errors import ModelError

#: extra cycles tried first, and the most a run may need before the drop-in gives up
#: (svZeroDSolver itself has no cap and would run forever)
FIRST_EXTRA = 8
MAX_EXTRA = 2000


def caps(vessels: list[Any]) -> list[tuple[str, str]]:
    """(svZeroDSolver vessel, "in" or "out") of each cap, in file order."""
    out = []
    for v in vessels:
        bc = v.get("boundary_conditions") or {}
        if "outlet" in bc:  # svZeroDSolver's vessel type: outlet overrides inlet
            out.append((v["vessel_name"], "out"))
        elif "inlet" in bc:
            out.append((v["vessel_name"], "in"))
    return out


def extra_cycles(cap_values: np.ndarray, cycles: int, steps: int, error: float) -> int | None:
    """The extra cycles svZeroDSolver runs, or None if the recorded cycles do not reach it.
    ``cap_values``: (rows, caps, 2) flow and pressure at every step from t = 0."""
    if cycles < 2:  # svZeroDSolver never fills its two-cycle window: the check passes
        return 0
    recorded = (len(cap_values) - 1) // steps
    for k in range(recorded - cycles + 1):
        last = cycles + k  # 1-based cycle whose mean is compared with the one before
        prev = cap_values[(last - 2) * steps:(last - 1) * steps + 1].mean(axis=0)
        now = cap_values[(last - 1) * steps:last * steps + 1].mean(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.abs((now - prev) / prev)
        # as svZeroDSolver's `err > eps` test: a NaN (0/0) counts as converged
        if not np.any(err > error):
            return k
    return None


def output_rows(cycles: int, steps: int, extra: int, interval: int, all_cycles: bool
                ) -> tuple[np.ndarray, np.ndarray]:
    """svZeroDSolver's output rows: (global step indices, output times in units of Δt)."""
    total = steps * cycles + 1
    start_last = total - (steps + 1)
    rows, times = [], []
    if all_cycles or start_last <= 0:
        rows.append(0)
        times.append(0)
    counter = 0
    for i in range(1, total):
        counter += 1
        if counter == interval or (not all_cycles and i == start_last):
            if all_cycles or i >= start_last:
                rows.append(i)
                times.append(i)
            counter = 0
    for c in range(extra):  # the extra cycles: time restarts at i Δt, i = 1 .. steps
        for i in range(1, steps + 1):
            counter += 1
            if counter == interval or (not all_cycles and i == start_last):
                if all_cycles or i >= start_last:
                    rows.append(total - 1 + c * steps + i)
                    times.append(i)
                counter = 0
    t = np.asarray(times, dtype=float)
    if not all_cycles and len(t):
        t -= t[0]
    return np.asarray(rows, dtype=np.intp), t


def run(simulate: Callable[[int], tuple[np.ndarray, np.ndarray]], cycles: int, steps: int,
        interval: int, all_cycles: bool, error: float, dt: float
        ) -> tuple[np.ndarray, np.ndarray]:
    """``simulate(n)`` runs n cycles recording every step and returns (outputs (rows, ...),
    cap values (rows, caps, 2)). Returns svZeroDSolver's output times and rows."""
    extra = FIRST_EXTRA
    while True:
        values, cap_values = simulate(cycles + extra)
        k = extra_cycles(cap_values, cycles, steps, error)
        if k is not None:
            break
        if extra >= MAX_EXTRA:
            raise ModelError(f"simulation_parameters: use_cycle_to_cycle_error: the vessel caps' "
                             f"cycle means still change by more than {100 * error}% after "
                             f"{cycles + extra} cycles")
        extra = min(4 * extra, MAX_EXTRA)
    rows, t = output_rows(cycles, steps, k, interval, all_cycles)
    return dt * t, values[rows]
