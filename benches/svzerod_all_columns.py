"""The svZeroDSolver drop-in against every stored reference result, on ALL stored columns:
per case the worst column (max|a − e| / its range, max|e| for a column constant to the files'
rounding), the worst
error beyond the files' 10-decimal rounding (5e-11 taken off |a − e| first, as the tests do)
and the variables the drop-in does not output.

    python benches/svzerod_all_columns.py [case ...]

About two minutes on a quiet machine (the two coupled-block cases run 100 cycles).
"""

from __future__ import annotations

import gzip
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from oxyline import svzerod as svz

CASES = Path(__file__).resolve().parents[1] / "tests" / "data" / "svzerod" / "cases"
ROUNDING = 0.5e-10


def _scale(e: np.ndarray) -> float:
    """A column's range, or its max|e| where it is constant to the files' rounding (the
    steady cases, the means)."""
    span, size = float(np.ptp(e)), float(np.max(np.abs(e)))
    return span if span > 2 * ROUNDING + 1e-9 * size else (size or 1.0)


def compare(name: str) -> tuple[str, float, float, int, int, float]:
    """(worst variable and column, its error, the same beyond the files' rounding, variables
    missing, variables stored, seconds)."""
    with gzip.open(CASES / "results" / f"result_{name}.json.gz") as f:
        expected = pd.DataFrame(json.load(f))
    t0 = time.perf_counter()
    actual = svz.simulate(CASES / f"{name}.json")
    seconds = time.perf_counter() - t0
    names = list(dict.fromkeys(expected["name"]))
    have = set(actual["name"])
    worst, err, beyond = "", -1.0, 0.0
    for var in names:
        if var not in have:
            continue
        a, e = actual[actual["name"] == var], expected[expected["name"] == var]
        for c in expected.columns:
            if c in ("name", "time") or c not in a.columns:
                continue
            ev, av = e[c].to_numpy(float), a[c].to_numpy(float)
            scale = _scale(ev)
            d = np.abs(av - ev)
            x = float(np.max(d)) / scale
            if x > err:
                worst, err = f"{var} {c}", x
            beyond = max(beyond, float(np.max(np.maximum(d - ROUNDING, 0.0))) / scale)
    return worst, err, beyond, sum(v not in have for v in names), len(names), seconds


def main(cases: list[str]) -> None:
    if not cases:
        cases = sorted(p.name[len("result_"):-len(".json.gz")]
                       for p in (CASES / "results").glob("result_*.json.gz"))
    print("| case | worst column | error / range | beyond rounding | variables missing / "
          "stored | s |")
    print("|---|---|---|---|---|---|")
    for name in cases:
        worst, err, beyond, missing, total, seconds = compare(name)
        print(f"| {name} | {worst} | {err:.1e} | {beyond:.1e} | {missing} / {total} | "
              f"{seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
