"""The explicit pair (``dopri5``) against generalized-α on the closed-loop heart circuits, both
error-controlled with their valve events located (docs/physics.md §10.4, "Valves"; §10.5), at
rtol 1e-2, 1e-3 and 1e-4, and which of the two ``method: auto`` runs.

Models: svZeroDSolver's ``closedLoopHeart_singleVessel`` (its fixed ``dt`` dropped) and the
heart circuit of ``closed-loop-o2`` (its fixed ``dt`` dropped; the pair refuses it, see the
table's note). For each: a reference (generalized-α at the fixed step T/``--reference-steps``,
the same cycles from the same start, rows every T/1000), then one run per method and rtol
with rows at the same times. Errors over every row of every cycle, the largest over the
vessels: pressure max|P − P_ref| / range(P_ref) and flow max|Q − Q_ref| / range(Q_ref)
(``pressure_in``, ``flow_in``), the cardiac output (mean flow of the last cycle through the
vessel after the heart) relative to the reference's, and the largest event-time error
against the reference's switches (each valve's status flips at the reference's rows; the
same number of events in the same order, else "count differs"). CPU: ``time.process_time``
of the ``simulate`` call, the least of ``--repeat`` runs (same process, same run).

    python benches/bench_valve_pair.py [--cycles 3] [--repeat 3] [--reference-steps 40000]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import oxyline
from oxyline import closed_loop
from oxyline import svzerod as svz
from oxyline.model import build_model

ROOT = Path(__file__).resolve().parent.parent
SINGLE = ROOT / "tests" / "data" / "svzerod" / "cases" / "closedLoopHeart_singleVessel.json"
RTOLS = (1e-2, 1e-3, 1e-4)
METHODS = ("generalized-alpha", "dopri5", "auto")
#: the vessel after the heart (its mean flow is the cardiac output)
OUTFLOW = {"closedLoopHeart_singleVessel": "branch0_seg0", "closed-loop-o2 heart": "arteries"}


def models() -> dict[str, Any]:
    """The two circuits, fixed steps dropped."""
    single = svz.to_oxyline_dict(str(SINGLE))
    single["simulation"].pop("dt", None)
    heart = closed_loop.heart_model(closed_loop.load("closed-loop-o2"))
    heart["simulation"].pop("dt", None)
    return {"closedLoopHeart_singleVessel": oxyline.load_model(single),
            "closed-loop-o2 heart": build_model(heart)}


def run(model: Any, repeat: int, **kw: Any) -> tuple[Any, float]:
    """The result and the least process time of `repeat` runs."""
    best, res = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = oxyline.simulate(model, progress=False, until_periodic=None,
                                   output_cycles="all", **kw)
        best = min(best, time.process_time() - t0)
    return res, best


def flips(res: Any, after: float) -> dict[str, list[tuple[float, bool]]]:
    """Each valve's status changes read from the rows' statuses later than `after` (time of
    the first row with the new status, opened); a switch of the start itself is the first
    step's reading, not an event."""
    out = {}
    for name, st in res.valve_status.items():
        st = np.asarray(st).astype(int)
        at = np.nonzero(np.diff(st))[0] + 1
        out[name] = [(float(res.time[i]), bool(st[i])) for i in at if res.time[i] > after]
    return out


def event_error(res: Any, ref_flips: dict[str, list[tuple[float, bool]]]) -> str:
    """The largest |t − t_ref| over the run's events after the start, "count differs" where
    a valve's events are not the reference's switches in kind and order."""
    worst = 0.0
    for name, want in ref_flips.items():
        got = [(t, o) for t, v, o in res.valve_events if v == name and t > START]
        if [o for _, o in got] != [o for _, o in want]:
            n_ref = sum(map(len, ref_flips.values()))
            n = sum(1 for t, _, _ in res.valve_events if t > START)
            return f"count differs ({n} vs {n_ref})"
        worst = max([worst] + [abs(a - b) for (a, _), (b, _) in zip(got, want, strict=True)])
    return f"{worst:.1e}"


def errors(res: Any, ref: Any, outflow: str, period: float) -> tuple[float, ...]:
    """(pressure, flow, the heart's own inflow, cardiac output) errors of `res` against
    `ref` at `res`'s rows (each one of the reference's). The flow error leaves out a heart
    block's inflow (its `flow_in`), given apart: on closed-loop-o2's circuit it is the
    flow into the right atrium's node, which the veins' capacitance shares (an index-2
    unknown: generalized-α's rows of it scatter)."""
    rows = np.searchsorted(ref.time, res.time - 1e-12)
    assert np.allclose(ref.time[rows], res.time, atol=1e-9), "row times differ"
    heart = [i for i, v in enumerate(res.vessels) if v in HEARTS]
    others = [i for i in range(len(res.vessels)) if i not in heart]

    def err(a: np.ndarray, e: np.ndarray) -> float:
        return float(np.max(np.max(np.abs(a - e), 0) / np.maximum(np.ptp(e, 0), 1e-300)))

    p, q = ref.pressure_in[rows], ref.flow_in[rows]
    e_p = err(res.pressure_in, p)
    e_q = err(res.flow_in[:, others], q[:, others])
    e_in = err(res.flow_in[:, heart], q[:, heart]) if heart else float("nan")

    def co(r: Any, k: np.ndarray | slice) -> float:
        t, qv = np.asarray(r.time)[k], np.asarray(r.vessel(outflow).flow_in)[k]
        last = t >= t[-1] - period * (1 + 1e-9)
        return float(np.trapezoid(qv[last], t[last]) / (t[last][-1] - t[last][0]))

    want = co(ref, rows)
    return e_p, e_q, e_in, abs(co(res, slice(None)) - want) / abs(want)


#: switches before this time (s) are the start's reading of the valves (a status the start
#: state's pressures and flows give, read at the first step), not events
START = 1e-3

#: the heart blocks' vessel names in the two models
HEARTS = ("CLH", "heart_pulmonary")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--reference-steps", type=int, default=40000)
    a = ap.parse_args()
    print("| model | rtol | method (auto ran) | steps (rejected) | CPU s | pressure | flow "
          "| heart inflow | cardiac output | event time s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, model in models().items():
        period = float(model.period)
        dt = period / a.reference_steps
        ref, ref_cpu = run(model, 1, cycles=a.cycles, method="generalized-alpha", dt=dt,
                           output_every=dt)
        ref_flips = flips(ref, after=START)
        print(f"| {name} | reference | generalized-α, T/{a.reference_steps} | "
              f"{a.cycles * a.reference_steps} | {ref_cpu:.2f} | | | | | |")
        for rtol in RTOLS:
            for method in METHODS:
                try:
                    res, cpu = run(model, a.repeat, rtol=rtol, method=method,
                                   cycles=a.cycles, output_every=period / 1000)
                except oxyline.ModelError as e:
                    print(f"| {name} | {rtol:g} | {method} | refused: {str(e)[:90]} "
                          "| | | | | | |")
                    continue
                ran = res.settings["method"]
                label = method if method != "auto" else f"auto ({ran})"
                e_p, e_q, e_in, e_co = errors(res, ref, OUTFLOW[name], period)
                ev = event_error(res, ref_flips)
                print(f"| {name} | {rtol:g} | {label} | {res.settings['steps']} "
                      f"({res.settings['rejected_steps']}) | {cpu:.3f} | {e_p:.1e} | {e_q:.1e} "
                      f"| {e_in:.1e} | {e_co:.1e} | {ev} |", flush=True)


if __name__ == "__main__":
    main()
