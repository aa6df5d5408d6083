"""The default (error-controlled) run's CPU against the fixed step of equal error, on the
threads it runs with (docs/performance.md, "A small circuit's step stays on the calling
thread").

adan56, 3 cycles from the same start, rows every 1 ms, ``until_periodic=None``: the default
run (rtol 1e-3) and generalized-α at 0.625 ms (the fixed step of equal error in
``bench_accuracy.py``'s sweep), each with the default threads (every core) and with
``threads=1``, taking turns ``--repeat`` times; process CPU (``time.process_time``) of the
``simulate`` call, the least of the turns, and the ratios measured in the same run.

    python benches/bench_controlled_cost.py --repeat 3
"""

from __future__ import annotations

import argparse
import time
import warnings

import oxyline

BASE = {"cycles": 3, "until_periodic": None, "output_every": 1e-3, "progress": False}
FIXED = {"method": "generalized-alpha", "dt": 0.625e-3}
CONFIGS = {
    "default": {},
    "default, threads=1": {"threads": 1},
    "fixed 0.625 ms": FIXED,
    "fixed 0.625 ms, threads=1": {**FIXED, "threads": 1},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="adan56")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    model = oxyline.load_model(args.model)
    best = dict.fromkeys(CONFIGS, float("inf"))
    steps: dict[str, object] = {}
    for _ in range(args.repeat):
        for name, kw in CONFIGS.items():
            t0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = oxyline.simulate(model, **BASE, **kw)
            best[name] = min(best[name], time.process_time() - t0)
            steps[name] = res.settings.get("steps", "fixed")
    print(f"| {args.model}, 3 cycles | CPU (least of {args.repeat}) | steps |")
    print("|---|---:|---:|")
    for name in CONFIGS:
        print(f"| {name} | {best[name] * 1e3:.1f} ms | {steps[name]} |")
    ratio = best["default"] / best["fixed 0.625 ms"]
    ratio1 = best["default, threads=1"] / best["fixed 0.625 ms, threads=1"]
    print(f"\ndefault / fixed of equal error: {ratio:.2f}x (threads=1: {ratio1:.2f}x)")


if __name__ == "__main__":
    main()
