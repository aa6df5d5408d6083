"""Time-varying coefficients, chambers, valves and closed loops: each
table times oxyline against svzerod 3.2 in the same run, interleaved (svzerod, oxyline
generalized-α, oxyline RK4, then again: every solver sees the same machine state), and reports
the best of ``--repeat`` (default 3) wall and CPU seconds of each with the accuracy.

* constant coefficients (``chain N`` / ``tree N`` of ``networks.py``, flow only, each timing in
  a fresh subprocess): svzerod, the drop-in (generalized-α) and the native RK4 run; the
  svzerod/oxyline ratio is the yardstick across builds and sessions (the element interface
  must not slow these down: earlier same-yardstick figures in benches/results.md).
  ``--baseline DIR`` adds another build of the ``oxyline`` package (e.g. a copy of an older
  ``python/`` with its ``_core.abi3.so``), interleaved too, for a direct before/after ratio;
* coronary (``pulsatileFlow_R_coronary(_varres)``): the drop-in against the stored reference,
  RK4 against svzerod 20x finer;
* chambers and valves (``valve_tanh``, ``chamber_elastance_inductor``,
  ``closedLoopHeart_singleVessel_decomposed``, ``chamber_sphere``): the drop-in against the
  stored reference, RK4 against svzerod 20x finer (``chamber_sphere``, which svzerod 3.2
  cannot run: against oxyline's generalized-α 400x finer, one RK4 run of ~1.6e6 steps);
* closed loops: svZeroDSolver's heart-block cases ``closedLoopHeart_singleVessel`` and
  ``closedLoopHeart_withCoronaries``, as stored (10 cycles of 100 steps) and lengthened (20
  cycles of 1000 steps), the drop-in against the stored reference and against svzerod with the
  same settings; the two ``coupledBlock_closedLoopHeart_*`` cases (coupling blocks with
  prescribed values) on the variables the drop-in outputs.

    python benches/bench_heart.py               # every table (a few minutes quiet)
    python benches/bench_heart.py --chambers    # the chamber/valve table only
    python benches/bench_heart.py --closed-loop # the closed-loop table only

Results print as Markdown, with the load average at the start and end of each table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
CASES = HERE.parent / "tests" / "data" / "svzerod" / "cases"
MARK = "@@BENCH@@"

CHILD = r'''
import json, sys, time
sys.path.insert(0, {here!r})
import networks, oxyline
import oxyline.svzerod as svz
what, n = {what!r}, {n!r}


def timed(f):
    t, c = time.perf_counter(), time.process_time()
    f()
    return time.perf_counter() - t, time.process_time() - c


nan = (float("nan"), float("nan"))
if {impl!r} == "svzerod":
    import svzerod
    cfg = networks.build(what, n)
    cold, warm, rk = timed(lambda: svzerod.simulate(cfg)), timed(lambda: svzerod.simulate(cfg)), nan
else:
    cfg = networks.build(what, n)
    # the first call of a process carries one-off costs (lazy imports, first allocations);
    # the second is the solver's own time
    cold, warm = timed(lambda: svz.simulate(cfg)), timed(lambda: svz.simulate(cfg))
    model = oxyline.load_model(cfg)
    rk = timed(lambda: oxyline.simulate(model, method="rk4", dt="auto", segments=False))
print({mark!r} + json.dumps({{"cold": cold, "ga": warm, "rk4": rk}}))
'''


def run_child(what: str, n: int | None, pythonpath: str | None,
              impl: str = "oxyline") -> dict[str, list[float]]:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    code = CHILD.format(here=str(HERE), what=what, n=n, cases=str(CASES), mark=MARK, impl=impl)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout
    return json.loads(out.split(MARK)[-1])


def interleaved(calls: dict[str, Callable[[], Any]], repeat: int
                ) -> dict[str, tuple[Any, float, float]]:
    """Every call ``repeat`` times in turn (a, b, c, a, b, c, ...), so that a drift of the
    machine's speed hits every solver alike and their ratios are same-run: per call its last
    output and its best (smallest) wall and CPU seconds."""
    best: dict[str, list[Any]] = {k: [None, math.inf, math.inf] for k in calls}
    for _ in range(repeat):
        for k, f in calls.items():
            t, c = time.perf_counter(), time.process_time()
            out = f()
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            b = best[k]
            b[0], b[1], b[2] = out, min(b[1], wall), min(b[2], cpu)
    return {k: (b[0], b[1], b[2]) for k, b in best.items()}


def peer_table(repeat: int) -> None:
    """The coronary cases: svzerod, the drop-in and RK4 interleaved (best wall and CPU s)."""
    import numpy as np
    import pandas as pd
    import svzerod

    import oxyline.svzerod as svz

    print(f"\nload average at start: {os.getloadavg()[0]:.1f}\n")
    print("| case | svzerod wall / CPU (s) | gen-α wall / CPU (s) | CPU svzerod/gen-α | "
          "gen-α err vs reference | RK4 wall / CPU (s) | RK4 err vs svzerod 20x |")
    print("|---|---|---|---|---|---|---|")
    for name in ("pulsatileFlow_R_coronary", "pulsatileFlow_R_coronary_varres"):
        cfg = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        r = interleaved({"peer": lambda cfg=cfg: svzerod.simulate(cfg),
                         "ga": lambda cfg=cfg: svz.simulate(cfg),
                         "rk4": lambda cfg=cfg: svz.simulate(cfg, method="rk4")}, repeat)
        fine_df = svzerod.simulate(_refined(cfg, 20))
        ga, rk = r["ga"][0], r["rk4"][0]
        cols = ("flow_in", "flow_out", "pressure_in", "pressure_out")
        e_ga = max(float(np.max(np.abs(ga[c] - ref[c])) / np.max(np.abs(ref[c]))) for c in cols)
        e_rk = max(float(np.max(np.abs(rk[c] - fine_df[c])) / np.ptp(fine_df[c])) for c in cols)
        print(f"| {name} | {_wc(r['peer'])} | {_wc(r['ga'])} | {r['peer'][2] / r['ga'][2]:.2f} "
              f"| {e_ga:.1e} | {_wc(r['rk4'])} | {e_rk:.1e} |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}")


def _wc(timing: tuple[Any, float, float]) -> str:
    """'wall / CPU' seconds of an :func:`interleaved` entry."""
    return f"{timing[1]:.3f} / {timing[2]:.3f}"


def _variable_errors(actual: Any, expected: Any, scale: str = "range") -> float:
    """max over shared variables of max|a - e| / range(e) (``scale="max"``: / max|e|, as
    tests/test_svzerod_sphere.py) without svZeroDSolver's generalized-α-stage valve_status."""
    import numpy as np

    if "y" not in expected.columns:  # vessel-based table: max|a - e| / max|e| per column
        cols = ("flow_in", "flow_out", "pressure_in", "pressure_out")
        return max(float(np.max(np.abs(actual[c].to_numpy() - expected[c].to_numpy()))
                         / np.max(np.abs(expected[c].to_numpy()))) for c in cols)
    worst = 0.0
    for name, e in expected.groupby("name", sort=False):
        a = actual[actual["name"] == name]
        if a.empty or name.startswith("valve_status:"):
            continue
        ev = e["y"].to_numpy(float)
        size = max(float(np.ptp(ev) if scale == "range" else np.max(np.abs(ev))), 1e-12)
        worst = max(worst, float(np.max(np.abs(a["y"].to_numpy(float) - ev))) / size)
    return worst


