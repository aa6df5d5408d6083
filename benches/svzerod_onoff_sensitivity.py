"""How far svZeroDSolver's own result for coupledBlock_closedLoopHeart_withCoronaries moves under
round-off, beside the drop-in's distance from it (docs/svzerod.md "The on/off
valves and round-off").

Runs the file's 100 cycles with svzerod 3.2 and the drop-in, unchanged and with one start value
(`V_RA:CLH`, `P_pul:CLH`) moved by one ulp, and prints for each run the worst variable's
max|a − e| / range against the stored reference, against the unperturbed run of the same code
and (drop-in) against svzerod's run of the same file; then, per on/off valve, how many of the
run's steps end with its flow at round-off level (|Q| ≤ 1e-12 of its range), whose sign the next
step reads.

    python benches/svzerod_onoff_sensitivity.py

About a minute and a half on a quiet machine (8 runs of 100 × 999 steps).
"""

from __future__ import annotations

import copy
import gzip
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
import svzerod

from oxyline import svzerod as svz

NAME = "coupledBlock_closedLoopHeart_withCoronaries"
CASES = Path(__file__).resolve().parents[1] / "tests" / "data" / "svzerod" / "cases"
VALVE_FLOWS = ("Q_RA:CLH", "Q_RV:CLH", "Q_LA:CLH", "Q_LV:CLH")


def table(df: pd.DataFrame) -> dict[str, np.ndarray]:
    return {n: g["y"].to_numpy(float) for n, g in df.groupby("name", sort=False)}


def worst(a: dict[str, np.ndarray], e: dict[str, np.ndarray]) -> str:
    err, name = max((float(np.max(np.abs(a[n] - v)) / np.ptp(v)), n) for n, v in e.items())
    return f"{err:.1e} ({name})"


def perturbed(cfg: dict, key: str | None, direction: float) -> dict:
    cfg = copy.deepcopy(cfg)
    if key is not None:
        ic = cfg["initial_condition"]
        ic[key] = float(np.nextafter(ic[key], direction))
    return cfg


def main() -> None:
    base = json.loads((CASES / f"{NAME}.json").read_text())
    with gzip.open(CASES / "results" / f"result_{NAME}.json.gz") as f:
        stored = table(pd.DataFrame(json.load(f)))
    runs = [("unchanged", None, 0.0), ("V_RA:CLH + 1 ulp", "V_RA:CLH", np.inf),
            ("V_RA:CLH − 1 ulp", "V_RA:CLH", -np.inf), ("P_pul:CLH + 1 ulp", "P_pul:CLH", np.inf)]
    print("| start | svzerod vs stored | svzerod vs svzerod unchanged | drop-in vs stored "
          "| drop-in vs drop-in unchanged | drop-in vs svzerod | CPU s svzerod / drop-in |")
    print("|---|---|---|---|---|---|---|")
    first: tuple[dict, dict] | None = None
    for label, key, direction in runs:
        cfg = perturbed(base, key, direction)
        t0 = time.process_time()
        s = table(svzerod.simulate(copy.deepcopy(cfg)))
        t1 = time.process_time()
        o = table(svz.simulate(cfg))
        t2 = time.process_time()
        first = first or (s, o)
        same = "–" if key is None else None
        print(f"| {label} | {worst(s, stored)} | {same or worst(s, first[0])} | "
              f"{worst(o, stored)} | {same or worst(o, first[1])} | {worst(o, s)} | "
              f"{t1 - t0:.1f} / {t2 - t1:.1f} |", flush=True)
    assert first is not None
    print("\nsteps ending with a valve flow at round-off level (|Q| <= 1e-12 of its range), "
          "unchanged start:")
    for who, t in (("svzerod", first[0]), ("drop-in", first[1])):
        counts = []
        for name in VALVE_FLOWS:
            q = t[name]
            noise = (np.abs(q) <= 1e-12 * np.ptp(q)) & (q != 0.0)
            counts.append(f"{name} {int(noise.sum())} ({int((noise & (q > 0)).sum())} positive)")
        print(f"  {who}: " + ", ".join(counts) + f" of {len(first[0]['Q_LV:CLH'])} rows")


if __name__ == "__main__":
    main()
