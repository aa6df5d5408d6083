"""Time-varying coefficients (issue 14): constant-coefficient models keep their fast path, and
the coronary cases against svzerod.

Every timing runs in a fresh subprocess; ``--baseline DIR`` names a directory holding another
build of the ``oxyline`` package (e.g. a copy of main's ``python/`` with its ``_core.abi3.so``),
run alternately with this one in the same session so that the before/after ratio is not skewed
by the load of a shared machine. Models:

* ``chain N`` / ``tree N``: the constant-coefficient chain and tree of ``networks.py`` through
  the svZeroDSolver drop-in (generalized-alpha) and natively with RK4, flow only;
* ``coronary`` / ``coronary_varres``: the peer cases ``pulsatileFlow_R_coronary(_varres)``
  (oxyline generalized-alpha and RK4 vs ``svzerod.simulate``, with the accuracy of each against
  the stored reference / a 20x finer svzerod run);
* chambers and valves: the peer cases ``valve_tanh``, ``chamber_elastance_inductor`` and the
  closed loop ``closedLoopHeart_singleVessel_decomposed`` (time
  of svzerod and of the drop-in in the same run, CPU seconds too, and the accuracy against the
  stored reference; RK4 where it runs).

* closed loop (``--closed-loop``: this table only): svZeroDSolver's closed-loop heart-block
  cases ``closedLoopHeart_singleVessel`` and ``closedLoopHeart_withCoronaries``, as stored
  (10 cycles of 100 steps) and lengthened (20 cycles of 1000 steps): svzerod and the drop-in in
  the same run (median wall and CPU seconds), the drop-in against the stored reference and
  against svzerod with the same settings, svzerod against the stored reference; then the two
  ``coupledBlock_closedLoopHeart_*`` cases (coupling blocks with prescribed values) as stored,
  on the variables the drop-in outputs.

Run ``python benches/bench_heart.py --help``; ``--quick`` (one repeat, N = 200, a few seconds
on a quiet machine plus the peer tables) is the rerun command. Results print as Markdown.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
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
if what in ("chain", "tree"):
    cfg = networks.build(what, n)
    t = time.perf_counter()
    svz.simulate(cfg)
    ga = time.perf_counter() - t
    model = oxyline.load_model(cfg)
    t = time.perf_counter()
    oxyline.simulate(model, method="rk4", dt="auto", segments=False)
    rk = time.perf_counter() - t
else:
    cfg = json.load(open({cases!r} + "/" + what + ".json"))
    t = time.perf_counter()
    svz.simulate(cfg)
    ga = time.perf_counter() - t
    t = time.perf_counter()
    svz.simulate(cfg, method="rk4")
    rk = time.perf_counter() - t
print({mark!r} + json.dumps({{"ga": ga, "rk4": rk}}))
'''


def run_child(what: str, n: int | None, pythonpath: str | None) -> dict[str, float]:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    code = CHILD.format(here=str(HERE), what=what, n=n, cases=str(CASES), mark=MARK)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout
    return json.loads(out.split(MARK)[-1])


def peer_table() -> None:
    import time

    import numpy as np
    import pandas as pd
    import svzerod

    import oxyline.svzerod as svz

    print("| case | svzerod (s) | oxyline gen-α (s) | gen-α err vs reference | oxyline RK4 (s) "
          "| RK4 err vs svzerod 20x |")
    print("|---|---|---|---|---|---|")
    for name in ("pulsatileFlow_R_coronary", "pulsatileFlow_R_coronary_varres"):
        cfg = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        t = time.perf_counter()
        svzerod.simulate(cfg)
        t_peer = time.perf_counter() - t
        t = time.perf_counter()
        ga = svz.simulate(cfg)
        t_ga = time.perf_counter() - t
        t = time.perf_counter()
        rk = svz.simulate(cfg, method="rk4")
        t_rk = time.perf_counter() - t
        fine = json.loads(json.dumps(cfg))
        sp = fine["simulation_parameters"]
        sp["number_of_time_pts_per_cardiac_cycle"] = (sp["number_of_time_pts_per_cardiac_cycle"]
                                                      - 1) * 20 + 1
        sp["output_interval"] = 20
        fine_df = svzerod.simulate(fine)
        cols = ("flow_in", "flow_out", "pressure_in", "pressure_out")
        e_ga = max(float(np.max(np.abs(ga[c] - ref[c])) / np.max(np.abs(ref[c]))) for c in cols)
        e_rk = max(float(np.max(np.abs(rk[c] - fine_df[c])) / np.ptp(fine_df[c])) for c in cols)
        print(f"| {name} | {t_peer:.3f} | {t_ga:.3f} | {e_ga:.1e} | {t_rk:.3f} | {e_rk:.1e} |")


def _variable_errors(actual: Any, expected: Any) -> float:
    """max over shared variables of max|a - e| / range(e) (svZeroDSolver's valve_status and
    chamber volumes are not output by the drop-in)."""
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
        scale = max(float(np.ptp(ev)), 1e-12)
        worst = max(worst, float(np.max(np.abs(a["y"].to_numpy(float) - ev))) / scale)
    return worst


#: RK4 sub-steps per output step of the drop-in in the chamber table (None: automatic, from
#: the stability bound and the time tables); the stiff chamber-inductor case needs 20 to
#: resolve its valves' switch (docs/physics.md §1.8, tests/test_svzerod_chambers.py)
RK4_SUBSTEPS = {"valve_tanh": None, "chamber_elastance_inductor": 20,
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


def chamber_table() -> None:
    """svzerod and the drop-in on the chamber/valve peer cases: wall and CPU seconds of each in
    the same run, the drop-in's accuracy against the stored reference, and RK4 (steps, CPU) against
    svzerod 20x finer (chamber_sphere, which svzerod 3.2 cannot run: against oxyline's
    generalized-α 400x finer)."""
    import time

    import pandas as pd
    import svzerod

    import oxyline
    import oxyline.svzerod as svz

    print(f"\nload average at start: {os.getloadavg()[0]:.1f}\n")
    print("| case | svzerod wall (s) | svzerod CPU (s) | gen-α wall (s) | gen-α CPU (s) | "
          "gen-α err vs reference | RK4 sub-steps | RK4 CPU (s) | RK4 err vs fine |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("valve_tanh", "chamber_elastance_inductor",
                 "closedLoopHeart_singleVessel_decomposed", "chamber_sphere"):
        cfg = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        sphere = name == "chamber_sphere"
        t, c = time.perf_counter(), time.process_time()
        if not sphere:
            svzerod.simulate(cfg)
        t_peer, c_peer = time.perf_counter() - t, time.process_time() - c
        t, c = time.perf_counter(), time.process_time()
        ga = svz.simulate(cfg)
        t_ga, c_ga = time.perf_counter() - t, time.process_time() - c
        sub = RK4_SUBSTEPS[name]
        try:
            c = time.process_time()
            rk = svz.simulate(cfg, method="rk4", rk4_substeps=sub)
            c_rk = f"{time.process_time() - c:.2f}"
            if sphere:
                # the zero start's t = 0 row: gen-α writes the given start, RK4 its consistent
                # algebraic unknowns
                fine = svz.simulate(_refined(cfg, 400))
                e_rk = f"{_variable_errors(_late(rk, 0.0), _late(fine, 0.0)):.1e} (gen-α 400x)"
            elif name.startswith("closedLoop"):
                fine = svzerod.simulate(_refined(cfg, 20))
                e_rk = f"{_frame_error(_late(rk, 0.0), _late(fine, 0.0)):.1e}"
            else:
                e_rk = f"{_variable_errors(rk, svzerod.simulate(_refined(cfg, 20))):.1e}"
        except (oxyline.SolverError, oxyline.ModelError) as err:
            c_rk, e_rk = "–", f"fails: {str(err)[:60]}"
        peer = ("–", "–") if sphere else (f"{t_peer:.3f}", f"{c_peer:.3f}")
        print(f"| {name} | {peer[0]} | {peer[1]} | {t_ga:.3f} | {c_ga:.3f} | "
              f"{_variable_errors(ga, ref):.1e} | {sub or 'auto'} | {c_rk} | {e_rk} |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}")


def _frame_error(actual: Any, expected: Any) -> float:
    """max over the pressure/flow columns of max|a - e| / max|e| (tests/test_svzerod.py)."""
    import numpy as np

    return max(float(np.max(np.abs(actual[c].to_numpy(float) - expected[c].to_numpy(float)))
                     / np.max(np.abs(expected[c].to_numpy(float))))
               for c in ("flow_in", "flow_out", "pressure_in", "pressure_out"))


def closed_loop_table(repeat: int) -> None:
    """svzerod and the drop-in on the closed-loop heart-block cases (time and accuracy)."""
    import statistics
    import time

    import pandas as pd
    import svzerod

    import oxyline.svzerod as svz

    def timed(f: Any, cfg: Any) -> tuple[Any, float, float]:
        walls, cpus, out = [], [], None
        for _ in range(repeat):
            t, c = time.perf_counter(), time.process_time()
            out = f(cfg)
            walls.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
        return out, statistics.median(walls), statistics.median(cpus)

    def fine(cfg: Any, factor: int) -> Any:
        out = json.loads(json.dumps(cfg))
        sp = out["simulation_parameters"]
        sp["number_of_time_pts_per_cardiac_cycle"] = (
            sp["number_of_time_pts_per_cardiac_cycle"] - 1) * factor + 1
        sp["output_interval"] = factor
        return out

    def rk4(cfg: Any) -> Any:
        return svz.simulate(cfg, method="rk4")

    print(f"\nload average at start: {os.getloadavg()[0]:.1f}\n")
    print("| case | cycles × steps | svzerod wall / CPU (s) | gen-α wall / CPU (s) | "
          "CPU gen-α/svzerod | gen-α vs svzerod | gen-α vs reference | svzerod vs reference "
          "| RK4 wall / CPU (s) | CPU RK4/svzerod | RK4 vs svzerod 20x finer |")
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
            peer, w_p, c_p = timed(svzerod.simulate, cfg)
            ga, w_g, c_g = timed(svz.simulate, cfg)
            # RK4 with the explicit valve law (docs/physics.md §1.10); its agreement with
            # svzerod 20x finer is the valve timing error of its sub-step (first order)
            rk, w_r, c_r = timed(rk4, cfg)
            e_r = _frame_error(rk, svzerod.simulate(fine(cfg, 20))) if cycles is None else None
            rk_cols = (f"{w_r:.3f} / {c_r:.3f} | {c_r / c_p:.2f} | "
                       f"{f'{e_r:.1e}' if e_r is not None else '–'}")
            stored = cycles is None
            print(f"| {name} | {sp['number_of_cardiac_cycles']} × "
                  f"{sp['number_of_time_pts_per_cardiac_cycle'] - 1} | {w_p:.3f} / {c_p:.3f} | "
                  f"{w_g:.3f} / {c_g:.3f} | {c_g / c_p:.2f} | {_frame_error(ga, peer):.1e} | "
                  f"{f'{_frame_error(ga, ref):.1e}' if stored else '–'} | "
                  f"{f'{_frame_error(peer, ref):.1e}' if stored else '–'} | {rk_cols} |")
    # coupling blocks with prescribed values (variable tables: the drop-in's shared variables,
    # max|a - e| / range(e))
    for name in ("coupledBlock_closedLoopHeart_singleVessel",
                 "coupledBlock_closedLoopHeart_withCoronaries"):
        cfg = json.loads((CASES / f"{name}.json").read_text())
        ref = pd.read_json(CASES / "results" / f"result_{name}.json.gz")
        sp = cfg["simulation_parameters"]
        peer, w_p, c_p = timed(svzerod.simulate, cfg)
        ga, w_g, c_g = timed(svz.simulate, cfg)
        shared = set(ga["name"])
        print(f"| {name} | {sp['number_of_cardiac_cycles']} × "
              f"{sp['number_of_time_pts_per_cardiac_cycle'] - 1} | {w_p:.3f} / {c_p:.3f} | "
              f"{w_g:.3f} / {c_g:.3f} | {c_g / c_p:.2f} | "
              f"{_variable_errors(ga, peer[peer['name'].isin(shared)]):.1e} | "
              f"{_variable_errors(ga, ref[ref['name'].isin(shared)]):.1e} | "
              f"{_variable_errors(peer[peer['name'].isin(shared)], ref[ref['name'].isin(shared)]):.1e} "
              f"| – | – | – |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", help="directory with another build of the oxyline package")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sizes", default="1000", help="comma-separated N of chain/tree")
    ap.add_argument("--quick", action="store_true", help="one repeat of N = 200, then the peer "
                    "tables (the rerun command)")
    ap.add_argument("--closed-loop", action="store_true", help="only the closed-loop heart-block "
                    "cases against svzerod (time and accuracy)")
    ap.add_argument("--chambers", action="store_true", help="only the chamber/valve cases "
                    "(gen-α and RK4 against svzerod)")
    args = ap.parse_args()
    if args.closed_loop:
        closed_loop_table(args.repeat)
        return
    if args.chambers:
        chamber_table()
        return
    if args.quick:
        args.repeat, args.sizes = 1, "200"

    impls = {"this": None}
    if args.baseline:
        impls["baseline"] = str(Path(args.baseline).resolve())
    load = os.getloadavg()[0]
    print(f"load average at start: {load:.1f}\n")
    print("| model | build | gen-α drop-in (s, median) | RK4 native (s, median) |")
    print("|---|---|---|---|")
    rows: dict[tuple[str, str], dict[str, list[float]]] = {}
    models = [(t, int(float(n))) for n in args.sizes.split(",") for t in ("chain", "tree")]
    for what, n in models:
        for _ in range(args.repeat):
            for impl, path in impls.items():  # alternate builds within each repeat
                r = run_child(what, n, path)
                d = rows.setdefault((f"{what} {n}", impl), {"ga": [], "rk4": []})
                d["ga"].append(r["ga"])
                d["rk4"].append(r["rk4"])
    for (model, impl), d in rows.items():
        print(f"| {model} | {impl} | {statistics.median(d['ga']):.3f} | "
              f"{statistics.median(d['rk4']):.3f} |")
    if args.baseline:
        print("\n| model | gen-α this/baseline | RK4 this/baseline |\n|---|---|---|")
        for what, n in models:
            a, b = rows[(f"{what} {n}", "this")], rows[(f"{what} {n}", "baseline")]
            print(f"| {what} {n} | {statistics.median(a['ga']) / statistics.median(b['ga']):.3f}"
                  f" | {statistics.median(a['rk4']) / statistics.median(b['rk4']):.3f} |")
    print(f"\nload average at end: {os.getloadavg()[0]:.1f}\n")
    peer_table()
    chamber_table()


if __name__ == "__main__":
    main()
