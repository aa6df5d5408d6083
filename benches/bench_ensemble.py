"""Ensembles (``oxyline.simulate_ensemble``): thread scaling, throughput against a loop of
svZeroDSolver runs, and the overhead of a Dask LocalCluster, interleaved in rounds.

    python benches/bench_ensemble.py --quick                        # 3 rounds, every size
    python benches/bench_ensemble.py --quick --sizes tree-64,tree-1000   # ~5 min quiet
    python benches/bench_ensemble.py --quick --sizes pwdb-200            # ~5 min quiet

Sizes (``--sizes``): ``tree-64`` and ``tree-1000``, 64 and 1,000 variants of the svzerod tree
of ``benches/networks.py`` (``--vessels`` vessels, svzerod's settings: ``--cycles`` cycles of
``--pts`` points, generalized-alpha) read through the svZeroDSolver drop-in
(``oxyline.svzerod.to_model``), variant k scaling every resistance (the vessels'
``R_poiseuille`` and the outlets' ``R``) by a factor in [0.8, 1.2]: in oxyline the patch
``{"scale": {"resistance": f}}``, in svzerod the same numbers written into a copy of the
configuration; ``pwdb-200``: 200 subjects of ``oxyline.populations.pwdb_like`` spread evenly
over the 4,374 (pwdb-116, from the periodic start to periodicity 1e-4, the population
bench's output).

The machine drifts (±30 % between runs of the same build on a quiet machine), so nothing is
measured in blocks: every round runs, per size, each configuration once, in an order rotated
from round to round —

* ``1 worker`` / ``2 workers``: the local ensemble with ``workers=1`` / ``workers=2`` (summary
  output);
* ``LocalCluster``: ``client=`` a ``LocalCluster(n_workers=2, threads_per_worker=1)``, started
  once before the first round (one warm-up ensemble of 2 variants per size on it, then idle
  while the local runs of later configurations run: its idle background CPU is printed);
* ``svzerod``: a Python loop of ``svzerod.simulate(config_k)`` (the svzerod PyPI package; each
  call returns its DataFrame) over ``--svzerod-runs`` of the size's variants spread evenly
  (tree-64: all 64; tree-1000: a subset, the table says how many). pwdb-116 has no svzerod
  form.

and every ratio is formed within one round: scaling = 1 worker / 2 workers, LocalCluster
overhead = LocalCluster / 2 workers − 1, vs svzerod = svzerod time per run / 2-worker ensemble
time per variant (the same networks: the root vessel's time-averaged inlet pressure agrees to
1e-6, checked on the first round). The tables give the best and the median wall time per
configuration and the median (min–max) of the per-round ratios. Each round also times the
machine's own 1 → 2 scaling (two processes of a CPU-bound Python loop against one): the
ceiling that no ensemble code can pass on this machine at that moment. After the rounds, the
cluster's fixed cost per call (median of 2-variant ensembles on the cluster minus on local
threads, first size) and the local ensemble duration above which its overhead stays within
15 %.

CPU time (user + system of this process and its threads; for the LocalCluster plus its worker
processes) is given beside the wall times and the 1-min load average per round, because the
machine may be shared. Results are printed as Markdown and appended to ``benches/results.md``
(``--output ''`` for none).
"""

from __future__ import annotations

import argparse
import copy
import datetime
import os
import platform
import resource
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import networks

import oxyline
from oxyline import svzerod as dropin
from oxyline import units

#: relative agreement of oxyline and svzerod on the root pressure that says "same network"
SAME_NETWORK_RTOL = 1e-6


def factors(n: int) -> np.ndarray:
    return np.linspace(0.8, 1.2, n)


def svzerod_config(cfg: dict[str, Any], f: float) -> dict[str, Any]:
    """The svzerod configuration with every resistance scaled by ``f``."""
    out = copy.deepcopy(cfg)
    for v in out["vessels"]:
        v["zero_d_element_values"]["R_poiseuille"] *= f
    for bc in out["boundary_conditions"]:
        if bc["bc_type"] == "RESISTANCE":
            bc["bc_values"]["R"] *= f
    return out


