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
run's (at 1 ms output), and the CPU ratio of the error-controlled run to it, the
error-controlled run writing its rows as often as that fixed step did (its solution does not
depend on the output interval; a fixed step writes a row per step at most). "ratio,
interpolated": the run's CPU (rows every 1 ms, or every that step if longer) over the fixed
step's CPU interpolated in the sweep at equal error (log-log, the binding error kind; the
sweep's factor-2 steps otherwise make the ratio jump with the side of a sweep step an error
falls on). All runs take
exactly ``cycles`` cycles (``until_periodic=None``).

Methods (``--methods``): the error-controlled runs of each rtol with generalized-α, the explicit
pair (``dopri5``, Dormand–Prince 5(4); a circuit with valves refuses it) and ``auto`` (which
picks one of the two by predicted cost; the table names the one it ran).

    python benches/bench_accuracy.py                     # the whole benchmark set
    python benches/bench_accuracy.py --models adan56 --cycles 2
    python benches/bench_accuracy.py --repeat 3          # least CPU of 3 runs each

``--default-table``: the default run (``simulate(model, output_every=...)``, no ``dt`` or
``rtol``: error control at rtol 1e-3) at output intervals 1, 5, 10, 20 ms beside the previous
default (a fixed step chosen from the output interval: RK4 at half its stable step when that
is at least 1/20 of the output interval, else generalized-α with dt = the output interval;
reproduced here by that rule on the model's RK4 stability limit, exact for a linear model
without transport), each against generalized-α at dt = 0.1 ms, in the same run:

    python benches/bench_accuracy.py --default-table --models adan56 --repeat 3
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import numpy as np

import oxyline

MODELS = ("adan56", "whole-body-140", "circle-of-willis", "paper-bifurcated", "closed-loop-o2",
          "tree-1e5-o2", "adan56-st")
OUTPUTS = (1e-3, 5e-3, 10e-3, 20e-3)
RTOLS = (1e-2, 1e-3, 1e-4)
METHODS = ("generalized-alpha", "dopri5", "auto")
SWEEP = (50, 100, 200, 400, 800, 1600, 3200, 6400)  # fixed steps per cycle
REF_ROWS = 32000  # reference rows per cycle: every output time of the runs is one of them


def load(name: str) -> Any:
    """A model of the benchmark set: a catalogue name; ``closed-loop-o2`` (its closed-loop
    heart circuit: chambers and valves, what its O2 run is driven by); ``tree-1e5-o2`` (the
    scale bench's binary tree of 2^14 − 1 vessels × 6 segments ≈ 1e5 segments, O2 by a
    mass-transfer wall)."""
    if name == "closed-loop-o2":
        from oxyline import closed_loop
        from oxyline.model import build_model
        return build_model(closed_loop.heart_model(closed_loop.load(name)))
    if name == "tree-1e5-o2":
        import sys
        from pathlib import Path
        sys.path.insert(0, str(Path(__file__).parent))
        import bench_scale
        return oxyline.load_model(bench_scale.tree(14, 6, "o2-k"))
    return oxyline.load_model(name)


#: the step-size history lines of the summary (`phases`), one per error-controlled run matched
#: with the sweep
STEP_HISTORY: list[str] = []

#: the rows of the `--time-error` table's runs at `rtol_to_meet()`
MEET: list[str] = []

REPEAT = [1]  # runs per timing (``--repeat``): the least CPU of them is reported


def run(model: Any, **kw: Any) -> tuple[Any, float]:
    """The result and the least process time of ``REPEAT[0]`` runs (a loaded machine only
    adds time)."""
    best = float("inf")
    for _ in range(REPEAT[0]):
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = oxyline.simulate(model, progress=False, until_periodic=None, **kw)
        best = min(best, time.process_time() - t0)
    return res, best


def at(ref: Any, key: str, t: np.ndarray) -> np.ndarray:
    """The reference's ``key`` at times ``t``: its rows every T/32000 hold every output time of
    the runs (T/n for n dividing 32000: 1, 5, 10, 20 ms at T = 1 s, the sweep's steps), so the
    interpolation is exact there (elsewhere linear: ~(T/32000)²|y''|/8, 3e-5 of a 100 Hz
    component)."""
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