#: RK4 sub-steps per output step of the drop-in in the chamber table (None: automatic, from
#: the stability bound and the time tables, refined for valves and chambers by the core's step
#: doubling: docs/physics.md §1.8, tests/test_svzerod_chambers.py)
RK4_SUBSTEPS = {"valve_tanh": None, "chamber_elastance_inductor": None,
                "closedLoopHeart_singleVessel_decomposed": None, "chamber_sphere": None}


def _refined(cfg: Any, factor: int) -> Any:
    fine = json.loads(json.dumps(cfg))
    sp = fine["simulation_parameters"]
    sp["number_of_time_pts_per_cardiac_cycle"] = (
        sp["number_of_time_pts_per_cardiac_cycle"] - 1) * factor + 1
    sp["output_interval"] = sp.get("output_interval", 1) * factor
    return fine


def _late(frame: Any, t0: float) -> Any:
    """Rows at t > t0 (the zero start's t = 0 row and start transient left out)."""
    return frame[frame["time"] > t0]


def chamber_table(repeat: int) -> None:
    """svzerod, the drop-in and its RK4 on the chamber/valve peer cases, interleaved (best wall
    and CPU s); the drop-in against the stored reference, RK4 against svzerod 20x finer
    (chamber_sphere, which svzerod 3.2 cannot run: one RK4 run against oxyline's generalized-α
    400x finer, max|a − e| / max|e| as tests/test_svzerod_sphere.py)."""
    import pandas as pd
    import svzerod

    import oxyline
    import oxyline.svzerod as svz

    print(f"\nload average at start: {os.getloadavg()[0]:.1f}\n")
    print("| case | svzerod wall / CPU (s) | gen-α wall / CPU (s) | CPU svzerod/gen-α | "
          "gen-α err vs reference | RK4 sub-steps | RK4 wall / CPU (s) | RK4 err vs fine |")
    print("|---|---|---|---|---|---|---|---|")
    for name in ("valve_tanh", "chamber_elastance_inductor",
                 "closedLoopHeart_singleVessel_decomposed", "chamber_sphere"):
        cfg = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        sphere = name == "chamber_sphere"
        sub = RK4_SUBSTEPS[name]

        def rk4(cfg: Any = cfg, sub: int | None = sub) -> Any:
            try:
                return svz.simulate(cfg, method="rk4", rk4_substeps=sub)
            except (oxyline.SolverError, oxyline.ModelError) as err:
                return err

        calls = {"ga": lambda cfg=cfg: svz.simulate(cfg)}
        if not sphere:  # svzerod 3.2 cannot run it; RK4 takes ~1.6e6 steps: timed once
            calls = {"peer": lambda cfg=cfg: svzerod.simulate(cfg), **calls, "rk4": rk4}
        r = interleaved(calls, repeat)
        if sphere:
            t, c = time.perf_counter(), time.process_time()
            r["rk4"] = (rk4(), time.perf_counter() - t, time.process_time() - c)
        rk = r["rk4"][0]
        if isinstance(rk, Exception):
            e_rk = f"fails: {str(rk)[:60]}"
        elif sphere:
            # the zero start's t = 0 row: gen-α writes the given start, RK4 its consistent
            # algebraic unknowns
            fine = svz.simulate(_refined(cfg, 400))
            e_rk = f"{_variable_errors(_late(rk, 0.0), _late(fine, 0.0), 'max'):.1e} (gen-α 400x)"
        elif name.startswith("closedLoop"):
            fine = svzerod.simulate(_refined(cfg, 20))
            e_rk = f"{_frame_error(_late(rk, 0.0), _late(fine, 0.0)):.1e}"
        else:
            e_rk = f"{_variable_errors(rk, svzerod.simulate(_refined(cfg, 20))):.1e}"
        peer = ("–", "–") if sphere else (_wc(r["peer"]), f"{r['peer'][2] / r['ga'][2]:.2f}")
        print(f"| {name} | {peer[0]} | {_wc(r['ga'])} | {peer[1]} | "
              f"{_variable_errors(r['ga'][0], ref):.1e} | {sub or 'auto'} | {_wc(r['rk4'])} | "
              f"{e_rk} |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}")


