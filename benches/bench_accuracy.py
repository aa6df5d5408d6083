"""Accuracy on demand: error-controlled runs (``rtol``) against a converged reference, and
their CPU time against the cheapest fixed step reaching the same error (docs/physics.md §10,
"Accuracy").

For each model: a reference run (generalized-α at a fixed step 20× below the finest of the
sweep), then for rtol 1e-2, 1e-3, 1e-4 one error-controlled run per output interval (1, 5,
10, 20 ms) and a sweep of fixed generalized-α steps (T/50 … T/3200, output every 1 ms). All
runs: the same cycles from the same start, the last cycle compared at the output times.

Errors (all relative, maximum over the output vessels):

* pulse pressure: |PP − PP_ref| / PP_ref of pressure_in per vessel (PP = max − min over the
  last cycle at the output times; the reference sampled at the same times);
* flow: max_t |Q − Q_ref| / max_t |Q_ref| of flow_in per vessel;
* PO2: max_t |PO2 − PO2_ref| / PO2_ref of po2_out (models with oxygen).

CPU: ``time.process_time`` of the ``simulate`` call (loading excluded). "fixed match": the
cheapest fixed step of the sweep whose three errors are all at most the error-controlled
run's (at 1 ms output), and the CPU ratio of the error-controlled run to it.

    python benches/bench_accuracy.py                     # adan56, paper-bifurcated
    python benches/bench_accuracy.py --models adan56 --cycles 2
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import numpy as np

import oxyline

OUTPUTS = (1e-3, 5e-3, 10e-3, 20e-3)
RTOLS = (1e-2, 1e-3, 1e-4)
SWEEP = (50, 100, 200, 400, 800, 1600, 3200)  # fixed steps per cycle


def run(model: Any, **kw: Any) -> tuple[Any, float]:
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = oxyline.simulate(model, progress=False, **kw)
    return res, time.process_time() - t0


def at(ref: Any, key: str, t: np.ndarray) -> np.ndarray:
    """The reference's ``key`` at times ``t`` (linear between its rows every T/3200: an
    interpolation error ~(T/3200)²|y''|/8, ~3e-5 of a 10 Hz harmonic's amplitude)."""
    a = getattr(ref, key)
    return np.column_stack([np.interp(t, ref.time, a[:, j]) for j in range(a.shape[1])])


def errors(res: Any, ref: Any) -> tuple[float, float, float]:
    """(pulse pressure, flow, PO2) errors of ``res`` against ``ref`` at ``res``'s times."""
    t = res.time
    p, pr = res.pressure_in, at(ref, "pressure_in", t)
    pp, ppr = p.max(0) - p.min(0), pr.max(0) - pr.min(0)
    e_pp = float(np.max(np.abs(pp - ppr) / ppr))
    q, qr = res.flow_in, at(ref, "flow_in", t)
    e_q = float(np.max(np.max(np.abs(q - qr), 0) / np.max(np.abs(qr), 0)))
    e_o2 = float("nan")
    if res.oxygen is not None:
        o, orf = res.po2_out, at(ref, "po2_out", t)
        e_o2 = float(np.max(np.abs(o - orf) / orf))
    return e_pp, e_q, e_o2


def fmt(e: float) -> str:
    return "—" if np.isnan(e) else f"{100 * e:.3g} %"


def bench(name: str, cycles: int, rtols: tuple[float, ...], outputs: tuple[float, ...]) -> None:
    model = oxyline.load_model(name)
    period = model.period or 1.0
    ref_dt = period / (20 * SWEEP[-1])
    ref, ref_cpu = run(model, cycles=cycles, dt=ref_dt, method="generalized-alpha",
                       output_every=period / SWEEP[-1])
    print(f"\n### {name} ({cycles} cycles; reference: generalized-α dt = {ref_dt:.2e} s, "
          f"{ref_cpu:.1f} s CPU)\n")
    fixed = []
    for n in SWEEP:
        res, cpu = run(model, cycles=cycles, dt=period / n, method="generalized-alpha",
                       output_every=1e-3)
        fixed.append((period / n, cpu, errors(res, ref)))
    print("| fixed generalized-α dt | pulse pressure | flow | PO2 | CPU |")
    print("|---|---|---|---|---|")
    for dt, cpu, (a, b, c) in fixed:
        print(f"| {dt * 1e3:.3g} ms | {fmt(a)} | {fmt(b)} | {fmt(c)} | {cpu:.3f} s |")
    print("\n| rtol | output | pulse pressure | flow | PO2 | estimate (p / q / species) | "
          "steps (rejected) | dt range | CPU | fixed match (dt, CPU) | CPU ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for rtol in rtols:
        for every in outputs:
            res, cpu = run(model, cycles=cycles, rtol=rtol, output_every=every)
            e = errors(res, ref)
            s, est = res.settings, res.error_estimate
            match = ""
            if every == outputs[0]:
                ok = [(c, dt) for dt, c, f in fixed
                      if all(np.isnan(x) or x <= y for x, y in zip(f, e, strict=True))]
                if ok:
                    c, dt = min(ok)
                    match = f"| {dt * 1e3:.3g} ms, {c:.3f} s | {cpu / c:.2f} |"
                else:
                    match = "| none of the sweep | — |"
            else:
                match = "| | |"
            est_s = " / ".join(f"{est.get(k, float('nan')):.1e}"
                               for k in ("pressure", "flow", "species"))
            print(f"| {rtol:g} | {every * 1e3:g} ms | {fmt(e[0])} | {fmt(e[1])} | {fmt(e[2])} "
                  f"| {est_s} | {s['steps']} ({s['rejected_steps']}) | "
                  f"{s['dt_min'] * 1e3:.2g}–{s['dt_max'] * 1e3:.2g} ms | {cpu:.3f} s {match}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", nargs="+", default=["adan56", "paper-bifurcated"])
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--rtols", type=float, nargs="+", default=list(RTOLS))
    ap.add_argument("--outputs", type=float, nargs="+", default=list(OUTPUTS),
                    help="output intervals in s (the first is compared with the sweep)")
    a = ap.parse_args()
    for name in a.models:
        bench(name, a.cycles, tuple(a.rtols), tuple(a.outputs))


if __name__ == "__main__":
    main()
