"""Cost of oxygen on the coronary and closed-loop examples (issue 14 item 5, O2 part): the same
model run flow-only and flow + O2, CPU time (process time, robust to a loaded machine) with the
load average, and the closed-loop O2 solve to periodic steady state.

    python benches/bench_closed_loop_o2.py [--repeats 3] [--tree-only] [--shooting both]

`closed-loop-o2` and `closed-loop-o2-tree` are driven by their default heart, svZeroDSolver's
ClosedLoopHeartAndPulmonary block (`closed_loop.run_heart`: 30 cycles at 1 ms, every unknown
recorded). Flow only = that heart run; flow + O2 = `closed_loop.simulate_o2`, i.e. the same
heart run, (with the tree) the tree's own flow run driven by its aortic outflow, and the O2
loop to its periodic steady state at the O2 step dt (flows block-averaged): Anderson
acceleration of the cycle map (default) or, with `--shooting both`, also the earlier
finite-difference Newton shooting (one cycle per unknown) in the same run. The rows with the
prescribed flow table time the O2 solve alone.
"""

from __future__ import annotations

import argparse
import os
import time

import oxyline
from oxyline import closed_loop, examples


def cpu(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tree-only", action="store_true", help="only the arterial-tree rows")
    ap.add_argument("--shooting", choices=("anderson", "both"), default="anderson",
                    help="'both': also the finite-difference Newton shooting, same run")
    a = ap.parse_args()
    shootings = ("anderson", "newton") if a.shooting == "both" else ("anderson",)
    print(f"load average at start: {os.getloadavg()}")
    print("| model | flow only (s CPU) | flow + O2 (s CPU) | ratio |")
    print("|---|---:|---:|---:|")
    if not a.tree_only:
        m = examples.load("paper-curved-coronary")
        flow = cpu(lambda: oxyline.simulate(m, transport=False), a.repeats)
        o2 = cpu(lambda: oxyline.simulate(m), a.repeats)
        print(f"| paper-curved-coronary, 8 cycles, 9 segments | {flow:.3f} | {o2:.3f} | "
              f"{o2 / flow:.2f} |")
        rows("closed-loop-o2", a.repeats, shootings)
        table_rows(a.repeats)
    rows("closed-loop-o2-tree", a.repeats, shootings)
    print(f"load average at end: {os.getloadavg()}")


def rows(name: str, repeats: int, shootings: tuple[str, ...]) -> None:
    """The block-driven model: the heart run alone vs flow + O2, per O2 step and shooting."""
    for dt in (4e-3, 1e-3):
        p = closed_loop.load(name)
        p["dt"] = dt
        flow = cpu(lambda p=p: closed_loop.run_heart(p), repeats)
        for shooting in shootings:
            res = None

            def both(p=p, shooting=shooting) -> None:
                nonlocal res
                res = closed_loop.simulate_o2(p, shooting=shooting)

            o2 = cpu(both, max(1, repeats // 3))
            s = res.summary()
            segs = f", {len(res.tree.segments)} segments" if res.tree is not None else ""
            print(f"| {name} block-driven, O2 dt {dt * 1e3:g} ms, {shooting}, {res.cycles} O2 "
                  f"cycles{segs} | {flow:.3f} | {o2:.3f} | {o2 / flow:.2f} |")
            print(f"|   SaO2 {s['SaO2']:.4f}, SvO2 {s['SvO2']:.4f}, VO2 {s['VO2']:.2f} mL/min "
                  f"(tree wall {s['VO2_tree_wall']:.3f}), CO {s['cardiac_output']:.3f} L/min, "
                  f"Fick {s['fick_residual']:.1e}, mass {s['mass_balance_residual']:.1e}, "
                  f"periodic {res.periodic_error:.1e} | | | |")


def table_rows(repeats: int) -> None:
    """closed-loop-o2 on the prescribed flow table: the O2 solve alone."""
    for dt in (4e-3, 1e-3):
        p = closed_loop.load()
        p["dt"] = dt
        p["flows"] = "table"
        table = cpu(lambda p=p: closed_loop.flow_table(p), repeats)
        res = None

        def run(p=p) -> None:
            nonlocal res
            res = closed_loop.simulate_o2(p)

        t = cpu(run, max(1, repeats // 2))
        steps = round(p["period"] / dt) * res.cycles
        per = t / steps / len(res.compartments) * 1e6
        print(f"| closed-loop-o2 prescribed table, dt {dt * 1e3:g} ms, {res.cycles} cycles to "
              f"periodic | {table:.4f} (table) | {t:.3f} | {per:.2f} µs per compartment-step |")


if __name__ == "__main__":
    main()
