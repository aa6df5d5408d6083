"""Where an error-controlled run's steps go: per cycle, and against the fixed step of equal
error (docs/performance.md, "Error-controlled steps: where the steps go").

For each model and rtol: runs of 1 … ``cycles`` cycles from the same start (generalized-α,
``until_periodic=None``), whose step counts differ by each cycle's accepted steps; the last
run's errors against a reference (generalized-α at ``dt = T/ref``, rows every T/32 000) as
``bench_accuracy.py`` measures them (pulse pressure, flow, PO2 of its last cycle); the fixed
generalized-α step of equal error interpolated in a sweep (``bench_accuracy.sweep_interpolated``)
and its steps over the run; and the last cycle's mean step in systole and diastole
(``bench_accuracy.phases``). "Steps ÷ fixed" is the controlled run's accepted steps over the
fixed step's at equal error: 1 is a uniform step's efficiency; the cost ratio is this times
the controlled step's cost over the fixed step's.

    python benches/bench_step_history.py                              # adan56, paper-bifurcated
    python benches/bench_step_history.py --models adan56 --rtols 1e-3 --cycles 3
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))
import bench_accuracy as ba

#: fixed steps per cycle of the equal-error sweep, per model (the coarsest of
#: paper-bifurcated's is coarser than the controlled run's ceiling T/32)
SWEEPS = {
    "adan56": (100, 200, 400, 800, 1600, 3200, 6400, 12800),
    "paper-bifurcated": (16, 25, 32, 50, 100, 200, 400, 800, 1600, 3200),
}
DEFAULT_SWEEP = (50, 100, 200, 400, 800, 1600, 3200, 6400)


def controlled(model: Any, cycles: int, rtol: float) -> Any:
    return ba.run(
        model, cycles=cycles, rtol=rtol, dt="auto", method="generalized-alpha", output_every=1e-3
    )[0]


def model_rows(name: str, cycles: int, rtols: tuple[float, ...], ref: int) -> list[str]:
    model = ba.load(name)
    period = model.period or 1.0
    reference = ba.run(
        model,
        cycles=cycles,
        dt=period / ref,
        method="generalized-alpha",
        output_every=period / ba.REF_ROWS,
    )[0]
    fixed = []
    for n in SWEEPS.get(name, DEFAULT_SWEEP):
        res, cpu = ba.run(
            model, cycles=cycles, dt=period / n, method="generalized-alpha", output_every=1e-3
        )
        fixed.append((period / n, cpu, ba.errors(res, reference), 1e-3))
    rows = []
    for rtol in rtols:
        runs = [controlled(model, c, rtol) for c in range(1, cycles + 1)]
        counts = [r.settings["steps"] for r in runs]
        per_cycle = [counts[0]] + [b - a for a, b in itertools.pairwise(counts)]
        last = runs[-1]
        e = ba.errors(last, reference)
        eq = ba.sweep_interpolated(fixed, e)
        if eq:
            n_fixed = cycles * period / eq[0]
            ratio = f"{eq[0] * 1e3:.3g} ms, {n_fixed:.0f} | {counts[-1] / n_fixed:.2f}"
            phases = ba.phases(last, reference, eq[0])
        else:
            ratio, phases = "finer than the sweep | —", ""
        rows.append(
            f"| {name} | {rtol:g} | {' / '.join(map(str, per_cycle))} | "
            f"{last.settings['rejected_steps']} | {ba.fmt(e[0])} / {ba.fmt(e[1])} / "
            f"{ba.fmt(e[2])} | {ratio} | {phases} |"
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", nargs="+", default=["adan56", "paper-bifurcated"])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-2, 1e-3, 1e-4])
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--ref", type=int, default=64000, help="reference steps per cycle")
    a = ap.parse_args()
    print(
        "| model | rtol | accepted steps per cycle | rejected | error PP / flow / PO2 "
        "(last cycle) | fixed step of equal error, its steps | steps ÷ fixed | last cycle |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in a.models:
        for row in model_rows(name, a.cycles, tuple(a.rtols), a.ref):
            print(row, flush=True)


if __name__ == "__main__":
    main()
