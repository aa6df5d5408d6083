"""Whole-tree scaling of flow and oxygen transport.

The tree family: a symmetric binary tree of ``2^depth - 1`` geometric vessels, Murray radii
r_child = r_parent 2^(-1/3) from a 1 cm root, lengths l = 10 r, Olufsen's wall law
Eh/r = k1 exp(k2 r) + k3 (k1 = 2e6 Pa, k2 = -2253 1/m, k3 = 8.65e4 Pa; Olufsen et al. 2000,
the CGS constants of ``benches/networks.py`` in SI), ``--per-vessel`` segments per vessel,
a half-sine systolic inflow of mean 90 mL/s and one RCR per leaf (parallel totals
R = 1.33e8 Pa s/m^3, 10 % proximal, C = 1e-8 m^3/Pa). Models are native dicts loaded through
the public API (``oxyline.load_model``), run with ``oxyline.simulate``.

Runs: one cycle, generalized-alpha dt = 1 ms (RK4: automatic dt, smaller trees only),
vessel-level output every 10 ms (``segments=False``: no per-segment flow columns).
Configurations: flow only; + O2 with a constant-k wall; + O2 with the Lévêque closure
(cycle-mean shear: needs the cycle-mean |Q| of a flow-only pass); + O2 with Hill haemoglobin
(constant k); + O2 with the default closure (``o2-default``: Graetz, inlet-renewal, whose
first pass also measures each vessel's flow harmonics).

Two O2/flow ratios: ``O2/flow run`` of the whole ``simulate`` (for Lévêque and the default
closure it includes their one-off flow-only first pass), and ``O2/flow step`` per step of the
main pass only (what the load rework asks): the CPU time between the first and the last
progress check of the main pass (every 256 steps, at most every 0.1 s wall), so the steady
start, the first pass and the result's assembly are left out of both runs alike.

Every configuration runs in a fresh subprocess, so that its peak RSS (``ru_maxrss``) is its
own. Times are CPU times of that process (user + system; robust on a shared machine), wall
times in brackets —
``load`` = ``load_model`` (validation, assembly, transport plan), ``run`` = ``simulate``.

    python benches/bench_scale.py --quick               # the issue's table, ~10 min quiet
    python benches/bench_scale.py                       # depths 8, 10, 12, 14, 16
    python benches/bench_scale.py --depths 8 10 12 14 16 18 --rk4-max-depth 12
    python benches/bench_scale.py --depths 8 10 12 14 16 18 --configs flow o2-k \
        --methods generalized-alpha        # the scale targets: slopes 1e3-1e6 (and >= 1e4)
    python benches/bench_scale.py --depths 18 --configs flow o2-k     # the 1e6-segment run
    python benches/bench_scale.py --depths 18 --configs o2-k --zarr   # ... streamed to Zarr
    python benches/bench_scale.py --depths 18 --configs o2-k --methods default
        # ... the default run (auto, error control at rtol 1e-3), opt-in
    python benches/bench_scale.py --depths 15 --configs o2-k --methods default \
        generalized-alpha --threads 1 2    # controlled vs fixed step, 1 and 2 threads
        # (docs/performance.md, "The error control's passes on the threads")
    python benches/bench_scale.py --depths 18 --configs o2-k --variables flow_in concentration_in
    python benches/bench_scale.py --depths 12 14 16 --methods rk4 --rk4-max-depth 16 \
        --rk4-fraction 0.01 --baseline /path/to/old        # before/after in the same run
    python benches/bench_scale.py --depths 16 18 --configs flow o2-k \
        --methods generalized-alpha --threads 1 2          # one run on 1 and 2 threads
    python benches/bench_scale.py --whole-body-st 1e-4 6e-5 --configs o2-k \
        --methods generalized-alpha --threads 2    # whole-body-140-st grown to min_radius
    python benches/bench_scale.py --whole-body-st 3.2e-5 --configs o2-k \
        --methods generalized-alpha --threads 2 --fraction 0.3  # 5.8 M segments, ~13 GB

``--whole-body-st MIN_RADIUS ...``: instead of the binary trees, the built-in
``whole-body-140-st`` with every structured-tree outlet grown down to ``MIN_RADIUS`` (m; one
segment per tree vessel, so ~one vessel per segment, and the base model's loops: the flow
solve takes the general sparse LU and the transport the flow-order sweep instead of the tree
eliminations, docs/performance.md "Whole body down to 32 µm"). 1e-4: 306 k segments, 6e-5:
1.08 M, 3.2e-5: 5.79 M. ``--fraction F`` stops those runs F into the cycle (the steps are timed
between progress checks, as RK4's partial cycles).

``--threads``: each configuration on each thread count (``simulate(threads=N)``); the
``wall 1/N`` column is the wall-time speed-up of the run over the same tree on the first
count. With ``--threads 1 N ...`` the ``serial s`` column is the CPU time of the calling
thread in the N-thread run over the CPU time of the one-thread run; ``Amdahl`` is
1/(s + (1 − s)/N) for 2, 16 and 64 cores. CPU times are the process's own threads', so the
machine's load distorts them far less than the wall ratio. Each phase of a step runs as one
entry of the run's pool, its serial parts (the top trees of the eliminations, the boundary
fluxes' sum in face order, the Newton bookkeeping) on a pool thread, so the calling thread's
CPU (the time loop, the rows' recording, its waking of the pool) is a lower bound of the
serial fraction; the wall ratio gives s = (N / S − 1) / (N − 1) on a free machine. With
several threads the calling thread's sleeps per step (its voluntary context switches: one
per entry of the run's pool) are printed under the row. ``--baseline DIR`` with
``--threads 1 2`` gives both before and after in the same run (docs/performance.md, "One pool
entry per step"). The memory floor of the machine is measured first in the same run: a
STREAM-like copy of a 256 MB array (numpy, one thread), given as ns per 8-byte value copied; the
``copies/seg-step`` column is a step's wall time per segment in units of that copy, i.e.
how many doubles a step could have copied per segment in its time.

O2/flow is per step (a partial RK4 cycle: the steps between the first progress check and the
stop); "run O2/flow" is the whole ``simulate`` call, including the steady start, RK4's step
size search and the Lévêque closure's one-off first pass (a partial cycle: extrapolated to the
whole cycle at the timed steps' rate).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import threading
import time
from typing import Any

#: the method label of oxyline.simulate's default run (no method, no dt)
DEFAULT_RUN = "default"
K1, K2, K3 = 2.0e6, -2253.0, 8.65e4  # Olufsen 2000, Eh/r in Pa with r in m
R_ROOT = 0.01  # m
LENGTH_PER_RADIUS = 10.0
MEAN_FLOW = 9.0e-5  # m^3/s
PERIOD = 1.0
T_SYSTOLE = 0.3
R_TOTAL = 1.33e8  # Pa s/m^3, parallel total of the outlets
C_TOTAL = 1.0e-8  # m^3/Pa
WALLS = {
    "o2-k": ({"model": "mass-transfer", "k": 1.0e-5, "po2": 60.0}, "none"),
    "o2-leveque": ({"model": "leveque", "po2": 60.0}, "none"),
    "o2-hill-k": ({"model": "mass-transfer", "k": 1.0e-5, "po2": 60.0}, "hill"),
    # the default closure: Graetz with the inlet-renewal reversal law (docs/oxygen.md), whose
    # flow-only first pass measures each vessel's mean flow and harmonics
    "o2-default": ({"model": "graetz", "po2": 60.0}, "none"),
}
CONFIGS = ["flow", *WALLS]
# closures whose run starts with a flow-only first pass (the cycle-mean flow)
FIRST_PASS = ("o2-leveque", "o2-default")


def inflow() -> dict[str, Any]:
    """Half-sine systole, zero diastole, time mean exactly MEAN_FLOW (as a 201-point table)."""
    n = 201
    t = [PERIOD * i / (n - 1) for i in range(n)]
    shape = [math.sin(math.pi * ti / T_SYSTOLE) if ti < T_SYSTOLE else 0.0 for ti in t]
    shape = [max(s, 0.0) for s in shape]
    mean = sum((shape[i] + shape[i + 1]) / 2.0 for i in range(n - 1)) / (n - 1)
    return {"type": "flow", "time": t, "flow": [MEAN_FLOW * s / mean for s in shape]}


def tree(depth: int, per_vessel: int, config: str) -> dict[str, Any]:
    """The tree of ``2^depth - 1`` vessels as a native model dict (SI)."""
    vessels: list[dict[str, Any]] = []
    n_leaves = 2 ** (depth - 1)
    bcs: dict[str, Any] = {"in": inflow()}
    rcr = {"type": "rcr", "proximal_resistance": 0.1 * R_TOTAL * n_leaves,
           "capacitance": C_TOTAL / n_leaves, "distal_resistance": 0.9 * R_TOTAL * n_leaves}
    # heap order: vessel i has children 2i+1, 2i+2; its end node is "n{i}"
    for i in range(2 ** depth - 1):
        level = int(math.log2(i + 1))
        r = R_ROOT * 2.0 ** (-level / 3.0)
        h = 0.1 * r
        eh_r = K1 * math.exp(K2 * r) + K3
        start = "in" if i == 0 else f"n{(i - 1) // 2}"
        vessels.append({"name": f"v{i}", "from": start, "to": f"n{i}",
                        "length": LENGTH_PER_RADIUS * r, "radius": r, "wall_thickness": h,
                        "youngs_modulus": eh_r * r / h, "segments": per_vessel})
        if level == depth - 1:
            bcs[f"n{i}"] = rcr
    m: dict[str, Any] = {"name": f"tree{depth}", "period": PERIOD, "vessels": vessels,
                         "boundary_conditions": bcs}
    if config in WALLS:
        wall, hb = WALLS[config]
        m["oxygen"] = {"inlet": {"po2": 95.0}, "wall": wall, "hemoglobin": hb,
                       "reference_pressure": 85.0}
    return m


def whole_body_st(min_radius: float, config: str) -> dict[str, Any]:
    """The built-in ``whole-body-140-st`` (native dict) with every structured-tree outlet's
    ``min_radius`` set to ``min_radius`` (m), with the ``config``'s oxygen section."""
    import oxyline

    m: dict[str, Any] = oxyline.catalogue.load_dict("whole-body-140-st")
    for bc in m["boundary_conditions"].values():
        if isinstance(bc, dict) and bc.get("type") == "structured-tree":
            bc["min_radius"] = min_radius
    m["name"] = f"whole-body-140-st-{min_radius:g}"
    if config in WALLS:
        wall, hb = WALLS[config]
        m["oxygen"] = {"inlet": {"po2": 95.0}, "wall": wall, "hemoglobin": hb,
                       "reference_pressure": 85.0}
    return m


