"""Cost of oxygen on the coronary and closed-loop examples (issue 14 item 5, O2 part): the same
model run flow-only and flow + O2, CPU time (process time, robust to a loaded machine) with the
load average, and the closed-loop O2 solve to periodic steady state.

    python benches/bench_closed_loop_o2.py [--repeats 5] [--tree-only]

`closed-loop-o2` driven by the native closed-loop heart (`closed_loop.heart_model`: chambers,
valves, 30 cycles at 1 ms): flow only = the heart run; flow + O2 = the same heart run plus the
O2 loop to periodic steady state (the core's Newton shooting + confirming cycles) at the O2 step
dt (flows block-averaged). The prescribed-table rows time the O2 solve alone.

`closed-loop-o2-tree` (the arterial pool replaced by a segment-resolved arterial tree, 65
segments): flow only = the closed-loop heart with the tree (30 cycles at 1 ms); flow + O2 =
`closed_loop.simulate_o2`, i.e. the same heart run, the tree's own flow run (driven by the
heart's aortic flow, 100 cycles at the O2 step, twice: for the flow balance and in the core)
and the O2 loop with the tree's transport to periodic steady state (Newton shooting on the
compartments and the tree's cells).
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
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--tree-only", action="store_true", help="only the arterial-tree rows")
    a = ap.parse_args()
    print(f"load average at start: {os.getloadavg()}")
    if a.tree_only:
        print("| model | flow only (s CPU) | flow + O2 (s CPU) | ratio |")
        print("|---|---:|---:|---:|")
        tree_rows(a.repeats)
        print(f"load average at end: {os.getloadavg()}")
        return
    m = examples.load("paper-curved-coronary")
    flow = cpu(lambda: oxyline.simulate(m, transport=False), a.repeats)
    o2 = cpu(lambda: oxyline.simulate(m), a.repeats)
    print("| model | flow only (s CPU) | flow + O2 (s CPU) | ratio |")
    print("|---|---:|---:|---:|")
    print(f"| paper-curved-coronary, 8 cycles, 9 segments | {flow:.3f} | {o2:.3f} | "
          f"{o2 / flow:.2f} |")
    for dt in (4e-3, 1e-3):
        p = closed_loop.load()
        p["dt"] = dt
        model = closed_loop.heart_model(p)
        flow = cpu(lambda model=model: oxyline.simulate(model), a.repeats)

        def both(p=p, model=model) -> None:
            closed_loop.simulate_o2(p, flows=closed_loop.heart_flows(p, oxyline.simulate(model)))

        o2 = cpu(both, max(1, a.repeats // 2))
        print(f"| closed-loop-o2 heart-driven, O2 dt {dt * 1e3:g} ms | {flow:.3f} | {o2:.3f} | "
              f"{o2 / flow:.2f} |")
    for dt in (4e-3, 1e-3):
        p = closed_loop.load()
        p["dt"] = dt
        table = cpu(lambda p=p: closed_loop.flow_table(p), a.repeats)
        res = None

        def run(p=p) -> None:
            nonlocal res
            res = closed_loop.simulate_o2(p)

        t = cpu(run, max(1, a.repeats // 2))
        steps = round(p["period"] / dt) * res.cycles
        per = t / steps / len(res.compartments) * 1e6
        print(f"| closed-loop-o2, dt {dt * 1e3:g} ms, {res.cycles} cycles to periodic | "
              f"{table:.4f} (table) | {t:.3f} | {per:.2f} µs per compartment-step |")
    tree_rows(a.repeats)
    print(f"load average at end: {os.getloadavg()}")


def tree_rows(repeats: int) -> None:
    """closed-loop-o2-tree: the heart + tree flow run alone vs flow + O2 with the tree."""
    for dt in (4e-3, 1e-3):
        p = closed_loop.load("closed-loop-o2-tree")
        p["dt"] = dt
        model = closed_loop.heart_model(p)
        flow = cpu(lambda model=model: oxyline.simulate(model), repeats)
        res = None

        def both(p=p) -> None:
            nonlocal res
            res = closed_loop.simulate_o2(p)

        o2 = cpu(both, max(1, repeats // 3))
        s = res.summary()
        print(f"| closed-loop-o2-tree heart-driven, O2 dt {dt * 1e3:g} ms, {res.cycles} O2 "
              f"cycles, {len(res.tree.segments)} segments | {flow:.3f} | {o2:.3f} | "
              f"{o2 / flow:.2f} |")
        print(f"|   SaO2 {s['SaO2']:.4f}, SvO2 {s['SvO2']:.4f}, VO2 {s['VO2']:.2f} mL/min "
              f"(tree wall {s['VO2_tree_wall']:.3f}), Fick {s['fick_residual']:.1e}, "
              f"mass {s['mass_balance_residual']:.1e}, periodic {res.periodic_error:.1e} | | | |")


if __name__ == "__main__":
    main()
