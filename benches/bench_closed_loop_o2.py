"""Cost of oxygen on the coronary and closed-loop examples: the same
model run flow-only and flow + O2, CPU time (process time, robust to a loaded machine) with the
load average, and the closed-loop O2 solve to periodic steady state.

    python benches/bench_closed_loop_o2.py [--repeats 3] [--tree-only] [--shooting both]

`closed-loop-o2` and `closed-loop-o2-tree` are driven by their default heart, svZeroDSolver's
ClosedLoopHeartAndPulmonary block (`closed_loop.heart_model`: 30 cycles at 1 ms). Flow only =
that heart run (`oxyline.simulate`); flow + O2 = `closed_loop.simulate_o2`, i.e. one core call:
the same heart run (every unknown of its last cycle recorded), (with the tree) the tree's own flow run driven by its aortic outflow, and the O2
loop to its periodic steady state at the O2 step dt (flows block-averaged): Anderson
acceleration of the cycle map (default) or, with `--shooting both`, also the earlier
finite-difference Newton shooting (one cycle per unknown) in the same run. The rows with the
prescribed flow table time the O2 solve alone. Flow only and flow + O2 run in turn, best of
`--repeats` (default 3) CPU seconds of each: same-run ratios (~2 min quiet).
"""

from __future__ import annotations

import argparse
import os
import time

from bench_heart import interleaved

import oxyline
from oxyline import catalogue, closed_loop


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3, help="interleaved repeats (best of)")
    ap.add_argument("--tree-only", action="store_true", help="only the arterial-tree rows")
    ap.add_argument("--shooting", choices=("anderson", "both"), default="anderson",
                    help="'both': also the finite-difference Newton shooting, same run")
    a = ap.parse_args()
    shootings = ("anderson", "newton") if a.shooting == "both" else ("anderson",)
    start = time.perf_counter()
    print(f"# bench_closed_loop_o2.py, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"best of {a.repeats} interleaved repeats (flow only, flow + O2, flow only, ...), "
          f"process CPU seconds\n")
    print(f"load average at start: {os.getloadavg()[0]:.1f}\n")
    print("| model | flow only (s CPU) | flow + O2 (s CPU) | ratio |")
    print("|---|---:|---:|---:|")
    if not a.tree_only:
        m = catalogue.load("paper-curved-coronary")
        r = interleaved({"flow": lambda: oxyline.simulate(m, transport=False),
                         "o2": lambda: oxyline.simulate(m)}, a.repeats)
        flow, o2 = r["flow"][2], r["o2"][2]
        print(f"| paper-curved-coronary, 8 cycles, 9 segments | {flow:.3f} | {o2:.3f} | "
              f"{o2 / flow:.2f} |")
        rows("closed-loop-o2", a.repeats, shootings)
        table_rows(a.repeats)
    rows("closed-loop-o2-tree", a.repeats, shootings)
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}; whole bench "
          f"{time.perf_counter() - start:.0f} s wall")


def rows(name: str, repeats: int, shootings: tuple[str, ...]) -> None:
    """The block-driven model: the heart run alone vs flow + O2, per O2 step and shooting."""
    for dt in (4e-3, 1e-3):
        p = closed_loop.load(name)
        p["dt"] = dt
        calls = {"flow": lambda p=p: oxyline.simulate(
            oxyline.load_model(closed_loop.heart_model(p)), **closed_loop.heart_run_options(p))}
        for shooting in shootings:
            calls[shooting] = lambda p=p, shooting=shooting: closed_loop.simulate_o2(
                p, shooting=shooting)
        r = interleaved(calls, repeats)
        flow = r["flow"][2]
        for shooting in shootings:
            res, o2 = r[shooting][0], r[shooting][2]
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
        r = interleaved({"table": lambda p=p: closed_loop.flow_table(p),
                         "o2": lambda p=p: closed_loop.simulate_o2(p)}, repeats)
        res, t = r["o2"][0], r["o2"][2]
        steps = round(p["period"] / dt) * res.cycles
        per = t / steps / len(res.compartments) * 1e6
        print(f"| closed-loop-o2 prescribed table, dt {dt * 1e3:g} ms, {res.cycles} cycles to "
              f"periodic | {r['table'][2]:.4f} (table) | {t:.3f} | {per:.2f} µs per "
              f"compartment-step |")


if __name__ == "__main__":
    main()
