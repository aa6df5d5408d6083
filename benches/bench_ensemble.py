"""Ensembles (``oxyline.simulate_ensemble``): thread scaling, throughput against a loop of
svZeroDSolver runs, and the overhead of a Dask LocalCluster.

The network is the svzerod tree of ``benches/networks.py`` (``--vessels`` vessels, svzerod's
settings: ``--cycles`` cycles of ``--pts`` points, generalized-alpha), read through the
svZeroDSolver drop-in (``oxyline.svzerod.to_model``). Variant k scales every resistance (the
vessels' ``R_poiseuille`` and the outlets' ``R``) by a factor in [0.8, 1.2]: in oxyline the
patch ``{"scale": {"resistance": f}}``, in svzerod the same numbers written into a copy of the
configuration.

1. Thread scaling: the ensemble with ``workers=1`` and ``workers=2`` (summary output).
2. svzerod: a Python loop of ``svzerod.simulate(config_k)`` (the svzerod PyPI package; each
   call returns its DataFrame) against one ``simulate_ensemble`` (every core, summary output).
   The mean inlet pressures of both are compared as a check that the networks are the same.
3. Dask: ``LocalCluster(n_workers=2, threads_per_worker=1)`` against local threads
   (``workers=2``), after one warm-up ensemble on the cluster (the workers import oxyline).

Wall times are the best of ``--repeat``; CPU time (user + system of this process and its
threads) is reported beside them because this machine is shared: the 1-min load average is
printed with every table. Results are printed as Markdown and appended to
``benches/results.md`` (``--output ''`` for none).
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


def timed(fn: Any, repeat: int) -> tuple[float, float, Any]:
    """(best wall time, CPU time of that call, its value) over ``repeat`` calls."""
    best = (np.inf, np.nan, None)
    for _ in range(repeat):
        c0, t0 = cpu(), time.perf_counter()
        value = fn()
        wall, used = time.perf_counter() - t0, cpu() - c0
        if wall < best[0]:
            best = (wall, used, value)
    return best


def load() -> str:
    return f"{os.getloadavg()[0]:.2f}"


def scaling(model: Any, patches: list[dict[str, Any]], repeat: int) -> list[str]:
    rows = ["| workers | wall (s) | CPU (s) | variants/s | speed-up | load |",
            "|---:|---:|---:|---:|---:|---:|"]
    base = None
    for w in (1, 2):
        wall, used, ds = timed(lambda w=w: oxyline.simulate_ensemble(
            model, patches, workers=w, progress=False), repeat)
        assert (ds.status.values == 0).all(), ds.error.values
        base = base or wall
        rows.append(f"| {w} | {wall:.2f} | {used:.2f} | {len(patches) / wall:.1f} | "
                    f"{base / wall:.2f} | {load()} |")
    return rows


def versus_svzerod(cfg: dict[str, Any], model: Any, patches: list[dict[str, Any]],
                   repeat: int) -> list[str]:
    import svzerod

    configs = [svzerod_config(cfg, f) for f in factors(len(patches))]

    def loop() -> list[Any]:
        return [svzerod.simulate(c) for c in configs]

    sv_wall, sv_cpu, frames = timed(loop, repeat)
    ox_wall, ox_cpu, ds = timed(lambda: oxyline.simulate_ensemble(
        model, patches, progress=False), repeat)
    # the same networks: the time-averaged inlet pressure of the root vessel, variant by
    # variant, both in Pa (svzerod reports in its file's units, cgs here: dyn/cm^2 = 0.1 Pa)
    root = model.vessel_names[0]
    to_si = units.factor(dropin.file_units(cfg), "pressure")
    sv_mean = np.array([time_average(f[f["name"] == root], "pressure_in") * to_si
                        for f in frames])
    ox_mean = ds.pressure_in_mean.sel(vessel=root).values
    diff = float(np.max(np.abs(ox_mean / sv_mean - 1)))
    # both are the same generalized-alpha scheme on the same linear circuit and output times:
    # they differ by round-off (1e-15 measured), far below 1e-6; another network, or a units
    # mix-up (a factor 10), is far above it. (The plain mean of svzerod's output rows, equal
    # weights instead of the trapezoidal rule's half weights at the ends, differs by ~7e-4.)
    if not diff < SAME_NETWORK_RTOL:
        raise SystemExit(f"oxyline and svzerod disagree: root-vessel time-averaged inlet "
                         f"pressure differs by {diff:.1e} (relative) > {SAME_NETWORK_RTOL:g}")
    return ["| solver | wall (s) | CPU (s) | variants/s | throughput ratio | load |",
            "|---|---:|---:|---:|---:|---:|",
            (f"| svzerod loop | {sv_wall:.2f} | {sv_cpu:.2f} | {len(configs) / sv_wall:.2f} | 1 | "
            f"{load()} |"),
            (f"| oxyline ensemble | {ox_wall:.2f} | {ox_cpu:.2f} | {len(patches) / ox_wall:.2f} | "
            f"{sv_wall / ox_wall:.1f} | {load()} |"),
            "",
            (f"Root-vessel time-averaged inlet pressure (trapezoidal rule over the last cycle's "
            f"output rows, in Pa), oxyline vs svzerod: max relative difference {diff:.1e} over "
            f"the variants (check: < {SAME_NETWORK_RTOL:g}).")]


def versus_cluster(model: Any, patches: list[dict[str, Any]], repeat: int) -> list[str]:
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        start = time.perf_counter() - t0
        t0 = time.perf_counter()
        oxyline.simulate_ensemble(model, patches[:4], client=client, progress=False)
        warm = time.perf_counter() - t0
        local_wall, _, local = timed(lambda: oxyline.simulate_ensemble(
            model, patches, workers=2, progress=False), repeat)
        dask_wall, _, remote = timed(lambda: oxyline.simulate_ensemble(
            model, patches, client=client, progress=False), repeat)
    same = bool((local.pressure_in_mean.values == remote.pressure_in_mean.values).all())
    return ["| run | wall (s) | overhead | load |", "|---|---:|---:|---:|",
            f"| local threads (workers=2) | {local_wall:.2f} | - | {load()} |",
            (f"| LocalCluster, 2 workers x 1 thread | {dask_wall:.2f} | "
            f"{100 * (dask_wall / local_wall - 1):+.0f} % | {load()} |"),
            "",
            (f"Cluster start {start:.1f} s and first (warm-up) ensemble {warm:.1f} s, not "
            f"included. Results bit-identical to the local run: {same}.")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", type=int, default=64)
    ap.add_argument("--vessels", type=int, default=31, help="vessels of the svzerod tree")
    ap.add_argument("--cycles", type=int, default=networks.CYCLES)
    ap.add_argument("--pts", type=int, default=networks.PTS_PER_CYCLE)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--parts", default="scaling,svzerod,dask")
    ap.add_argument("--output", default=str(HERE / "results.md"))
    args = ap.parse_args(argv)

    cfg = networks.build("tree", args.vessels, args.cycles, args.pts)
    model = dropin.to_model(cfg)
    patches = [{"scale": {"resistance": float(f)}} for f in factors(args.variants)]
    # warm-up (imports, first assembly), not timed
    oxyline.simulate_ensemble(model, patches[:2], progress=False)
    now = datetime.datetime.now(datetime.timezone.utc)
    lines = [f"## Ensembles (bench_ensemble.py), {now:%Y-%m-%d %H:%M} UTC", "",
             (f"{os.cpu_count()} x {platform.processor() or platform.machine()}, oxyline "
             f"{oxyline.__version__}; svzerod tree of {args.vessels} vessels, {args.cycles} "
             f"cycles x {args.pts} points, {args.variants} variants (resistances x 0.8-1.2), "
             f"summary output; best of {args.repeat}. Load = 1-min load average after the row "
             "(the machine is shared: compare rows of one table)."), ""]
    parts = {"scaling": ("Thread scaling", scaling),
             "svzerod": ("Throughput against a loop of svzerod runs", None),
             "dask": ("Dask LocalCluster against local threads", versus_cluster)}
    for part in args.parts.split(","):
        title, fn = parts[part]
        print(f"{title} ...", file=sys.stderr, flush=True)
        rows = (versus_svzerod(cfg, model, patches, args.repeat) if part == "svzerod"
                else fn(model, patches, args.repeat))
        lines += [f"### {title}", "", *rows, ""]
    text = "\n".join(lines)
    print(text)
    if args.output:
        with open(args.output, "a") as f:
            f.write("\n" + text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
