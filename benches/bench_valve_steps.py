"""Every heart and valve model of the tests under the default (error-controlled) settings at
rtol 1e-2, 1e-3 and 1e-4: whether it runs, its steps (rejected), valve events, smallest step
and CPU time (best of ``--repeat``), as a Markdown table (docs/physics.md §10.5).

    python benches/bench_valve_steps.py [--cycles 5] [--repeat 1]

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

import oxyline
from oxyline import closed_loop
from oxyline import svzerod as svz

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
CASES = ROOT / "tests" / "data" / "svzerod" / "cases"
SVZ = ["valve_tanh", "piecewise_Chamber_and_Valve", "chamber_elastance_inductor",
       "chamber_sphere", "closedLoopHeart_singleVessel", "closedLoopHeart_withCoronaries",
       "closedLoopHeart_singleVessel_decomposed", "closed_loop_two_hill"]


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


def run(m: dict[str, Any], rtol: float, cycles: int, repeat: int) -> str:
    best, res = float("inf"), None
    for _ in range(repeat):
        t = time.process_time()
        try:
            res = oxyline.simulate(oxyline.load_model(m), rtol=rtol, cycles=cycles,
                                   until_periodic=None)
        except oxyline.SolverError as e:
            return f"fails: {e}"
        best = min(best, time.process_time() - t)
    s = res.settings
    return (f"{s['steps']} ({s['rejected_steps']}) | {len(res.valve_events)} | "
            f"{s['dt_min']:.1e} | {best:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cycles", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    print(f"{a.cycles} cycles, default settings but rtol; CPU s best of {a.repeat}\n")
    print("| model | rtol | steps (rejected) | events | smallest step (s) | CPU (s) |")
    print("|---|---|---|---|---|---|")
    for name, m in models().items():
        for rtol in (1e-2, 1e-3, 1e-4):
            print(f"| {name} | {rtol:g} | {run(m, rtol, a.cycles, a.repeat)} |", flush=True)


if __name__ == "__main__":
    main()
