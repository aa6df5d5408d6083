"""The per-variant overhead of an ensemble: what the calling thread spends turning each patch
into a variant for the core's workers (merge, read of the changed elements, hand-over), and
the process CPU of a small ensemble per variant.

    python benches/bench_variant_overhead.py                      # 200 variants, 5 rounds
    python benches/bench_variant_overhead.py --variants 1000 --rounds 3
    python benches/bench_variant_overhead.py --parts prepare --rounds 20

Model: ``paper-bifurcated`` (3 vessels, 30 segments, oxygen). Variant k changes the CCA
radius, the ICA outlet's resistance, ``scale.resistance`` and the wall PO2 (``oxygen.wall.po2``)
by factors in [0.9, 1.1]: every kind of patch path (a vessel, a condition, a scale, a
section). Two figures, each the process CPU (user + system of this process and its threads,
``time.process_time``; meaningful on a shared machine where wall time is not) per variant:

* ``prepare``: the names checked (``Patcher.check_all``) and every variant prepared
  (``Patcher.variant``), as ``simulate_ensemble`` does on its calling thread;
* ``ensemble``: ``simulate_ensemble(..., workers=1, output="summary", cycles=1)`` whole.

The best and the median of ``--rounds`` rounds are printed as a Markdown table. Run the same
command with two builds (``PYTHONPATH`` set to a copy of the former package) in one session
for a before/after ratio.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

import oxyline
from oxyline.ensemble.patch import Patcher

MODEL = "paper-bifurcated"


def patches(n: int) -> list[dict]:
    """Variant k of ``n``: four patch paths scaled by factors in [0.9, 1.1]."""
    f = np.linspace(0.9, 1.1, n)
    return [{"vessels": {"CCA": {"radius": 0.003 * x}},
             "boundary_conditions": {"ica_out": {"resistance": 2.8931e9 * x}},
             "scale": {"resistance": float(2.0 - x)},
             "oxygen": {"wall": {"po2": 55.5 * x}}} for x in f.tolist()]


def prepare(model: oxyline.Model, ps: list[dict]) -> float:
    """Process CPU of checking and preparing every variant (s)."""
    t = time.process_time()
    patcher = Patcher(model)
    patcher.check_all(ps)
    for k, p in enumerate(ps):
        patcher.variant(p, k)
    return time.process_time() - t


def ensemble(model: oxyline.Model, ps: list[dict]) -> float:
    """Process CPU of a summary ensemble of one cycle per variant on one worker (s)."""
    t = time.process_time()
    ds = oxyline.simulate_ensemble(model, ps, workers=1, output="summary", cycles=1,
                                   progress=False)
    spent = time.process_time() - t
    assert (ds.status.values == 0).all(), ds.error.values
    return spent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--label", default="this build")
    ap.add_argument("--parts", default="prepare,ensemble", help="which figures to measure")
    args = ap.parse_args(argv)
    model = oxyline.load_model(MODEL)
    ps = patches(args.variants)
    prepare(model, ps[:2])  # warm-up: imports, first reads
    parts = {"prepare": prepare, "ensemble": ensemble}
    times: dict[str, list[float]] = {p: [] for p in args.parts.split(",")}
    for _ in range(args.rounds):
        for part, ts in times.items():
            ts.append(parts[part](model, ps))
    n = args.variants
    print(f"\n{MODEL}, {n} variants, {args.rounds} rounds ({args.label}); process CPU per "
          "variant\n")
    print("| part | best (µs) | median (µs) |")
    print("|---|---:|---:|")
    for part, ts in times.items():
        print(f"| {part} | {min(ts) / n * 1e6:,.0f} | {statistics.median(ts) / n * 1e6:,.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
