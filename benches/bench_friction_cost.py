"""CPU per step of Womersley friction and viscoelastic walls against Poiseuille segments, flow
only and with O2 (``o2-k``), on ``bench_scale.py``'s binary tree (generalized-α, 1 ms steps),
and the unknowns per segment each adds.

Runs are sequential in one process (a loaded machine drifts by tens of percent: compare the
ratios of one invocation, and repeat with ``--rounds``); each run is built once
(``load_model``), then one period is timed with ``time.thread_time`` (the core steps on the
calling thread).

    python benches/bench_friction_cost.py                 # depth 12: 4095 vessels x 4 segments
    python benches/bench_friction_cost.py --depth 15      # 32767 vessels x 4 = 1.3e5 segments
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_scale import PERIOD, tree

import oxyline

OPTIONS = {
    "poiseuille": {},
    "womersley": {"wall_friction": "womersley"},
    "viscoelastic": {"viscosity": 3e3},
    "womersley+viscoelastic": {"wall_friction": "womersley", "viscosity": 3e3},
}


def model(depth: int, config: str, option: dict[str, Any]) -> dict[str, Any]:
    m = tree(depth, 4, config)
    if "wall_friction" in option:
        m["wall_friction"] = option["wall_friction"]
    if "viscosity" in option:
        for v in m["vessels"]:
            v["wall_viscosity"] = option["viscosity"]
    return m


def step_cost(m: oxyline.Model, segments: int) -> float:
    """ns per segment-step of one period (after a steady start)."""
    t0 = time.thread_time()
    oxyline.simulate(m, cycles=1, dt=1e-3, method="generalized-alpha", output_every=1e-2)
    steps = round(PERIOD / 1e-3)
    return (time.thread_time() - t0) / (steps * segments) * 1e9


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--depth", type=int, default=12)
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args()
    print("| option | config | unknowns / segment | ns / segment-step | ratio to flow Poiseuille |")
    print("|---|---|---:|---:|---:|")
    base = None
    for name, option in OPTIONS.items():
        for config in ("flow", "o2-k"):
            m = oxyline.load_model(model(args.depth, config, option))
            summary = m.network.summary()
            segments, unknowns = summary["segments"], summary["unknowns"]
            cost = statistics.median(step_cost(m, segments) for _ in range(args.rounds))
            if base is None:
                base = cost
            print(f"| {name} | {config} | {unknowns / segments:.2f} | {cost:.0f} | "
                  f"{cost / base:.2f} |", flush=True)


if __name__ == "__main__":
    main()