def child(spec: dict[str, Any]) -> dict[str, Any]:
    """One configuration, measured in this (fresh) process. ``spec["zarr"]``: stream the output
    to a Zarr store (``simulate_to_zarr``, ``time_chunk`` rows at a time) instead of keeping it."""
    import tempfile

    import oxyline

    model = (whole_body_st(spec["whole_body_st"], spec["config"]) if spec.get("whole_body_st")
             else tree(spec["depth"], spec["per_vessel"], spec["config"]))
    kw: dict[str, Any] = {"cycles": 1, "output_every": 0.01, "segments": False,
                          "method": spec["method"]}
    if spec.get("threads"):
        kw["threads"] = spec["threads"]
    if spec.get("variables"):
        # "all": every variable, also above the large-model threshold (oxyline.run)
        kw["variables"] = "all" if spec["variables"] == ["all"] else spec["variables"]
    if spec.get("segment_variables"):  # these segment variables too (with the vessel selection)
        kw["segments"] = True
        kw["variables"] = [*(spec.get("variables") or []), *spec["segment_variables"]]
    if spec["method"] == "generalized-alpha":
        kw["dt"] = 1e-3
    elif spec["method"] == DEFAULT_RUN:
        del kw["method"]  # oxyline.simulate's default: auto, error control at rtol 1e-3
    fraction = spec.get("fraction", 1.0)
    # (simulated time, CPU time, wall time) at progress checks
    marks: list[tuple[float, float, float]] = []
    # with ``fraction`` < 1, stop the run a fraction into the cycle (RK4's many small steps
    # on big trees): the progress callback (every 256 steps) sets the cancel event; the steps
    # are timed from the first check to the stop, so the start (steady state, step size) is
    # left out. Always: the checks of the main pass time its steps (a first pass's checks are
    # dropped when the simulated time starts again)
    cancel = threading.Event()
    passes: list[float] = []  # a start of the main pass seen (after a first pass)

    def mark(t: float, t_end: float) -> None:
        if cancel.is_set():
            return
        if marks and t < marks[-1][0]:
            marks.clear()  # the main pass after a first pass
            passes.append(t)
        marks.append((t, time.process_time(), time.perf_counter()))
        if spec.get("verbose"):  # a long run: its progress and peak so far, as it goes
            print(f"t = {t:.3f} s: CPU {marks[-1][1]:.1f} s, wall {marks[-1][2] - w0:.1f} s, "
                  f"peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB",
                  file=sys.stderr, flush=True)
        # (the RK4 pass only, not the generalized-alpha first pass of a closure that needs
        # the mean flow)
        main = bool(passes) or spec["config"] not in FIRST_PASS
        if fraction < 1.0 and t >= fraction * PERIOD and len(marks) > 1 and main:
            cancel.set()

    kw.update(progress=mark, cancel=cancel)
    c0, w0 = time.process_time(), time.perf_counter()
    m = oxyline.load_model(model)
    del model  # the model crosses once: load_model keeps its own copy
    c1, w1 = time.process_time(), time.perf_counter()
    # the calling thread's CPU: with threads > 1 what the run does outside its parallel
    # loops (they run on the pool's threads while this one waits, without spinning)
    t1 = time.thread_time()
    s1 = thread_sleeps()
    p1 = pool_threads()
    with tempfile.TemporaryDirectory() as d:
        if spec.get("zarr"):
            res = oxyline.simulate_to_zarr(m, os.path.join(d, "run.zarr"),
                                           time_chunk=spec["time_chunk"], **kw)
            settings = {"dt": res.attrs["solver_dt"]}
        else:
            try:
                res = oxyline.simulate(m, **kw)
            except oxyline.SimulationCancelled as exc:
                res = exc.result
            settings = res.settings
        c2, w2, t2 = time.process_time(), time.perf_counter(), time.thread_time()
        sleeps = thread_sleeps() - s1 if s1 is not None else None
        p2 = pool_threads()
        dt = float(settings["dt"]) if settings.get("dt") else None
        out = {"load_cpu": c1 - c0, "load_wall": w1 - w0, "run_cpu": c2 - c1,
               "run_main_cpu": t2 - t1,
               "run_wall": w2 - w1, "segments": int(m.network.summary()["segments"]),
               "dt": dt, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
        if sleeps is not None:
            out["sleeps"] = sleeps
        if p2:
            # the run pool's threads: their CPU and sleeps during this run
            out["pool_cpu"] = sum(c - p1.get(t, (0.0, 0))[0] for t, (c, _) in p2.items())
            out["pool_sleeps"] = sum(n - p1.get(t, (0.0, 0))[1] for t, (_, n) in p2.items())
        # the run's start before its first step: the steady start and `auto`'s choice of
        # method (its stability probe reports progress at t = 0)
        at_start = [c for t, c, _ in marks if t == 0.0]
        if at_start:
            out["start_cpu"], out["start_marks"] = at_start[-1] - c1, len(at_start)
        if settings.get("steps"):  # an error-controlled run: its accepted steps
            out["steps"] = int(settings["steps"])
            out["ran"] = f"{settings['method']}, {settings.get('step_control', '')}"
        if len(marks) > 1 and dt:
            # the main pass's steps between its first and last progress checks
            out["main_steps"] = round((marks[-1][0] - marks[0][0]) / dt)
            out["main_cpu"] = marks[-1][1] - marks[0][1]
            out["main_wall"] = marks[-1][2] - marks[0][2]
        if fraction < 1.0 and len(marks) > 1:
            # a partial cycle: the timed steps only, no end-of-cycle mass balance
            out["steps"], out["step_cpu"] = out["main_steps"], out["main_cpu"]
            # the whole cycle's CPU estimated as everything before the first timed check
            # (steady start, step size, first pass, the first steps) plus the remaining steps
            # at the timed rate
            rest = round((PERIOD - marks[0][0]) / dt)
            out["cycle_cpu"] = marks[0][1] - c1 + out["step_cpu"] / out["steps"] * rest
            return out
        if not spec.get("zarr") and res.species:
            mb = res.o2_mass_balance
            out["residual"] = float(mb["residual"][-1] / mb["inflow"][-1])
        del res
    return out


def measure(spec: dict[str, Any], baseline: str | None = None) -> dict[str, Any]:
    """Run ``spec`` in a fresh interpreter; best (smallest CPU) of ``repeat`` runs.
    ``baseline``: a directory holding another build of the ``oxyline`` package, put first on
    the child's path (a before/after comparison in the same run)."""
    env = None
    if baseline:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [baseline, *filter(None, [os.environ.get("PYTHONPATH")])]))
    best: dict[str, Any] | None = None
    for _ in range(spec["repeat"]):
        p = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)],
                           capture_output=True, text=True, check=False, env=env)
        if p.returncode != 0:
            return {"error": (p.stderr.strip().splitlines() or ["?"])[-1]}
        r = json.loads(p.stdout.strip().splitlines()[-1])
        if best is None or r["run_cpu"] + r["load_cpu"] < best["run_cpu"] + best["load_cpu"]:
            best = r
    assert best is not None
    return best


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of log y against log x."""
    lx = [math.log(x) for x in xs]
    ly = [math.log(max(y, 1e-9)) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    den = sum((a - mx) ** 2 for a in lx)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / den if den > 0 else float("nan")


# --quick: what the lead reruns on a quiet machine in <= 10 min (~8.5 min CPU estimated
# from the loaded-machine runs); gen-alpha flow, o2-k and o2-leveque reach 1.05 M segments
# (depth 18), Hill stops at 65 k, RK4 at 1 k and 4 k: its automatic dt follows the smallest vessel,
# 2 400 / 6 400 / 16 600 steps per cycle at depths 8 / 10 / 12 (~×2.6 per two levels), so a
# 16 k-segment RK4 cycle costs ~30-80 s CPU per configuration and 1.05 M would take hours
QUICK = {"depths": [8, 10, 12, 14, 16, 18], "max_depth": {"o2-hill-k": 14, "o2-default": 16},
         "rk4_max_depth": 10}


def step_cpu(r: dict[str, Any]) -> float:
    """CPU s of the timed steps: the whole run, or the steps of a partial cycle."""
    return r.get("step_cpu", r["run_cpu"])


def main_step_cpu(r: dict[str, Any]) -> float | None:
    """CPU s per step of the main pass (between its progress checks), if it had two."""
    return r["main_cpu"] / r["main_steps"] if r.get("main_steps") else None


def copy_ns() -> tuple[float, float, float]:
    """A STREAM-like copy on this machine, now: ns per 8-byte value of copying a 256 MB array
    into another (read + write, numpy, one thread; best of 5), measured in a child process
    (Linux keeps a process's peak RSS across fork and exec: measured here, the 512 MB would
    become every later child's peak); with the copy's CPU ns per value of one thread alone and
    of each of two threads copying a half at once (`copy_cpu`)."""
    p = subprocess.run([sys.executable, __file__, "--copy"], capture_output=True, text=True,
                       check=True)
    wall, alone, both = json.loads(p.stdout.strip().splitlines()[-1])
    return wall, alone, both


def copy_in_this_process() -> tuple[float, float, float]:
    """`copy_ns`'s measurement."""
    import numpy as np

    a = np.ones(1 << 25)
    b = np.empty_like(a)
    best = math.inf
    for _ in range(5):
        t0 = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - t0)
    return 1e9 * best / a.size, copy_cpu(a, b, 1), copy_cpu(a, b, 2)


