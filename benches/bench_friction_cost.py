"""CPU per step of Womersley friction and viscoelastic walls against Poiseuille segments, flow
only and with O2 (``o2-k``), on ``bench_scale.py``'s binary tree (generalized-α, 1 ms steps),
and the unknowns per segment each adds.

Runs are sequential in one process (a loaded machine drifts by tens of percent: compare the
ratios of one invocation, and repeat with ``--rounds``: the best of the rounds is shown); each
run is built once (``load_model``), then one period is timed with ``time.thread_time`` on one
thread (``threads=1``: the core then steps on the calling thread, so its CPU time is the run's).

``--memory``: each option also in a child process, its peak resident memory growth over the
load and the run (VmHWM − VmRSS before, Linux /proc) per segment.

    python benches/bench_friction_cost.py                 # depth 12: 4095 vessels x 4 segments
    python benches/bench_friction_cost.py --depth 15      # 32767 vessels x 4 = 1.3e5 segments
    python benches/bench_friction_cost.py --depth 15 --rounds 3 --memory
"""

from __future__ import annotations

import argparse
import os
import subprocess
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
    oxyline.simulate(m, cycles=1, dt=1e-3, method="generalized-alpha", output_every=1e-2,
                     threads=1)
    steps = round(PERIOD / 1e-3)
    return (time.thread_time() - t0) / (steps * segments) * 1e9


CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
import oxyline
from bench_friction_cost import OPTIONS, model

def rss(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return float(line.split()[1]) * 1024

oxyline.simulate("bifurcation", cycles=1, threads=1)
base = rss("VmRSS:")
depth, name, config = int(sys.argv[2]), sys.argv[3], sys.argv[4]
m = oxyline.load_model(model(depth, config, OPTIONS[name]))
oxyline.simulate(m, cycles=1, dt=1e-3, method="generalized-alpha", output_every=1e-2,
                 threads=1)
print(json.dumps((rss("VmHWM:") - base) / m.network.summary()["segments"]))
"""


def peak_per_segment(depth: int, name: str, config: str) -> float:
    """Peak resident memory growth per segment (bytes) of one load and run in a child."""
    here = os.path.dirname(os.path.abspath(__file__))
    done = subprocess.run([sys.executable, "-c", CHILD, here, str(depth), name, config],
                          check=True, capture_output=True, text=True)
    return float(done.stdout.splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--depth", type=int, default=12)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--memory", action="store_true")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}")
    memory = " peak B / segment |" if args.memory else ""
    print("| option | config | unknowns / segment | ns / segment-step | ratio to flow Poiseuille |"
          + memory)
    print("|---|---|---:|---:|---:|" + ("---:|" if args.memory else ""))
    base = None
    for name, option in OPTIONS.items():
        for config in ("flow", "o2-k"):
            m = oxyline.load_model(model(args.depth, config, option))
            summary = m.network.summary()
            segments, unknowns = summary["segments"], summary["unknowns"]
            cost = min(step_cost(m, segments) for _ in range(args.rounds))
            if base is None:
                base = cost
            del m
            peak = f" {peak_per_segment(args.depth, name, config):.0f} |" if args.memory else ""
            print(f"| {name} | {config} | {unknowns / segments:.2f} | {cost:.1f} | "
                  f"{cost / base:.2f} |{peak}", flush=True)


if __name__ == "__main__":
    main()
