"""RK4 stability limit above the dense size: old vs new vs dense.

    python benches/bench_stability.py                    # 1e3 ... 1e5 unknowns + built-ins
    python benches/bench_stability.py --old-pythonpath /path/to/old/python   # add the old limit

For each model: the core's limit (`rk4_stability_limit()`, Krylov above 600 differential
unknowns) and its wall time, the dense limit (numpy eigenvalues of the exported operator,
`rk4_operator`, up to `--dense-max` unknowns) and, with `--old-pythonpath`, the limit that an
older build (the power iteration) reports for the same model, computed in a subprocess.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import oxyline

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_stability import chain, refined, rk4_step_limits, tree


def cases() -> list[tuple[str, dict]]:
    return [
        ("chain 145 vessels", chain(145, wiggle=False)),
        ("chain 155 vessels", chain(155, wiggle=False)),
        ("circle-of-willis, max_length 5 mm", refined("circle-of-willis", 0.005)),
        ("matthys37, max_length 5 mm", refined("matthys37", 0.005)),
        ("chain 250 vessels", chain(250)),
        ("tree depth 9", tree(9)),
        ("chain 1250 vessels", chain(1250)),
        ("chain 2500 vessels", chain(2500)),
        ("tree depth 12", tree(12)),
        ("chain 25000 vessels", chain(25000)),
    ]


OLD = """
import json, sys, oxyline
d = json.load(sys.stdin)
print(oxyline.load_model(d).network.rk4_stability_limit()[0])
"""


def old_limit(d: dict, pythonpath: str) -> float:
    env = {**os.environ, "PYTHONPATH": pythonpath}
    out = subprocess.run([sys.executable, "-c", OLD], input=json.dumps(d), text=True,
                         capture_output=True, env=env, check=True, cwd="/")
    return float(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--old-pythonpath")
    ap.add_argument("--dense-max", type=int, default=5000)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}")
    print("| model | diff. unknowns | old (s) | new (s) | dense (s) | new/dense | old/dense |"
          " new time (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, d in cases():
        model = oxyline.load_model(d)
        net = model.network
        t0 = time.perf_counter()
        new, _, _ = net.rk4_stability_limit()
        t_new = time.perf_counter() - t0
        n = model.summary()["unknowns"]
        dense = float("nan")
        nd = "?"
        if n <= 2 * args.dense_max:
            flat, nd = net.rk4_operator()
            if nd <= args.dense_max:
                dense = float(rk4_step_limits(np.linalg.eigvals(flat.reshape(nd, nd))).min())
            del flat
        old = old_limit(d, args.old_pythonpath) if args.old_pythonpath else float("nan")
        print(f"| {name} | {nd if nd != '?' else f'({n} in all)'} | {old:.3e} | {new:.3e} |"
              f" {dense:.3e} | {new / dense:.4f} | {old / dense:.4f} | {t_new:.2f} |",
              flush=True)


if __name__ == "__main__":
    main()