def time_average(frame: Any, column: str) -> float:
    """Time average of one vessel's ``column`` in an svzerod result frame (trapezoidal rule
    over its output times, as oxyline's summary ``_mean``)."""
    t = frame["time"].to_numpy(dtype=float)
    return float(np.trapezoid(frame[column].to_numpy(dtype=float), t) / (t[-1] - t[0]))


def cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def cluster_cpu(client: Any) -> float:
    """User + system CPU time of the cluster's worker processes so far (s)."""
    return sum(client.run(cpu).values())


def load() -> str:
    return f"{os.getloadavg()[0]:.2f}"


class Size:
    """One ensemble of the table: its model, patches, run settings and svzerod configs."""

    def __init__(self, name: str, args: argparse.Namespace) -> None:
        self.name = name
        kind, n = name.split("-")
        self.n = int(n)
        self.settings: dict[str, Any] = {}
        self.cfg: dict[str, Any] | None = None
        #: the network (svzerod's per-run time is measured once per network)
        self.key = (args.vessels, args.cycles, args.pts)
        if kind == "tree":
            self.cfg = networks.build("tree", args.vessels, args.cycles, args.pts)
            self.model = dropin.to_model(self.cfg)
            self.patches = [{"scale": {"resistance": float(f)}} for f in factors(self.n)]
            self.what = (f"svzerod tree of {args.vessels} vessels, {args.cycles} cycles x "
                         f"{args.pts} points, resistances x 0.8-1.2, summary output")
        elif kind == "pwdb":
            from oxyline import populations as P

            everyone = P.pwdb_like()
            picks = np.linspace(0, len(everyone) - 1, self.n).round().astype(int)
            self.model = oxyline.load_model(P.MODEL)
            self.patches = [everyone[i] for i in picks]
            # each subject from its periodic state, as bench_population.py runs them
            self.settings = {"output": P.subject_summary, "until_periodic": 1e-4,
                             "start": "periodic", "vessels": P.summary_vessels(),
                             "variables": ["pressure_in", "pressure_out",
                                           "segment_pressure_in"]}
            self.what = (f"{self.n} of the 4,374 pwdb_like subjects of pwdb-116 (spread "
                         "evenly), from the periodic start to periodicity 1e-4, per-subject "
                         "summary")
        else:
            raise SystemExit(f"unknown size {name!r} (tree-N or pwdb-N)")

    def run(self, **kw: Any) -> Any:
        ds = oxyline.simulate_ensemble(self.model, self.patches, progress=False,
                                       **self.settings, **kw)
        assert (ds.status.values == 0).all(), ds.error.values
        return ds


class Svzerod:
    """The svzerod loop of a size: ``runs`` of its configurations spread evenly over its
    variants (all of them if ``runs`` >= variants)."""

    def __init__(self, size: Size, runs: int) -> None:
        assert size.cfg is not None
        self.size = size
        self.picks = np.linspace(0, size.n - 1, min(runs, size.n)).round().astype(int)
        fs = factors(size.n)
        self.configs = [svzerod_config(size.cfg, fs[i]) for i in self.picks]
        self.check = ""

    def run(self) -> list[Any]:
        import svzerod

        return [svzerod.simulate(c) for c in self.configs]

    def same_network(self, frames: list[Any], ds: Any) -> None:
        """Check that oxyline and svzerod ran the same networks: the time-averaged inlet
        pressure of the root vessel, variant by variant, both in Pa (svzerod reports in its
        file's units, cgs here: dyn/cm^2 = 0.1 Pa)."""
        size = self.size
        root = size.model.vessel_names[0]
        to_si = units.factor(dropin.file_units(size.cfg), "pressure")
        sv_mean = np.array([time_average(f[f["name"] == root], "pressure_in") * to_si
                            for f in frames])
        ox_mean = ds.pressure_in_mean.sel(vessel=root).values[self.picks]
        diff = float(np.max(np.abs(ox_mean / sv_mean - 1)))
        # both are the same generalized-alpha scheme on the same linear circuit and output
        # times: they differ by round-off (1e-15 measured), far below 1e-6; another network, or
        # a units mix-up (a factor 10), is far above it. (The plain mean of svzerod's output
        # rows, equal weights instead of the trapezoidal rule's half weights at the ends,
        # differs by ~7e-4.)
        if not diff < SAME_NETWORK_RTOL:
            raise SystemExit(f"oxyline and svzerod disagree: root-vessel time-averaged inlet "
                             f"pressure differs by {diff:.1e} (relative) > {SAME_NETWORK_RTOL:g}")
        self.check = (f"{size.name}: root-vessel time-averaged inlet pressure, oxyline vs "
                      f"svzerod, max relative difference {diff:.1e} over the {len(frames)} "
                      f"variants svzerod ran (check: < {SAME_NETWORK_RTOL:g}).")