def per_vessel(res: Any, ref: Any) -> dict[str, np.ndarray]:
    """Every output vessel's error per kind against that vessel's own scale, at ``res``'s
    times: flow max_t |Q − Q_ref| / max_t |Q_ref| (``flow_in``), pressure max_t |P − P_ref| /
    max_t |P_ref| and its pulse pressure |PP − PP_ref| / PP_ref (``pressure_in``), PO2
    max_t |PO2 − PO2_ref| / max_t PO2_ref (``po2_out``, models with oxygen)."""
    t = res.time
    q, qr = res.flow_in, at(ref, "flow_in", t)
    p, pr = res.pressure_in, at(ref, "pressure_in", t)
    pp, ppr = p.max(0) - p.min(0), pr.max(0) - pr.min(0)
    out = {"flow": np.max(np.abs(q - qr), 0) / np.max(np.abs(qr), 0),
           "flow_scale": np.max(np.abs(qr), 0),
           "pressure": np.max(np.abs(p - pr), 0) / np.max(np.abs(pr), 0),
           "pulse": np.abs(pp - ppr) / ppr}
    if res.oxygen is not None:
        o, orf = res.po2_out, at(ref, "po2_out", t)
        out["po2"] = np.max(np.abs(o - orf), 0) / np.max(np.abs(orf), 0)
    return out


def vessel_table(name: str, cycles: int, rtols: tuple[float, ...], ref_steps: int,
                 method: str) -> None:
    """The worst vessel's error per kind against its own scale (``per_vessel``), in units of
    rtol, with the run's steps and CPU, per rtol (``--vessel-table``)."""
    model = load(name)
    period = model.period or 1.0
    rows = REF_ROWS if ref_steps % REF_ROWS == 0 else ref_steps
    ref, ref_cpu = run(model, cycles=cycles, dt=period / ref_steps, method="generalized-alpha",
                       output_every=period / rows)
    print(f"\n### {name}: worst vessel against its own scale ({cycles} cycles, {method}; "
          f"reference generalized-α dt = T/{ref_steps}, {ref_cpu:.1f} s CPU)\n")
    print("| rtol | steps (rejected) | CPU | flow: worst (vessel, its share of the largest "
          "amplitude), median | pressure vs its peak | pulse pressure | PO2 | estimate "
          "(p / q / species) |")
    print("|---|---|---|---|---|---|---|---|")
    for rtol in rtols:
        res, cpu = run(model, cycles=cycles, rtol=rtol, dt="auto", method=method,
                       output_every=1e-3)
        e, s, est = per_vessel(res, ref), res.settings, res.error_estimate
        k = int(np.argmax(e["flow"]))
        share = e["flow_scale"][k] / e["flow_scale"].max()
        po2 = f"{np.max(e['po2']) / rtol:.2g}" if "po2" in e else "—"
        est_s = " / ".join(f"{est.get(x, float('nan')) / rtol:.2g}"
                           for x in ("pressure", "flow", "species"))
        print(f"| {rtol:g} | {s['steps']} ({s['rejected_steps']}) | {cpu:.3f} s | "
              f"{e['flow'][k] / rtol:.3g} ({res.vessels[k]}, {share:.1e}), "
              f"{np.median(e['flow']) / rtol:.2g} | {np.max(e['pressure']) / rtol:.3g} | "
              f"{np.max(e['pulse']) / rtol:.3g} | {po2} | {est_s} |")


