"""Every heart and valve model of the tests under the default (error-controlled) settings at
rtol 1e-2, 1e-3 and 1e-4: whether it runs, its steps (rejected), valve events, smallest step,
CPU time (best of ``--repeat``), the worst valve-law residual of its output rows and its
cardiac output's relative error against a fine fixed step (generalized-α at 1/``--reference-steps`` of the period, the same cycles), as a Markdown
table (docs/physics.md §10.5). The cardiac output is the mean flow over the last cycle through
the model's outlet valve (or the vessel after a heart block). The valve-law residual is, over
the last cycle's rows and every `valve` element, the largest |Q − Q_law(ΔP)| (the flow against
the flow its law gives at the row's pressures) over the valve's peak flow (the heart block's
on/off valves have no flow law and are left out).

    python benches/bench_valve_steps.py [--cycles 5] [--repeat 1] [--reference-steps 10000]
                                        [--models NAME ...]

Models: svZeroDSolver's chamber/valve cases (their fixed ``dt`` dropped), the native left
heart of tests/test_sensitivity_heart.py, the closed-loop heart of closed-loop-o2 and the
minimal closed loop of tests/test_svzerod_chambers.py.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import oxyline
from oxyline import closed_loop
from oxyline import svzerod as svz

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
CASES = ROOT / "tests" / "data" / "svzerod" / "cases"
SVZ = ["valve_tanh", "piecewise_Chamber_and_Valve", "chamber_elastance_inductor",
       "chamber_sphere", "closedLoopHeart_singleVessel", "closedLoopHeart_withCoronaries",
       "closedLoopHeart_singleVessel_decomposed", "closed_loop_two_hill"]


#: the vessel whose mean flow is each model's cardiac output
OUTPUT_VESSEL = {
    "valve_tanh": "valve", "piecewise_Chamber_and_Valve": "aortic",
    "chamber_elastance_inductor": "valve1", "chamber_sphere": "outlet_valve",
    "closedLoopHeart_singleVessel": "branch0_seg0",
    "closedLoopHeart_withCoronaries": "branch0_seg0",
    "closedLoopHeart_singleVessel_decomposed": "AV", "closed_loop_two_hill": "AR_SYS",
    "left-heart (native)": "aortic", "closed-loop-o2 heart": "arteries",
    "minimal closed loop": "aortic_valve"}


def cardiac_output(res: oxyline.Result, vessel: str, period: float) -> float:
    """The mean flow through `vessel` over the last cycle (trapezoid over the output rows)."""
    t, q = np.asarray(res.time), np.asarray(res.vessel(vessel).flow_in)
    last = t >= t[-1] - period * (1 + 1e-9)
    t, q = t[last], q[last]
    return float(np.sum(0.5 * (q[1:] + q[:-1]) * np.diff(t)) / (t[-1] - t[0]))


def law_flow(valve: dict[str, Any], dp: np.ndarray, cgs: bool) -> np.ndarray:
    """The flow (P_from − P_to)/R(ΔP) of a `valve` element's law at the drop `dp` =
    P_from − P_to in Pa (docs/physics.md §1.8: tanh in P_to − P_from, piecewise R_min while
    open); `cgs`: the law's parameters in dyn s/cm^5 and cm^2/dyn (1 dyn/cm^2 = 0.1 Pa)."""
    to_si = 1e5 if cgs else 1.0
    r_min, r_max = valve["min_resistance"] * to_si, valve["max_resistance"] * to_si
    if valve["law"] == "tanh":
        k = valve["steepness"] * (10.0 if cgs else 1.0)
        r = 0.5 * (r_max + r_min) + 0.5 * (r_max - r_min) * np.tanh(-k * dp)
    else:
        r = np.where(dp > 0.0, r_min, r_max)
    return dp / r


def valve_law_residual(m: dict[str, Any], res: oxyline.Result, period: float,
                       peaks: dict[str, float]) -> float:
    """The largest |Q − Q_law(ΔP)| over the last cycle's rows of every `valve` element, over
    that valve's peak |Q| in the reference (`peaks`; nan without a valve)."""
    t = np.asarray(res.time)
    last = t >= t[-1] - period * (1 + 1e-9)
    worst = float("nan")
    for v in m.get("vessels", []):
        if "valve" not in v:
            continue
        r = res.vessel(v["name"])
        dp = np.asarray(r.pressure_in - r.pressure_out)[last]
        q_law = law_flow(v["valve"], dp, m.get("units") == "cgs")
        peak = max(peaks[v["name"]], 1e-300)
        miss = float(np.max(np.abs(np.asarray(r.flow_in)[last] - q_law))) / peak
        worst = miss if np.isnan(worst) else max(worst, miss)
    return worst