#: the configurations of a round, in their order in the tables
CONFIGS = ("1 worker", "2 workers", "LocalCluster", "svzerod")


class Rounds:
    """Every measurement of one size: per configuration and round, (wall s, CPU s)."""

    def __init__(self, size: Size, svz: Svzerod | None) -> None:
        self.size, self.svz = size, svz
        self.runs: dict[str, list[tuple[float, float]]] = {}
        self.loads: list[float] = []
        self.notes: list[str] = []
        self.identical: bool | None = None

    def configs(self, client: Any) -> list[str]:
        return [c for c in CONFIGS if (c != "LocalCluster" or client is not None)
                and (c != "svzerod" or self.svz is not None)]

    def measure(self, config: str, client: Any, first: bool) -> None:
        size = self.size
        c0, t0 = cpu(), time.perf_counter()
        w0 = cluster_cpu(client) if config == "LocalCluster" else 0.0
        if config == "svzerod":
            assert self.svz is not None
            frames = self.svz.run()
        else:
            kw = ({"client": client} if config == "LocalCluster"
                  else {"workers": 1 if config == "1 worker" else 2})
            ds = size.run(**kw)
        wall, used = time.perf_counter() - t0, cpu() - c0
        if config == "LocalCluster":
            used += cluster_cpu(client) - w0
        self.runs.setdefault(config, []).append((wall, used))
        if config == "2 workers":
            self.local = ds
        if first and config == "svzerod":
            self.frames = frames
        if first and config == "LocalCluster":
            self.remote = ds

    def checks(self) -> None:
        """After the first round: svzerod ran the same networks, the cluster the same bits."""
        if self.svz is not None and hasattr(self, "frames"):
            self.svz.same_network(self.frames, self.local)
            self.notes.append(self.svz.check)
            del self.frames
        if hasattr(self, "remote"):
            self.identical = all(
                bool(np.array_equal(self.local[v].values, self.remote[v].values, equal_nan=True))
                for v in self.local.data_vars if self.local[v].dtype.kind == "f")
            self.notes.append(f"{self.size.name}: LocalCluster results bit-identical to the "
                              f"local run: {self.identical}.")
            del self.remote

    def ratios(self) -> dict[str, list[float]]:
        """Per round: scaling, LocalCluster overhead (%), vs svzerod."""
        w1 = [w for w, _ in self.runs["1 worker"]]
        w2 = [w for w, _ in self.runs["2 workers"]]
        out = {"scaling": [a / b for a, b in zip(w1, w2, strict=True)]}
        if "LocalCluster" in self.runs:
            out["overhead"] = [100 * (d / b - 1) for (d, _), b in
                               zip(self.runs["LocalCluster"], w2, strict=True)]
        if "svzerod" in self.runs:
            assert self.svz is not None
            per_run = [s / len(self.svz.picks) for s, _ in self.runs["svzerod"]]
            out["svzerod"] = [p / (b / self.size.n) for p, b in zip(per_run, w2, strict=True)]
        return out

    def best(self, config: str) -> tuple[float, float, float]:
        """(best wall, its CPU, median wall) of ``config``."""
        runs = self.runs[config]
        wall, used = min(runs)
        return wall, used, float(np.median([w for w, _ in runs]))