def phases(res: Any, ref: Any, dt_eq: float) -> str:
    """Where the last cycle's accepted steps (``Result.step_times``/``step_sizes``) are larger
    than the fixed step of equal error ``dt_eq``: per phase, the share of the phase's time
    covered by such steps and the phase's mean step. Systole: where the model's inlet
    vessel's reference inflow (``flow_in`` of the first vessel) is above its cycle mean;
    diastole: the rest."""
    h, t0 = res.step_sizes, res.step_times
    if h.size == 0:
        return "no step history"
    period = float(np.sum(h))
    # the reference's last cycle (its rows run over every cycle), time into that cycle
    tr = ref.time - (ref.time[-1] - period)
    keep = tr >= -1e-12
    q = ref.flow_in[keep, 0]
    systole = np.interp(t0 + 0.5 * h, tr[keep], (q > q.mean()).astype(float)) > 0.5
    parts = []
    for label, sel in (("systole", systole), ("diastole", ~systole)):
        span = float(np.sum(h[sel]))
        if span <= 0:
            continue
        larger = float(np.sum(h[sel & (h > dt_eq)])) / span
        parts.append(f"{label} {100 * larger:.0f} % of {span * 1e3:.0f} ms "
                     f"(mean step {span / max(int(np.sum(sel)), 1) * 1e3:.2g} ms)")
    return f"steps > {dt_eq * 1e3:.3g} ms: " + ", ".join(parts)


def time_error_table(name: str, cycles: int, rtols: tuple[float, ...], ref_steps: int,
                     method: str) -> None:
    """The worst vessel's achieved error per kind (``per_vessel``) beside what the run reports
    (the step control's ``error_estimate``, a local target) and ``estimate_time_error``'s
    estimate from a second run at rtol/4, in units of rtol, with both runs' CPU
    (``--time-error``)."""
    model = load(name)
    period = model.period or 1.0
    rows = REF_ROWS if ref_steps % REF_ROWS == 0 else ref_steps
    ref, ref_cpu = run(model, cycles=cycles, dt=period / ref_steps, method="generalized-alpha",
                       output_every=period / rows)
    print(f"\n### {name}: achieved error against the reported ones ({cycles} cycles, {method}; "
          f"reference generalized-α dt = T/{ref_steps}, {ref_cpu:.1f} s CPU), in units of "
          "rtol\n")
    print("| rtol | flow: achieved (vessel) / step control's estimate / estimate_time_error | "
          "pressure vs its peak: the three | pulse pressure: achieved / estimate_time_error | "
          "PO2: achieved / estimate_time_error | CPU: the run / the estimate's second run |")
    print("|---|---|---|---|---|---|")
    for rtol in rtols:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.process_time()
            est = oxyline.estimate_time_error(model, rtol=rtol, cycles=cycles,
                                              until_periodic=None, method=method,
                                              output_every=1e-3, progress=False)
            cpu_both = time.process_time() - t0
        t0 = time.process_time()
        run(model, cycles=cycles, rtol=rtol, dt="auto", method=method, output_every=1e-3)
        cpu = time.process_time() - t0
        e, rep, w = per_vessel(est.result, ref), est.result.error_estimate, est.worst
        k = int(np.argmax(e["flow"]))
        po2 = (f"{np.max(e['po2']) / rtol:.2g} / {w['po2'][0] / rtol:.2g}" if "po2" in e
               else "—")
        # the run at the rtol estimated to meet rtol in every vessel, and its achieved error
        r_meet = est.rtol_to_meet()
        met, cpu_met = run(model, cycles=cycles, rtol=r_meet, dt="auto", method=method,
                           output_every=1e-3)
        em = per_vessel(met, ref)
        worst_met = max(float(np.max(em[x])) for x in ("flow", "pressure", "pulse", "po2")
                        if x in em)
        MEET.append(f"| {name} | {rtol:g} | {r_meet:.2g} | {met.settings['steps']} "
                    f"({est.result.settings['steps']} at rtol) | {worst_met / rtol:.2f} "
                    f"(flow {np.max(em['flow']) / rtol:.2f}, pulse pressure "
                    f"{np.max(em['pulse']) / rtol:.2f}) | {cpu_met:.2f} s ({cpu:.2f} s at "
                    f"rtol) |")
        print(f"| {rtol:g} | {e['flow'][k] / rtol:.3g} ({est.result.vessels[k]}) / "
              f"{rep['flow'] / rtol:.2g} / {w['flow'][0] / rtol:.3g} | "
              f"{np.max(e['pressure']) / rtol:.3g} / {rep['pressure'] / rtol:.2g} / "
              f"{w['pressure'][0] / rtol:.3g} | {np.max(e['pulse']) / rtol:.3g} / "
              f"{w['pulse_pressure'][0] / rtol:.3g} | {po2} | {cpu:.2f} s / "
              f"{max(cpu_both - cpu, 0.0):.2f} s |")


