"""Where does ``oxyline.svzerod.simulate`` spend its time? Phase timings on the benchmark models.

    python benches/profile_oxyline.py --sizes 1e3,1e4 --topologies chain,tree

Phases (each timed separately, in one process, after an untimed warm-up import of pandas):

* ``convert``: svZeroDSolver dict -> oxyline native dict (``oxyline.svzerod`` Python code);
* ``build``: ``oxyline.model._build``: validation, JSON to the core, Rust circuit assembly
  (``core`` is the Rust ``Network`` construction alone, on the same JSON);
* ``run 1 cycle`` and ``run k cycles``: the Rust run (``Network.simulate`` with the drop-in's
  settings); their difference in CPU time gives the cost per step, the rest is setup (steady start,
  LU analysis, first factorisation);
* ``frame (drop-in)``: the DataFrame construction as ``oxyline.svzerod.simulate`` does it
  (separate column copies, then pandas consolidates); ``frame (long_table)`` builds the same
  table with ``oxyline.result.long_table``; ``simulate()`` is the whole drop-in call.

For a sampling profile of the Rust core use ``perf`` on the benchmark child, e.g.
``perf record -F 999 -g python benches/profile_oxyline.py --sizes 1e4 --topologies chain``
then ``perf report --no-children``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import networks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="1e3,1e4")
    ap.add_argument("--topologies", default="chain,tree")
    ap.add_argument("--cycles", type=int, default=networks.CYCLES)
    args = ap.parse_args()

    import numpy as np
    import pandas  # warm-up, as in bench_svzerod.py

    import oxyline.svzerod as svz
    from oxyline import _core
    from oxyline.io.svzerod import reader
    from oxyline.model import _build
    from oxyline.result import long_table

    print("| topology | N | unknowns | convert s | build s | core s | run 1 cycle s "
          f"| run {args.cycles} cycles s | setup CPU s | CPU ns / (vessel step) "
          "| CPU ns / (unknown step) "
          "| frame (drop-in) s | frame (long_table) s | simulate() s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in [int(float(s)) for s in args.sizes.split(",")]:
        for topo in args.topologies.split(","):
            cfg = networks.build(topo, n, args.cycles)
            t0 = time.perf_counter()
            native, s, _ = reader._convert(cfg)
            t1 = time.perf_counter()
            model = _build({**native, "units": "SI"})  # the file's units, as the drop-in runs
            t2 = time.perf_counter()
            _core.Network(json.dumps(model.canonical))
            t3 = time.perf_counter()
            kw = {"period": s.period, "method": "generalized-alpha", "rho_infty": s.rho_infty,
                  "start": "svzerod-steady" if s.steady_initial else "zero",
                  "newton_atol": s.absolute_tolerance, "max_iterations": s.max_iterations,
                  "output_all_cycles": False, "segments": False, "dt": s.dt,
                  "output_every": s.dt * s.output_interval}
            runs, cpu = {}, {}
            for c in (1, args.cycles):
                ta, ca = time.perf_counter(), time.process_time()
                raw = model.network.simulate(cycles=c, **kw)
                runs[c], cpu[c] = time.perf_counter() - ta, time.process_time() - ca
            steps = s.points_per_cycle - 1
            # per-step cost and setup from CPU time (robust to other processes on the machine)
            per_step = (cpu[args.cycles] - cpu[1]) / (steps * (args.cycles - 1))
            setup = cpu[1] - per_step * steps
            unknowns = model.network.summary()["unknowns"]
            names = [v["name"] for v in native["vessels"] if v.get("output", True)]
            data = np.asarray(raw["data"])
            ta = time.perf_counter()
            long_table(names, np.asarray(raw["times"]), data[:, : 4 * len(names)])
            frame_lt = time.perf_counter() - ta
            nt, blk = data.shape[0], data[:, : 4 * len(names)]
            ta = time.perf_counter()
            # the construction in oxyline.svzerod.simulate (column-wise, then consolidated)
            pandas.DataFrame({
                "name": np.repeat(np.array(names, dtype=object), nt),
                "time": np.tile(np.asarray(raw["times"]), len(names)),
                "flow_in": blk[:, 2::4].T.reshape(-1), "flow_out": blk[:, 3::4].T.reshape(-1),
                "pressure_in": blk[:, 0::4].T.reshape(-1),
                "pressure_out": blk[:, 1::4].T.reshape(-1)})
            frame = time.perf_counter() - ta
            ta = time.perf_counter()
            svz.simulate(cfg)
            total = time.perf_counter() - ta
            print(f"| {topo} | {n} | {unknowns} | {t1 - t0:.3g} | {t2 - t1:.3g} | {t3 - t2:.3g} "
                  f"| {runs[1]:.3g} | {runs[args.cycles]:.3g} | {setup:.3g} "
                  f"| {1e9 * per_step / n:.0f} | {1e9 * per_step / unknowns:.0f} "
                  f"| {frame:.3g} | {frame_lt:.3g} | {total:.3g} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