def spread(values: list[float], fmt: str) -> str:
    """``median (min–max)`` of per-round values."""
    if len(values) == 1:
        return format(values[0], fmt)
    return (f"{format(float(np.median(values)), fmt)} ({format(min(values), fmt)}–"
            f"{format(max(values), fmt)})")


#: iterations of the machine-scaling reference loop (~0.4 s of one core)
REFERENCE_LOOP = 4_000_000


def machine_scaling() -> float:
    """The machine's own 1 → 2 scaling right now: 2 × the wall time of one process running a
    CPU-bound Python loop over that of two such processes at once. On a shared or
    frequency-scaled host (2 vCPUs that share a physical core, a turbo that drops with both
    cores busy) it is below 2; an ensemble's scaling cannot exceed it."""
    import subprocess

    cmd = [sys.executable, "-c", f"s = 0\nfor i in range({REFERENCE_LOOP}): s += i * i"]

    def wall(n: int) -> float:
        t0 = time.perf_counter()
        procs = [subprocess.Popen(cmd) for _ in range(n)]
        for p in procs:
            p.wait()
        return time.perf_counter() - t0

    one = min(wall(1), wall(1))
    return 2 * one / wall(2)


#: calls of a 2-variant ensemble that measure the cluster's fixed cost per call
FIXED_CALLS = 7