def in_run_table(name: str, cycles: int, rtols: tuple[float, ...], ref_steps: int,
                 method: str) -> None:
    """``simulate(..., estimate_time_error=True)`` (the last cycle again at rtol/4) against
    the achieved error and ``estimate_time_error``'s two whole runs, per kind's worst vessel
    in units of rtol, each vessel's estimate over its achieved error (vessels within 0.3x of
    the worst), the steps and the CPU of the run with the estimate over the run alone; then
    ``meet_rtol`` (``--in-run``)."""
    import pandas  # noqa: F401  (Result.time_error's import, outside the timings)

    model = load(name)
    period = model.period or 1.0
    rows = REF_ROWS if ref_steps % REF_ROWS == 0 else ref_steps
    ref, _ = run(model, cycles=cycles, dt=period / ref_steps, method="generalized-alpha",
                 output_every=period / rows)
    kw = {"cycles": cycles, "method": method, "output_every": 1e-3}
    print(f"\n### {name}: the accumulated error within one run ({cycles} cycles, {method}; "
          f"reference generalized-α dt = T/{ref_steps}), in units of rtol\n")
    print("| rtol | flow: achieved / in the run / two runs | per vessel | pressure: the three | "
          "pulse pressure: the three | PO2: the three | steps: run / second | CPU ratio | "
          "meet_rtol: runs, rtol run, steps ratio, CPU ratio, achieved worst |")
    print("|---|---|---|---|---|---|---|---|---|")
    for rtol in rtols:
        plain, cpu = run(model, rtol=rtol, **kw)
        res, cpu_est = run(model, rtol=rtol, estimate_time_error=True, **kw)
        two = oxyline.estimate_time_error(model, rtol=rtol, until_periodic=None,
                                          progress=False, **kw)
        met, cpu_met = run(model, rtol=rtol, meet_rtol=True, **kw)
        e, em = per_vessel(res, ref), per_vessel(met, ref)
        cells = []
        for kind, key in (("flow", "flow"), ("pressure", "pressure"),
                          ("pulse_pressure", "pulse"), ("po2", "po2")):
            if key not in e:
                cells.append("—")
                continue
            cells.append(f"{np.max(e[key]) / rtol:.3g} / {res.error_estimate[kind] / rtol:.3g}"
                         f" / {two.worst[kind][0] / rtol:.3g}")
        big = e["flow"] > 0.3 * np.max(e["flow"])
        ratio = res.time_error["flow"].to_numpy()[big] / e["flow"][big]
        worst_met = max(float(np.max(em[k])) for k in ("flow", "pressure", "pulse", "po2")
                        if k in em)
        ms = met.settings
        print(f"| {rtol:g} | {cells[0]} | {ratio.min():.2f}–{ratio.max():.2f} | {cells[1]} | "
              f"{cells[2]} | {cells[3]} | {res.settings['steps']} / "
              f"{res.settings['time_error_steps']} | {cpu_est / cpu:.2f} | "
              f"{ms['meet_rtol_runs']}, {ms['rtol']:.2g}, "
              f"{ms['meet_rtol_steps'] / plain.settings['steps']:.1f}, {cpu_met / cpu:.1f}, "
              f"{worst_met / rtol:.2f} |")
        assert np.array_equal(plain.data, res.data)  # the estimate leaves the run as it was


def fmt(e: float) -> str:
    return "—" if np.isnan(e) else f"{100 * e:.3g} %"


