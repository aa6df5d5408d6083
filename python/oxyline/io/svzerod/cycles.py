"""svZeroDSolver's ``use_cycle_to_cycle_error`` without RCR boundary conditions: the caps the
rule watches, and the rows svZeroDSolver outputs once it holds.

Without a Windkessel svZeroDSolver (``Solver::run_integration``) runs the file's cycles, then
extra cycles until, at every vessel cap, the means of the flow and of the pressure over the
last cycle differ from those over the cycle before by at most ``sim_cycle_to_cycle_percent_error``
percent (relative to the earlier mean; each mean over the cycle's points, both ends included).
The core runs that rule (``oxyline_core::run::svzerod::CycleMeanStop``); the caps are the
vessels with a boundary condition: the outlet node of a vessel with an outlet condition (also
one with both), else the inlet node. svZeroDSolver's output rows go on with the extra cycles,
their times restarting at Δt each cycle (with last-cycle output only the file's last cycle is
kept, plus, for a 2-cycle file, each extra cycle's end): :func:`output_rows`.
"""

from __future__ import annotations

from typing import Any

import numpy as np


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
