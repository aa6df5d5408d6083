"""closed-loop-o2's heart circuit (``closed_loop.heart_model``: svZeroDSolver's heart block,
its arteries, organ beds and veins) over its first cycles under the default controlled step,
against the fixed 1 ms generalized-α step its O2 loop runs the heart with, and the O2 loop at
its periodic state (Fick's principle residual, the loop's cycle-to-cycle change).

Per run: process CPU (``time.process_time``; meaningful under load, wall clock is not
reported), accepted (rejected) steps and valve events; per cycle: the cardiac output (the mean
flow into the arteries over the cycle) and the cycle-to-cycle change of the state at the cycle
ends (the largest change of any vessel's inlet pressure or flow, against that kind's largest
magnitude over the run).

    python benches/bench_closed_loop_cycles.py [--cycles 5] [--rtol 1e-3]
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

import numpy as np

import oxyline
from oxyline import closed_loop


def per_cycle(res: Any, period: float, cycles: int) -> list[tuple[float, float]]:
    """(cardiac output in L/min, cycle-to-cycle change at the cycle's end) of each cycle."""
    t = np.asarray(res.time)
    q_art = np.asarray(res.flow_in)[:, 0]  # the arteries' inlet: the aortic outflow
    ends = [int(np.argmin(np.abs(t - k * period))) for k in range(cycles + 1)]
    p, q = np.asarray(res.pressure_in), np.asarray(res.flow_in)
    sp, sq = np.max(np.abs(p)), np.max(np.abs(q))
    out = []
    for k in range(cycles):
        a, b = ends[k], ends[k + 1]
        co = float(np.trapezoid(q_art[a:b + 1], t[a:b + 1]) / period) * 6e4
        change = max(float(np.max(np.abs(p[b] - p[a]))) / sp, float(np.max(np.abs(q[b] - q[a]))) / sq)
        out.append((co, change))
    return out


def run(model: Any, label: str, cycles: int, period: float, **kw: Any) -> None:
    t0 = time.process_time()
    res = oxyline.simulate(model, cycles=cycles, until_periodic=None, output_cycles="all",
                           output_every=1e-3, progress=False, threads=1, **kw)
    cpu = time.process_time() - t0
    s = res.settings
    steps = f"{s['steps']} ({s['rejected_steps']})" if "steps" in s else \
        f"{round(cycles * period / s['dt'])} (fixed)"
    rows = per_cycle(res, period, cycles)
    print(f"| {label} | {cpu:.3f} | {steps} | {len(res.valve_events)} | "
          + " / ".join(f"{co:.3f}" for co, _ in rows) + " | "
          + " / ".join(f"{ch:.1e}" for _, ch in rows) + " |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, default=5)
    ap.add_argument("--rtol", type=float, default=1e-3)
    a = ap.parse_args()
    p = closed_loop.load("closed-loop-o2")
    model = oxyline.load_model(closed_loop.heart_model(p))
    period = model.period
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average "
          f"{os.getloadavg()[0]:.1f}, one thread, {a.cycles} cycles, rows every 1 ms\n")
    print("| heart run | CPU s | steps (rejected) | valve events | cardiac output per cycle "
          "(L/min) | change at each cycle's end |")
    print("|---|---:|---:|---:|---|---|")
    # (the default Newton control: the loop's absolute 1e-10 is for its fixed step)
    run(model, f"default (rtol {a.rtol:g})", a.cycles, period, rtol=a.rtol, dt="auto")
    run(model, "generalized-α, dt 1 ms (the O2 loop's heart step)", a.cycles, period,
        dt=1e-3, method="generalized-alpha", **closed_loop.heart_run_options(p))
    t0 = time.process_time()
    o2 = closed_loop.simulate_o2(p)
    cpu = time.process_time() - t0
    s = o2.summary()
    print(f"\nO2 loop (its heart: 30 cycles at dt 1 ms, as the core runs it): {cpu:.2f} s CPU, "
          f"{o2.cycles} O2 cycles, Fick residual {s['fick_residual']:.1e}, mass balance "
          f"{s['mass_balance_residual']:.1e}, periodic {o2.periodic_error:.1e}, CO "
          f"{s['cardiac_output']:.3f} L/min, SaO2 {s['SaO2']:.4f}, SvO2 {s['SvO2']:.4f}")


if __name__ == "__main__":
    main()