def sweep_match(fixed: list[Any], e: tuple[float, float, float]
                ) -> tuple[float, float, float] | None:
    """(CPU, dt, output spacing) of the cheapest fixed step of the sweep whose three errors are all at most
    ``e``'s (PO2 ignored where the model has none)."""
    ok = [(c, dt, every) for dt, c, f, every in fixed
          if all(np.isnan(x) or x <= y for x, y in zip(f, e, strict=True))]
    return min(ok) if ok else None


def loglog(x: float, x0: float, x1: float, y0: float, y1: float) -> float:
    """y at x on the straight line through (x0, y0), (x1, y1) in log-log."""
    if x1 == x0 or min(x0, x1, y0, y1) <= 0:
        return y0
    f = np.log(x / x0) / np.log(x1 / x0)
    return float(np.exp(np.log(y0) + f * np.log(y1 / y0)))


def sweep_interpolated(fixed: list[Any], e: tuple[float, float, float]
                       ) -> tuple[float, float] | None:
    """The fixed step's CPU at equal error, interpolated in the sweep: per error kind the
    largest dt whose error is ``e``'s (log-log between the two sweep steps around it, every
    finer step of the sweep within it), the smallest of these dt, and the CPU there (log-log
    between its neighbours): (dt, CPU). None when ``e`` is below the finest step's error."""
    runs = sorted(fixed, key=lambda r: r[0])
    dts = [r[0] for r in runs]
    dt_eq = dts[-1]
    for k, target in enumerate(e):
        errs = [r[2][k] for r in runs]
        if np.isnan(target) or np.isnan(errs[0]):
            continue
        if errs[0] > target:
            return None
        j = 0
        while j + 1 < len(runs) and errs[j + 1] <= target:
            j += 1
        dt_k = dts[j] if j + 1 == len(runs) else loglog(target, errs[j], errs[j + 1],
                                                          dts[j], dts[j + 1])
        dt_eq = min(dt_eq, dt_k)
    i = max(0, min(int(np.searchsorted(dts, dt_eq)) - 1, len(runs) - 2))
    return dt_eq, loglog(dt_eq, dts[i], dts[i + 1], runs[i][1], runs[i + 1][1])