def fixed_cost(size: Size, client: Any) -> str:
    """The LocalCluster's fixed cost per ``simulate_ensemble`` call: the median wall time of
    :data:`FIXED_CALLS` calls of a 2-variant ensemble on the cluster minus that of the same
    calls on local threads (workers=2), and the local ensemble duration above which the
    cluster's overhead stays within 15 % (fixed cost / 0.15, if the per-variant work costs
    the same in both)."""
    two = size.patches[:2]

    def median_wall(**kw: Any) -> float:
        walls = []
        for _ in range(FIXED_CALLS):
            t0 = time.perf_counter()
            oxyline.simulate_ensemble(size.model, two, progress=False, **size.settings, **kw)
            walls.append(time.perf_counter() - t0)
        return float(np.median(walls))

    local, remote = median_wall(workers=2), median_wall(client=client)
    fixed = remote - local
    return (f"{size.name}: LocalCluster fixed cost per call {1e3 * fixed:.0f} ms (median of "
            f"{FIXED_CALLS} calls of a 2-variant ensemble: {1e3 * remote:.0f} ms on the cluster, "
            f"{1e3 * local:.0f} ms on local threads); <= +15 % needs a local ensemble run of "
            f"{max(fixed, 0) / 0.15:.2f} s or more.")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 rounds (the headline tables)")
    ap.add_argument("--sizes", default="tree-64,tree-1000,pwdb-200")
    ap.add_argument("--vessels", type=int, default=31, help="vessels of the svzerod tree")
    ap.add_argument("--cycles", type=int, default=networks.CYCLES)
    ap.add_argument("--pts", type=int, default=networks.PTS_PER_CYCLE)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--svzerod-runs", type=int, default=64,
                    help="svzerod runs per size and round (variants spread evenly)")
    ap.add_argument("--parts", default="svzerod,dask", help="besides the thread scaling")
    ap.add_argument("--output", default=str(HERE / "results.md"))
    args = ap.parse_args(argv)
    if args.quick:
        args.rounds = 3

    sizes = [Size(name, args) for name in args.sizes.split(",")]
    rows = [Rounds(s, Svzerod(s, args.svzerod_runs)
                   if s.cfg is not None and "svzerod" in args.parts else None) for s in sizes]
    # warm-up (imports, first assembly), not timed
    for size in sizes:
        oxyline.simulate_ensemble(size.model, size.patches[:2], progress=False, **size.settings)
    now = datetime.datetime.now(datetime.timezone.utc)
    t_start = time.perf_counter()
    client = cluster = None
    notes: list[str] = []
    if "dask" in args.parts:
        from distributed import Client, LocalCluster

        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        start = time.perf_counter() - t0
        for size in sizes:  # the workers import oxyline and hold the model
            oxyline.simulate_ensemble(size.model, size.patches[:2], client=client,
                                      progress=False, **size.settings)
        time.sleep(2.0)  # the worker processes' start-up settles
        c0, w0, t0 = cpu(), cluster_cpu(client), time.perf_counter()
        time.sleep(2.0)
        idle = (cpu() - c0 + cluster_cpu(client) - w0) / (time.perf_counter() - t0)
        notes.append(f"LocalCluster started once before the rounds ({start:.1f} s) with one "
                     f"warm-up ensemble of 2 variants per size, not timed; idle, it (the "
                     f"scheduler in this process and its 2 worker processes) used {idle:.3f} "
                     "CPU-s per second beside the local runs.")
    machine: list[float] = []
    try:
        for r in range(args.rounds):
            for row in rows:
                configs = row.configs(client)
                k = r % len(configs)
                order = configs[k:] + configs[:k]
                print(f"round {r + 1}/{args.rounds} {row.size.name}: {', '.join(order)} ...",
                      file=sys.stderr, flush=True)
                for config in order:
                    row.measure(config, client, first=r == 0)
                row.loads.append(os.getloadavg()[0])
                if r == 0:
                    row.checks()
            machine.append(machine_scaling())
        fixed = fixed_cost(sizes[0], client) if client is not None else None
    finally:
        if client is not None:
            client.close()
            cluster.close()
    elapsed = time.perf_counter() - t_start
    lines = [f"## Ensembles (bench_ensemble.py), {now:%Y-%m-%d %H:%M} UTC", "",
             (f"{os.cpu_count()} x {platform.processor() or platform.machine()}, oxyline "
              f"{oxyline.__version__}; {args.rounds} rounds, each running every configuration "
              "of a size once (order rotated per round); ratios formed within a round, "
              "median (min–max) over the rounds; load = 1-min load average after each round. "
              "Targets: 1 -> 2 workers >= 1.8x, >= 50x a loop of svzerod runs, "
              "LocalCluster (2 worker processes x 1 thread) <= +15 % over local threads "
              f"(workers=2). Whole bench {elapsed / 60:.1f} min."), ""]
    lines += [f"* {s.name}: {s.what}" for s in sizes] + [""]
    lines += ["| ensemble | variants | configuration | best (s) | CPU of best (s) | median (s) |",
              "|---|---:|---|---:|---:|---:|"]
    for row in rows:
        for config in CONFIGS:
            if config in row.runs:
                wall, used, med = row.best(config)
                what = config if config != "svzerod" else (
                    f"svzerod loop, {len(row.svz.picks)} runs" if row.svz else config)
                lines.append(f"| {row.size.name} | {row.size.n} | {what} | {wall:.2f} | "
                             f"{used:.2f} | {med:.2f} |")
    lines += ["", ("| ensemble | scaling 1 -> 2 workers | vs svzerod (per variant) | "
                   "LocalCluster overhead | load |"), "|---|---:|---:|---:|---:|"]
    for row in rows:
        rat = row.ratios()
        sv = (f"**{spread(rat['svzerod'], '.1f')}x**" + (
            "" if row.svz is None or len(row.svz.picks) == row.size.n else
            f" ({len(row.svz.picks)} of the {row.size.n} variants in svzerod)")
            if "svzerod" in rat else "n/a")
        ov = f"**{spread(rat['overhead'], '+.0f')} %**" if "overhead" in rat else "-"
        lines.append(f"| {row.size.name} | **{spread(rat['scaling'], '.2f')}x** | {sv} | {ov} | "
                     f"{spread(row.loads, '.2f')} |")
    lines += ["", (f"Machine 1 -> 2 scaling in the same rounds (2 processes of a CPU-bound "
                   f"Python loop against 1): {', '.join(f'{m:.2f}x' for m in machine)}."), ""]
    for row in rows:
        rat = row.ratios()
        per = "; ".join(f"{k} " + ", ".join(f"{v:.2f}" for v in vals) for k, vals in rat.items())
        notes.append(f"{row.size.name} per round: {per}.")
        notes += row.notes
    if fixed is not None:
        notes.append(fixed)
    lines += [f"* {n}" for n in notes]
    text = "\n".join(lines)
    print(text)
    if args.output:
        with open(args.output, "a") as f:
            f.write("\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
