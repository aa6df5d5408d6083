"""Runs to periodicity from the steady and the periodic start (the default start's rule,
docs/physics.md §10 "The default start"): cycles, accepted steps, process CPU and how far the
last cycle lies from the steady start's, on the built-in models and a binary tree with O2.

Each model runs its own periodicity setting (or ``--until``) error-controlled at ``--rtol``, one
thread, rows every ``--every`` s; the two starts run one after the other in this process
(process CPU: ``time.process_time``, meaningful under load; wall clock is not reported). The last
column is the largest difference of the two runs' last cycles (inlet pressure and flow of every
vessel, each against its kind's largest magnitude).

    python benches/bench_default_start.py
    python benches/bench_default_start.py --models adan56 --tree 12
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

import oxyline

MODELS = ["aortic-bifurcation", "cca", "circle-of-willis", "adan56", "pwdb-116"]


def _run(model: Any, start: str | None, kw: dict[str, Any]) -> tuple[Any, float]:
    opts = dict(kw) if start is None else {**kw, "start": start}
    t0 = time.process_time()
    res = oxyline.simulate(model, **opts)
    return res, time.process_time() - t0


def _difference(a: Any, b: Any) -> float:
    """Largest difference of the last cycles, each kind against its largest magnitude."""
    out = 0.0
    for name in ("pressure_in", "flow_in"):
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        n = min(len(x), len(y))
        out = max(out, float(np.max(np.abs(x[-n:] - y[-n:])) / np.max(np.abs(y[-n:]))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="*", default=MODELS)
    ap.add_argument("--tree", type=int, default=0, help="also a binary tree of this depth, O2")
    ap.add_argument("--until", type=float, default=None, help="until_periodic (default: model's)")
    ap.add_argument("--rtol", type=float, default=1e-3)
    ap.add_argument("--every", type=float, default=1e-2)
    a = ap.parse_args()
    cases: list[tuple[str, Any]] = [(m, m) for m in a.models]
    if a.tree:
        from bench_scale import tree

        cases.append((f"tree depth {a.tree}, O2", tree(a.tree, 6, "o2-k")))
    print("| model | start | cycles | steps (rejected) | CPU s | periodic error | last cycle vs steady |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name, source in cases:
        model = oxyline.load_model(source)
        until = a.until if a.until is not None else \
            (model.simulation or {}).get("until_periodic", 1e-4)
        kw = {"rtol": a.rtol, "dt": "auto", "until_periodic": until, "threads": 1,
              "output_every": a.every, "progress": False}
        steady, cpu_s = _run(model, "steady", kw)
        default, cpu_d = _run(model, None, kw)
        for label, res, cpu in (("steady", steady, cpu_s),
                                (f"default ({default.settings['start']})", default, cpu_d)):
            s = res.settings
            print(f"| {name} | {label} | {s['cycles_run']} | {s['steps']} "
                  f"({s['rejected_steps']}) | {cpu:.2f} | {s.get('periodic_error', 0):.1e} | "
                  f"{_difference(res, steady):.1e} |", flush=True)


if __name__ == "__main__":
    main()