def bench(name: str, cycles: int, rtols: tuple[float, ...], outputs: tuple[float, ...],
          sweep: tuple[int, ...], ref_factor: int, summary: list[str],
          methods: tuple[str, ...] = METHODS) -> None:
    model = load(name)
    period = model.period or 1.0
    ref_dt = period / (ref_factor * sweep[-1])
    n_ref = ref_factor * sweep[-1]
    rows = REF_ROWS if n_ref % REF_ROWS == 0 else n_ref  # a row per step if not a multiple
    ref, ref_cpu = run(model, cycles=cycles, dt=ref_dt, method="generalized-alpha",
                       output_every=period / rows)
    print(f"\n### {name} ({cycles} cycles; reference: generalized-α dt = {ref_dt:.2e} s, "
          f"{ref_cpu:.1f} s CPU)\n")
    fixed = []
    for n in sweep:
        res, cpu = run(model, cycles=cycles, dt=period / n, method="generalized-alpha",
                       output_every=1e-3)
        fixed.append((period / n, cpu, errors(res, ref), float(res.time[1] - res.time[0])))
    print("| fixed generalized-α dt | pulse pressure | flow | PO2 | CPU |")
    print("|---|---|---|---|---|")
    for dt, cpu, (a, b, c), _ in fixed:
        print(f"| {dt * 1e3:.3g} ms | {fmt(a)} | {fmt(b)} | {fmt(c)} | {cpu:.3f} s |")
    print("\n| rtol | method (ran) | output | pulse pressure | flow | PO2 | estimate (p / q / "
          "species) | steps (rejected) | dt range | CPU | fixed match (dt, CPU) | "
          "CPU ratio at its output |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for rtol in rtols:
        for method in methods:
            controlled(model, name, cycles, rtol, method, outputs, ref, fixed, summary)


def controlled(model: Any, name: str, cycles: int, rtol: float, method: str,
           outputs: tuple[float, ...], ref: Any, fixed: list[Any], summary: list[str]
           ) -> None:
    """The rows of one rtol and method: a run per output interval, the first matched with
    the fixed sweep."""
    kw = {"cycles": cycles, "rtol": rtol, "dt": "auto", "method": method}
    for every in outputs:
        try:
            res, cpu = run(model, output_every=every, **kw)
        except oxyline.ModelError as err:
            print(f"| {rtol:g} | {method} (refused: {err}) |")
            return
        e = errors(res, ref)
        ran = f"{method} ({res.settings['method']})"
        s, est = res.settings, res.error_estimate
        match = "| | |"
        if every == outputs[0]:
            m = sweep_match(fixed, e)
            # the ratio at equal output: the same error-controlled run (output never
            # changes its solution) writing rows as often as the matched fixed step did
            # (a fixed step of 20 ms writes 50 rows a cycle, not 1000)
            cpu_eq = run(model, output_every=m[2], **kw)[1] if m else 0
            match = (f"| {m[1] * 1e3:.3g} ms, {m[0]:.3f} s | {cpu_eq / m[0]:.2f} |" if m
                     else "| none of the sweep | — |")
            ratio = f"{cpu_eq / m[0]:.2f}" if m else "— (finer than the sweep)"
            # the sweep's steps are a factor 2 apart: the ratio to the CPU interpolated at
            # equal error does not jump with which side of a sweep step an error falls
            eq = sweep_interpolated(fixed, e)
            ratio_i = "—"
            if eq:
                # rows as often as that fixed step writes them (1 ms, or a row per step)
                every_eq = max(eq[0], outputs[0])
                cpu_i = cpu if every_eq == outputs[0] else run(model, output_every=every_eq,
                                                                **kw)[1]
                ratio_i = f"{cpu_i / eq[1]:.2f}"
            if eq:
                STEP_HISTORY.append(f"| {name} | rtol {rtol:g}, {ran} | "
                                  f"{phases(res, ref, eq[0])} |")
            summary.append(f"| {name} | rtol {rtol:g}, {ran} | {fmt(e[0])} / {fmt(e[1])} / "
                           f"{fmt(e[2])} | {s['steps']} | {cpu:.3f} s ({cpu_eq:.3f} s) | "
                           f"{f'{m[1] * 1e3:.3g} ms, {m[0]:.3f} s' if m else '—'} "
                           f"| {ratio} | {ratio_i} |")
        est_s = " / ".join(f"{est.get(k, float('nan')):.1e}"
                           for k in ("pressure", "flow", "species"))
        print(f"| {rtol:g} | {ran} | {every * 1e3:g} ms | {fmt(e[0])} | {fmt(e[1])} | {fmt(e[2])} "
              f"| {est_s} | {s['steps']} ({s['rejected_steps']}) | "
              f"{s['dt_min'] * 1e3:.2g}–{s['dt_max'] * 1e3:.2g} ms | {cpu:.3f} s {match}")


def old_default(model: Any, every: float) -> dict[str, Any]:
    """The settings that reproduce the previous default's fixed step at output interval
    ``every``: RK4's automatic step when half its stable step is at least every/20, else
    generalized-α at dt = every."""
    half = 0.5 * model.summary()["rk4_dt_max"]
    if half >= every / 20:
        return {"method": "rk4"}
    return {"method": "generalized-alpha", "dt": every}


def default_table(name: str, cycles: int, outputs: tuple[float, ...], ref_dt: float) -> None:
    """The default run against the previous default, per output interval (module text)."""
    model = load(name)
    period = model.period or 1.0
    ref, ref_cpu = run(model, cycles=cycles, dt=ref_dt, method="generalized-alpha",
                       output_every=ref_dt)
    print(f"\n### {name}: the default run ({cycles} cycles; reference generalized-α dt = "
          f"{ref_dt * 1e3:g} ms, {ref_cpu:.2f} s CPU)\n")
    print("| output every | default | method, steps | pulse-pressure error | flow error | "
          "CPU |")
    print("|---|---|---|---|---|---|")
    for every in outputs:
        for label, kw in (("previous (fixed)", old_default(model, every)),
                          ("new (rtol 1e-3)", {})):
            res, cpu = run(model, cycles=cycles, output_every=every, **kw)
            s = res.settings
            steps = s.get("steps") or round(cycles * period / s["dt"])
            how = (f"{s['method']}, {steps} steps ({s['rejected_steps']} rejected), "
                   f"dt {s['dt_min'] * 1e3:.2g}–{s['dt_max'] * 1e3:.2g} ms"
                   if s.get("steps") else f"{s['method']}, dt {s['dt']:.2g} s, {steps} steps")
            e = errors(res, ref)
            print(f"| {every * 1e3:g} ms | {label} | {how} | {fmt(e[0])} | {fmt(e[1])} | "
                  f"{cpu:.3f} s |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", nargs="+", default=list(MODELS))
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--rtols", type=float, nargs="+", default=list(RTOLS))
    ap.add_argument("--outputs", type=float, nargs="+", default=list(OUTPUTS),
                    help="output intervals in s (the first is compared with the sweep)")
    ap.add_argument("--sweep", type=int, nargs="+", default=list(SWEEP),
                    help="fixed steps per cycle of the sweep (the largest sets the reference)")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--ref-factor", type=int, default=20,
                    help="the reference step is the sweep's finest over this")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs per timing; the least CPU time is reported")
    ap.add_argument("--default-table", action="store_true",
                    help="only the default run against the previous default (module text)")
    ap.add_argument("--ref-dt", type=float, default=1e-4,
                    help="the reference step of --default-table, s")
    ap.add_argument("--vessel-table", action="store_true",
                    help="only the worst vessel's error per kind against its own scale, in "
                         "units of rtol (the first of --methods)")
    ap.add_argument("--in-run", action="store_true",
                    help="only simulate(..., estimate_time_error=True) and meet_rtol against "
                         "the achieved error and estimate_time_error's (the first of --methods)")
    ap.add_argument("--time-error", action="store_true",
                    help="only the achieved error against the step control's estimate and "
                         "estimate_time_error's, in units of rtol (the first of --methods)")
    a = ap.parse_args()
    REPEAT[0] = a.repeat
    if a.default_table:
        for name in a.models:
            default_table(name, a.cycles, tuple(a.outputs), a.ref_dt)
        return
    if a.vessel_table:
        for name in a.models:
            vessel_table(name, a.cycles, tuple(a.rtols), a.ref_factor * max(a.sweep),
                         a.methods[0])
        return
    if a.in_run:
        for name in a.models:
            in_run_table(name, a.cycles, tuple(a.rtols), a.ref_factor * max(a.sweep),
                         a.methods[0])
        return
    if a.time_error:
        for name in a.models:
            time_error_table(name, a.cycles, tuple(a.rtols), a.ref_factor * max(a.sweep),
                             a.methods[0])
        print("\n### Runs at `rtol_to_meet()`: the worst vessel's achieved error of every "
              "kind, in units of the rtol asked for\n")
        print("| model | rtol asked | rtol run | steps | achieved worst / rtol asked | CPU |")
        print("|---|---|---|---|---|---|")
        print("\n".join(MEET))
        return
    summary: list[str] = []
    for name in a.models:
        bench(name, a.cycles, tuple(a.rtols), tuple(a.outputs), tuple(sorted(a.sweep)),
              a.ref_factor, summary, tuple(a.methods))
    print("\n## Summary (errors: pulse pressure / flow / PO2; ratio: CPU of the "
          "error-controlled run over the cheapest fixed step of equal error)\n")
    print("| model | method | error vs reference | steps | CPU at 1 ms output (at the fixed "
          "step's) | cheapest fixed step of equal error (dt, CPU) | ratio | ratio, "
          "interpolated |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(summary))
    print("\n## Step-size history (the last cycle's accepted steps against the fixed step of "
          "equal error, interpolated in the sweep; systole: the inlet vessel's inflow above its "
          "cycle mean)\n")
    print("| model | method | where the steps are larger than the fixed step of equal error |")
    print("|---|---|---|")
    print("\n".join(STEP_HISTORY))


if __name__ == "__main__":
    main()