def copy_cpu(a: Any, b: Any, threads: int, rounds: int = 8) -> float:
    """CPU ns per value of copying ``a`` into ``b`` on ``threads`` threads at once, each its
    own part (numpy releases the GIL), best of ``rounds``; the slower thread's. A thread's CPU
    time counts only while it runs, so the machine's load does not inflate it as it does the
    wall time: if each of two threads copying at once takes longer per value than one alone,
    they share the memory's bandwidth, and a memory-bound pass cannot run 2× as fast on two
    threads (at most alone / both × 2)."""
    import numpy as np

    cut = np.linspace(0, a.size, threads + 1).astype(int)
    best = math.inf
    for _ in range(rounds):
        start = threading.Barrier(threads)
        took = [0.0] * threads

        def part(i: int, start: threading.Barrier, took: list[float]) -> None:
            lo, hi = cut[i], cut[i + 1]
            start.wait()
            c0 = time.thread_time()
            np.copyto(b[lo:hi], a[lo:hi])
            took[i] = 1e9 * (time.thread_time() - c0) / (hi - lo)

        workers = [threading.Thread(target=part, args=(i, start, took))
                   for i in range(threads)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        best = min(best, max(took))
    return best


def thread_sleeps() -> int | None:
    """The calling thread's voluntary context switches so far (Linux; None elsewhere): with
    threads > 1 one per entry of the run's pool (the thread sleeps until the pool is done)."""
    try:
        with open("/proc/thread-self/status") as f:
            for line in f:
                if line.startswith("voluntary_ctxt_switches:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def pool_threads() -> dict[str, tuple[float, int]]:
    """CPU seconds and voluntary context switches (sleeps) of each of the run pools' threads
    (``oxyline-run-N``) so far (Linux; empty elsewhere)."""
    out: dict[str, tuple[float, int]] = {}
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return out
    tick = os.sysconf("SC_CLK_TCK")
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                stat = f.read()
            with open(f"/proc/self/task/{tid}/status") as f:
                status = f.read()
        except OSError:
            continue
        if not stat[stat.index("(") + 1:stat.rindex(")")].startswith("oxyline-run-"):
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        sleeps = int(status.split("\nvoluntary_ctxt_switches:")[1].split()[0])
        out[tid] = ((int(fields[11]) + int(fields[12])) / tick, sleeps)
    return out


def serial_fraction(r: dict[str, Any], first: dict[str, Any] | None) -> float | None:
    """The run's serial fraction s: the calling thread's CPU in a run on several threads
    (what it does outside the parallel loops) over the whole CPU of the one-thread run of
    the same tree (``first``). Both are CPU times of this process's own threads, which the
    machine's load distorts far less than wall times."""
    if not first or first is r or first.get("threads") != 1 or (r.get("threads") or 0) < 2:
        return None
    return r["run_main_cpu"] / first["run_cpu"]


def amdahl(s: float, cores: int) -> float:
    """Amdahl's speed-up on ``cores`` cores of a run with serial fraction ``s``."""
    return 1.0 / (s + (1.0 - s) / cores)


def thread_cells(r: dict[str, Any], first: dict[str, Any] | None, copy: float) -> str:
    """The threads, wall speed-up over the first thread count's run of the same tree, the
    main pass's wall ns per segment-step in copies of one double (see the module doc), and
    the serial fraction with Amdahl's speed-up from it on 2, 16 and 64 cores."""
    speedup = (f"{(first['run_wall']) / r['run_wall']:.2f}" if first and first is not r
               else "–")
    wall = r.get("main_wall")
    copies = (f"{1e9 * wall / (r['segments'] * r['main_steps']) / copy:.1f}"
              if wall and r.get("main_steps") else "–")
    s = serial_fraction(r, first)
    serial = (f"{s:.3f} | " + " / ".join(f"{amdahl(s, n):.2f}" for n in (2, 16, 64))
              if s is not None else "– | –")
    return f" {r.get('threads') or 'all'} | {speedup} | {copies} | {serial} |"


def row(method: str, config: str, r: dict[str, Any], flow: dict[str, Any] | None) -> str:
    """One table row; ``flow``: the flow-only run of the same tree and method (for O2/flow)."""
    steps = r.get("steps", round(PERIOD / r["dt"]))
    ns = 1e9 * step_cpu(r) / (r["segments"] * steps)
    # (a partial cycle is timed between progress checks: O2/flow per step)
    # the whole simulate call (steady start, step size, first pass included; a partial cycle
    # extrapolated to the whole one)
    ratio = (f"{r.get('cycle_cpu', r['run_cpu']) / flow.get('cycle_cpu', flow['run_cpu']):.2f}"
             if flow and config != "flow" else "–")
    main, main_flow = main_step_cpu(r), flow and main_step_cpu(flow)
    ns_main = f"{1e9 * main / r['segments']:.1f}" if main else "–"
    ratio_main = (f"{main / main_flow:.2f}" if main and main_flow and config != "flow"
                  else "–")
    res = f"{r['residual']:.1e}" if "residual" in r else "–"
    return (f"| {method} | {config} | {r['segments']} | {steps} | {r['load_cpu']:.2f} "
            f"({r['load_wall']:.2f}) | {r['run_cpu']:.2f} ({r['run_wall']:.2f}) | {ns:.1f} | "
            f"{ns_main} | {r['peak_mb']:.0f} | {r['peak_mb'] * 1048576 / r['segments']:.0f} | "
            f"{ratio} | {ratio_main} | "
            f"{1e6 * r['load_cpu'] / r['segments']:.2f} | {res} |")


def print_slopes(rows: dict[tuple[str, str], list[dict[str, Any]]], min_segments: float) -> None:
    print(f"\nlog-log slopes against segments (trees of >= {min_segments:.0e} segments, CPU "
          "time; target <= 1.1):")
    for (method, config), rs in rows.items():
        rs = [r for r in rs if r["segments"] >= min_segments]
        if len(rs) < 2:
            continue
        n = [r["segments"] for r in rs]
        print(f"  {method:<18} {config:<11} load {slope(n, [r['load_cpu'] for r in rs]):.2f}"
              f"  run {slope(n, [step_cpu(r) / r.get('steps', PERIOD / r['dt']) for r in rs]):.2f}"
              f" (per step; {n[0]}-{n[-1]} segments)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--copy", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true",
                    help="depths 8-18 (gen-alpha flow/o2-k/o2-leveque to 1.05 M, Hill to "
                         "65 k, RK4 1-4 k): < 10 min on a quiet 2-core machine")
    ap.add_argument("--depths", type=int, nargs="+", default=[8, 10, 12, 14, 16])
    ap.add_argument("--per-vessel", type=int, default=4)
    ap.add_argument("--configs", nargs="+", default=CONFIGS, choices=CONFIGS)
    ap.add_argument("--methods", nargs="+", default=["generalized-alpha", "rk4"],
                    choices=["generalized-alpha", "rk4", DEFAULT_RUN],
                    help=f"'{DEFAULT_RUN}' (opt-in): oxyline.simulate's default run, no method "
                         "and no dt (auto, error control at rtol 1e-3)")
    ap.add_argument("--rk4-max-depth", type=int, default=12,
                    help="largest tree run with RK4 (its stable dt shrinks with the vessels)")
    ap.add_argument("--fit-min-segments", type=float, nargs="+", default=[1e3, 1e4],
                    help="smallest tree included in the log-log fits, one fit per value "
                         "(default: from 1e3, the range of the scale targets, and from 1e4, "
                         "the fits of earlier sessions)")
    ap.add_argument("--zarr", action="store_true",
                    help="stream the output to a Zarr store (simulate_to_zarr) instead of "
                         "keeping it in memory")
    ap.add_argument("--time-chunk", type=int, default=10,
                    help="rows per Zarr chunk with --zarr")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--threads", type=int, nargs="+", default=[None],
                    help="run every configuration on each of these thread counts "
                         "(simulate(threads=N); default: the simulate() default, every core)")
    ap.add_argument("--variables", nargs="+",
                    help="output only these vessel variables (the run's output selection, "
                         "e.g. pressure_in flow_in concentration_in concentration_out; "
                         "'all': every variable); default: the simulate() default (above "
                         "oxyline.run.LARGE_MODEL_SEGMENTS the large-model subset)")
    ap.add_argument("--segment-variables", nargs="+",
                    help="also output these segment variables (segments=True), e.g. "
                         "segment_wall_flux: the run's output grows by a column per segment")
    ap.add_argument("--rk4-fraction", type=float, default=1.0,
                    help="RK4 runs stop this fraction into the cycle (its automatic dt makes "
                         "a whole cycle of a 65 k-segment tree take minutes); O2/flow is then "
                         "per step")
    ap.add_argument("--whole-body-st", type=float, nargs="+", metavar="MIN_RADIUS",
                    help="run whole-body-140-st grown to these structured-tree min_radius "
                         "(m) instead of the binary trees (e.g. 3.2e-5: 5.8 M segments)")
    ap.add_argument("--fraction", type=float, default=1.0,
                    help="--whole-body-st runs stop this fraction into the cycle")
    ap.add_argument("--baseline", metavar="DIR",
                    help="also run every configuration with the oxyline package in DIR "
                         "(rows marked 'baseline', right after this build's)")
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(json.loads(a.child))))
        return
    if a.copy:
        print(json.dumps(copy_in_this_process()))
        return
    max_depth: dict[str, int] = {}
    if a.quick:
        a.depths, max_depth, a.rk4_max_depth = QUICK["depths"], QUICK["max_depth"], \
            QUICK["rk4_max_depth"]
    out = (f"streamed to Zarr ({a.time_chunk} rows per chunk)" if a.zarr
           else "kept in memory")
    if a.variables:
        out += f", variables {' '.join(a.variables)}"
    if a.segment_variables:
        out += f", segment variables {' '.join(a.segment_variables)}"
    print(f"# binary trees, {a.per_vessel} segments per vessel, one cycle, vessel output every "
          f"10 ms {out}; CPU s (wall s), best of {a.repeat}; peak RSS of a fresh process; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}"
          + (f"; RK4 runs stop {a.rk4_fraction:g} into the cycle (ns/seg-step and O2/flow "
             "over the steps between the first progress check and the stop)"
             if a.rk4_fraction < 1.0 and "rk4" in a.methods else ""))
    copy, alone, both = copy_ns()
    print(f"STREAM-like copy: {copy:.2f} ns per double (256 MB array, one thread); its CPU "
          f"per double {alone:.2f} ns alone, {both:.2f} ns each of 2 threads at once: "
          f"2 threads copy at most {2.0 * alone / both:.2f}× as fast as one")
    print("| method | config | segments | steps | load s | run s | ns/seg-step run "
          "| ns/seg-step main pass | peak MB | peak B/seg | O2/flow run "
          "| O2/flow step (main pass) "
          "| load µs/seg | mass residual | threads | wall 1/N | copies/seg-step "
          "| serial s | Amdahl 2 / 16 / 64 |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:"
          "|---:|---:|")
    rows: dict[tuple[str, str], list[dict[str, Any]]] = {}
    skipped: list[str] = []
    if a.whole_body_st:
        whole_body_rows(a, copy)
        return
    for method in a.methods:
        for depth in a.depths:
            flows: dict[str | None, dict[str, Any]] = {}
            for config in a.configs:
                limit = a.rk4_max_depth if method == "rk4" else max_depth.get(config, 99)
                if depth > limit:
                    skipped.append(f"{method} {config} depth {depth}")
                    continue
                firsts: dict[str | None, dict[str, Any]] = {}
                for threads, build in [(t, b) for t in a.threads
                                       for b in ([None, a.baseline] if a.baseline else [None])]:
                    spec = {"depth": depth, "per_vessel": a.per_vessel, "config": config,
                            "method": method, "repeat": a.repeat, "zarr": a.zarr,
                            "segment_variables": a.segment_variables,
                            "fraction": a.rk4_fraction if method == "rk4" else 1.0,
                            "time_chunk": a.time_chunk, "variables": a.variables,
                            "threads": threads}
                    label = f"{method} (baseline)" if build else method
                    r = measure(spec, build)
                    if "error" in r:
                        print(f"| {label} | {config} | depth {depth} | failed: {r['error']} |")
                        continue
                    r["threads"] = threads
                    first = firsts.setdefault(build, r)
                    if config == "flow" and threads == a.threads[0]:
                        flows[build] = r
                    print(row(label, config, r, flows.get(build))
                          + thread_cells(r, first, copy), flush=True)
                    if "ran" in r:
                        print(f"|   ran: {r['ran']} |", flush=True)
                    if "start_cpu" in r:
                        print(f"|   to the last progress mark at t = 0 (load excluded: steady "
                              f"start, `auto`'s choice): {r['start_cpu']:.1f} CPU s, "
                              f"{r['start_marks']} marks |", flush=True)
                    steps = r.get("steps", round(PERIOD / r["dt"])) if r.get("dt") else 1
                    if threads != 1 and r.get("sleeps") is not None:
                        print(f"|   calling thread: {r['sleeps'] / steps:.1f} sleeps per step "
                              "(entries of the run's pool) |", flush=True)
                    if threads != 1 and "pool_cpu" in r:
                        more = (f", {r['run_cpu'] / first['run_cpu']:.2f}× the one-thread run's "
                                "CPU" if first is not r and first.get("threads") == 1 else "")
                        print(f"|   pool threads: {r['pool_cpu']:.2f} CPU s, "
                              f"{r['pool_sleeps'] / steps:.2f} sleeps per step{more} |",
                              flush=True)
                    if threads == a.threads[0]:
                        rows.setdefault((label, config), []).append(r)
    if skipped:
        print(f"\nnot run (--rk4-max-depth {a.rk4_max_depth}: RK4's automatic dt makes its step "
              f"count grow with the tree; --quick also stops Hill at depth 14): "
              + ", ".join(skipped))
    for min_segments in a.fit_min_segments:
        print_slopes(rows, min_segments)


def whole_body_rows(a: argparse.Namespace, copy: float) -> None:
    """The table's rows of ``whole-body-140-st`` grown to each ``--whole-body-st`` radius."""
    for method in a.methods:
        for min_radius in a.whole_body_st:
            flows: dict[str, Any] = {}
            for config in a.configs:
                first: dict[str, Any] | None = None
                for threads in a.threads:
                    spec = {"whole_body_st": min_radius, "depth": 0, "per_vessel": 1,
                            "config": config, "method": method, "repeat": a.repeat,
                            "fraction": a.fraction, "variables": a.variables,
                            "threads": threads}
                    label = f"{method}, whole-body-140-st {min_radius:g} m"
                    r = measure(spec)
                    if "error" in r:
                        print(f"| {label} | {config} | failed: {r['error']} |")
                        continue
                    r["threads"] = threads
                    first = first or r
                    if config == "flow":
                        flows = r
                    print(row(label, config, r, flows or None) + thread_cells(r, first, copy),
                          flush=True)


if __name__ == "__main__":
    main()