def default_settings(m: dict[str, Any]) -> dict[str, Any]:
    """The model with its fixed step and method dropped: the default error control."""
    m = copy.deepcopy(m)
    for key in ("dt", "method", "rtol", "cycles", "until_periodic", "output_every"):
        m.get("simulation", {}).pop(key, None)
    return m


def models() -> dict[str, dict[str, Any]]:
    from tests.test_sensitivity_heart import HEART
    from tests.test_svzerod_chambers import CLOSED_LOOP
    out = {name: svz.to_oxyline_dict(str(CASES / f"{name}.json")) for name in SVZ}
    out["left-heart (native)"] = HEART
    out["closed-loop-o2 heart"] = closed_loop.heart_model(closed_loop.load("closed-loop-o2"))
    out["minimal closed loop"] = CLOSED_LOOP
    return {k: default_settings(v) for k, v in out.items()}


def peak_valve_flows(m: dict[str, Any], res: oxyline.Result, period: float) -> dict[str, float]:
    """Every `valve` element's largest |Q| over the last cycle."""
    t = np.asarray(res.time)
    last = t >= t[-1] - period * (1 + 1e-9)
    return {v["name"]: float(np.max(np.abs(np.asarray(res.vessel(v["name"]).flow_in)[last])))
            for v in m.get("vessels", []) if "valve" in v}


def reference(m: dict[str, Any], vessel: str, cycles: int,
              steps: int) -> tuple[str, float, dict[str, float]]:
    """The cardiac output and the valves' peak flows of generalized-α at a fixed step of
    period/`steps` (or half or twice that where its plain Newton fails at a step); where all
    three fail, of generalized-α under error control at rtol 1e-6."""
    model = oxyline.load_model(m)
    period = model.period
    common = {"cycles": cycles, "until_periodic": None, "output_every": period / 1000}
    for n in (steps, 2 * steps, steps // 2):
        try:
            res = oxyline.simulate(model, method="generalized-alpha", dt=period / n, **common)
            return f"GA T/{n}", cardiac_output(res, vessel, period), peak_valve_flows(m, res, period)
        except oxyline.SolverError:
            continue
    res = oxyline.simulate(model, method="generalized-alpha", rtol=1e-6, **common)
    return "GA rtol 1e-6", cardiac_output(res, vessel, period), peak_valve_flows(m, res, period)


def run(m: dict[str, Any], rtol: float, cycles: int, repeat: int,
        ref: tuple[str, float, dict[str, float]]) -> str:
    best, res = float("inf"), None
    for _ in range(repeat):
        t = time.process_time()
        try:
            res = oxyline.simulate(oxyline.load_model(m), rtol=rtol, cycles=cycles,
                                   until_periodic=None)
        except oxyline.SolverError as e:
            return f"fails: {e} | | | | | |"
        best = min(best, time.process_time() - t)
    s = res.settings
    period = oxyline.load_model(m).period
    err = abs(cardiac_output(res, ref[0], period) - ref[1]) / abs(ref[1])
    law = valve_law_residual(m, res, period, ref[2])
    return (f"{s['method']} | {s['steps']} ({s['rejected_steps']}) | {len(res.valve_events)} | "
            f"{s['dt_min']:.1e} | {best:.3f} | {err:.1e} | {law:.1e}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cycles", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--reference-steps", type=int, default=10000)
    ap.add_argument("--models", nargs="*", help="only these models (default: all)")
    a = ap.parse_args()
    print(f"{a.cycles} cycles, default settings but rtol; CPU s best of {a.repeat}; cardiac "
          f"output (CO) against generalized-alpha at period/{a.reference_steps}\n")
    print("| model | rtol | method | steps (rejected) | events | smallest step (s) | CPU (s) "
          "| CO error | valve-law residual | reference |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, m in models().items():
        if a.models and name not in a.models:
            continue
        vessel = OUTPUT_VESSEL[name]
        how, co, peaks = reference(m, vessel, a.cycles, a.reference_steps)
        for rtol in (1e-2, 1e-3, 1e-4):
            row = run(m, rtol, a.cycles, a.repeat, (vessel, co, peaks))
            print(f"| {name} | {rtol:g} | {row} | {how} |", flush=True)


if __name__ == "__main__":
    main()