def _frame_error(actual: Any, expected: Any) -> float:
    """max over the pressure/flow columns of max|a - e| / max|e| (tests/test_svzerod.py)."""
    import numpy as np

    return max(float(np.max(np.abs(actual[c].to_numpy(float) - expected[c].to_numpy(float)))
                     / np.max(np.abs(expected[c].to_numpy(float))))
               for c in ("flow_in", "flow_out", "pressure_in", "pressure_out"))


def closed_loop_table(repeat: int) -> None:
    """svzerod, the drop-in and its RK4 on the closed-loop heart-block cases, interleaved (best
    wall and CPU s), with the accuracy of each."""
    import pandas as pd
    import svzerod

    import oxyline.svzerod as svz

    print(f"\nload average at start: {os.getloadavg()[0]:.1f}\n")
    print("| case | cycles × steps | svzerod wall / CPU (s) | gen-α wall / CPU (s) | "
          "CPU svzerod/gen-α | gen-α vs svzerod | gen-α vs reference | svzerod vs reference "
          "| RK4 wall / CPU (s) | CPU svzerod/RK4 | RK4 vs svzerod 20x finer |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in ("closedLoopHeart_singleVessel", "closedLoopHeart_withCoronaries"):
        base = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        for cycles, pts in ((None, None), (20, 1001)):
            cfg = json.loads(json.dumps(base))
            sp = cfg["simulation_parameters"]
            if cycles:
                sp["number_of_cardiac_cycles"], sp["number_of_time_pts_per_cardiac_cycle"] = \
                    cycles, pts
            # RK4 with the explicit valve law (docs/physics.md §1.10); its agreement with
            # svzerod 20x finer is the valve timing error of its sub-step (first order)
            r = interleaved({"peer": lambda cfg=cfg: svzerod.simulate(cfg),
                             "ga": lambda cfg=cfg: svz.simulate(cfg),
                             "rk4": lambda cfg=cfg: svz.simulate(cfg, method="rk4")}, repeat)
            peer, ga, rk = r["peer"][0], r["ga"][0], r["rk4"][0]
            stored = cycles is None
            e_r = (f"{_frame_error(rk, svzerod.simulate(_refined(cfg, 20))):.1e}" if stored
                   else "–")
            print(f"| {name} | {sp['number_of_cardiac_cycles']} × "
                  f"{sp['number_of_time_pts_per_cardiac_cycle'] - 1} | {_wc(r['peer'])} | "
                  f"{_wc(r['ga'])} | {r['peer'][2] / r['ga'][2]:.2f} | "
                  f"{_frame_error(ga, peer):.1e} | "
                  f"{f'{_frame_error(ga, ref):.1e}' if stored else '–'} | "
                  f"{f'{_frame_error(peer, ref):.1e}' if stored else '–'} | {_wc(r['rk4'])} | "
                  f"{r['peer'][2] / r['rk4'][2]:.2f} | {e_r} |")
    # coupling blocks with prescribed values (variable tables: the drop-in's shared variables,
    # max|a - e| / range(e))
    for name in ("coupledBlock_closedLoopHeart_singleVessel",
                 "coupledBlock_closedLoopHeart_withCoronaries"):
        cfg = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        sp = cfg["simulation_parameters"]
        r = interleaved({"peer": lambda cfg=cfg: svzerod.simulate(cfg),
                         "ga": lambda cfg=cfg: svz.simulate(cfg)}, repeat)
        peer, ga = r["peer"][0], r["ga"][0]
        shared = set(ga["name"])
        peer_shared, ref_shared = peer[peer["name"].isin(shared)], ref[ref["name"].isin(shared)]
        print(f"| {name} | {sp['number_of_cardiac_cycles']} × "
              f"{sp['number_of_time_pts_per_cardiac_cycle'] - 1} | {_wc(r['peer'])} | "
              f"{_wc(r['ga'])} | {r['peer'][2] / r['ga'][2]:.2f} | "
              f"{_variable_errors(ga, peer_shared):.1e} | {_variable_errors(ga, ref_shared):.1e} "
              f"| {_variable_errors(peer_shared, ref_shared):.1e} | – | – | – |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}")


def constant_table(sizes: str, repeat: int, baseline: str | None) -> None:
    """Constant-coefficient chain/tree: svzerod, this build's drop-in (generalized-α) and
    native RK4 (and ``baseline``'s), each in a fresh subprocess, interleaved; best of
    ``repeat`` CPU seconds (robust to a shared machine) of the process's first call (cold:
    with the one-off costs a single-run user pays) and of a second call (warm: the solver)."""
    impls: dict[str, str | None] = {"svzerod": None, "this": None}
    if baseline:
        impls["baseline"] = str(Path(baseline).resolve())
    print(f"\nload average at start: {os.getloadavg()[0]:.1f}\n")
    print("| model | build | drop-in cold CPU (s) | drop-in warm CPU (s) | RK4 native CPU (s) | "
          "svzerod / drop-in, cold | svzerod / drop-in, warm |")
    print("|---|---|---|---|---|---|---|")
    rows: dict[tuple[str, str], dict[str, list[list[float]]]] = {}
    models = [(t, int(float(n))) for n in sizes.split(",") for t in ("chain", "tree")]
    for what, n in models:
        for _ in range(repeat):
            for impl, path in impls.items():  # alternate solvers and builds within a repeat
                r = run_child(what, n, path, "svzerod" if impl == "svzerod" else "oxyline")
                d = rows.setdefault((f"{what} {n}", impl), {"cold": [], "ga": [], "rk4": []})
                for k in d:
                    d[k].append(r[k])

    def cpu(runs: list[list[float]]) -> float:
        return min(c for _, c in runs)

    for what, n in models:
        peer = rows[(f"{what} {n}", "svzerod")]
        for impl in impls:
            d = rows[(f"{what} {n}", impl)]
            rk = "–" if impl == "svzerod" else f"{cpu(d['rk4']):.3f}"
            print(f"| {what} {n} | {impl} | {cpu(d['cold']):.3f} | {cpu(d['ga']):.3f} | {rk} | "
                  f"{cpu(peer['cold']) / cpu(d['cold']):.1f} | "
                  f"{cpu(peer['ga']) / cpu(d['ga']):.1f} |")
    if baseline:
        print("\n| model | CPU drop-in warm this/baseline | CPU RK4 this/baseline |\n"
              "|---|---|---|")
        for what, n in models:
            a, b = rows[(f"{what} {n}", "this")], rows[(f"{what} {n}", "baseline")]
            print(f"| {what} {n} | {cpu(a['ga']) / cpu(b['ga']):.3f} | "
                  f"{cpu(a['rk4']) / cpu(b['rk4']):.3f} |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", help="directory with another build of the oxyline package")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved repeats (best of)")
    ap.add_argument("--sizes", default="100", help="comma-separated N of chain/tree")
    ap.add_argument("--quick", action="store_true", help="one repeat (a smoke run)")
    ap.add_argument("--constant", action="store_true", help="only the constant-coefficient "
                    "chain/tree table")
    ap.add_argument("--closed-loop", action="store_true", help="only the closed-loop heart-block "
                    "cases against svzerod (time and accuracy)")
    ap.add_argument("--chambers", action="store_true", help="only the chamber/valve cases "
                    "(gen-α and RK4 against svzerod)")
    args = ap.parse_args()
    if args.quick:
        args.repeat = 1
    print(f"# bench_heart.py, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, best of "
          f"{args.repeat} interleaved repeats, {os.cpu_count()} CPUs")
    start = time.perf_counter()
    if args.closed_loop:
        closed_loop_table(args.repeat)
    elif args.chambers:
        chamber_table(args.repeat)
    elif args.constant:
        constant_table(args.sizes, args.repeat, args.baseline)
    else:
        constant_table(args.sizes, args.repeat, args.baseline)
        peer_table(args.repeat)
        chamber_table(args.repeat)
        closed_loop_table(args.repeat)
    print(f"\nwhole bench: {time.perf_counter() - start:.0f} s wall")


if __name__ == "__main__":
    main()
