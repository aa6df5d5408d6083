"""How evenly ``simulate_ensemble(..., client=...)`` keeps the workers of a LocalCluster busy:
the chunking in use ("balanced": many tasks that Dask queues and hands out) against the
session-11 one ("pinned": one task per worker thread, each pinned to its worker), run
alternately on the same cluster in rounds, from Dask's task stream.

    python benches/cluster_balance.py --sizes pwdb-200,tree-1000 --rounds 2

Each round also runs the ensemble on 2 local threads (``workers=2``; its CPU is
this process's), and every cluster wall time is divided by that round's (``/ local``); the
order is rotated from round to round. Per run and worker: its busy time (the compute spans of
its tasks), its CPU time (user + system of the worker process over the run: the work it was
given, independent of the load) and its idle tail (from its last task's end to the last
task's end on any worker), as fractions of the run's wall time (submission to the returned
dataset); the run's wall time and the 1-min load average. The sizes are those of
``bench_ensemble.py``; every cluster result is checked bit-identical to the local one.
Prints Markdown.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_ensemble as B
import networks
import xarray as xr

from oxyline.ensemble import cluster as C


def pinned_plan(n: int, nthreads: Any) -> tuple[list[range], list[str | None]]:
    """The earlier chunking: one task per worker thread (more, up to 4 per thread, only
    while each keeps 256 variants), every task pinned to a worker thread in turn."""
    threads = max(1, sum(nthreads.values()))
    per_thread = max(1, min(4, n // (threads * 256)))
    tasks = max(1, min(n, threads * per_thread))
    chunks = [range(j, n, tasks) for j in range(tasks)]
    return chunks, C._placement(nthreads, len(chunks))


DEFAULTS = C.TASKS_PER_THREAD, C.MIN_TASK_VARIANTS
PLANS = {"pinned": pinned_plan, "balanced": C._plan}


def local(size: B.Size) -> dict[str, Any]:
    """The same ensemble on 2 local threads (the LocalCluster's reference)."""
    c0, t0 = B.cpu(), time.time()
    ds = size.run(workers=2)
    wall = time.time() - t0
    return {"ds": ds, "wall": wall, "workers": {}, "load": os.getloadavg()[0],
            "cpu": B.cpu() - c0}


def run(size: B.Size, client: Any, plan: str) -> dict[str, Any]:
    from distributed import get_task_stream

    if plan == "local":
        return local(size)
    name, *knobs = plan.split(":")
    C._plan = PLANS[name]
    if knobs:  # "balanced:16:8": at most 16 tasks per thread, of at least 8 variants
        C.TASKS_PER_THREAD = int(knobs[0])
    if len(knobs) > 1:
        C.MIN_TASK_VARIANTS = int(knobs[1])
    try:
        cpu0 = client.run(B.cpu)
        with get_task_stream(client) as stream:
            t0 = time.time()
            ds = size.run(client=client)
            t1 = time.time()
        cpu1 = client.run(B.cpu)
    finally:
        C._plan, C.TASKS_PER_THREAD, C.MIN_TASK_VARIANTS = PLANS["balanced"], *DEFAULTS
    spans: dict[str, list[tuple[float, float]]] = {w: [] for w in cpu0}
    for rec in stream.data:
        if str(rec["key"]).startswith("run_chunk"):
            spans[rec["worker"]] += [(s["start"], s["stop"]) for s in rec["startstops"]
                                     if s["action"] == "compute"]
    wall = t1 - t0
    end = max(stop for s in spans.values() for _, stop in s)
    workers = {w: {"tasks": len(s), "busy": sum(b - a for a, b in s) / wall,
                   "cpu": (cpu1[w] - cpu0[w]) / wall,
                   "tail": (end - max((b for _, b in s), default=t0)) / wall}
               for w, s in sorted(spans.items())}
    cpu = sum(cpu1[w] - cpu0[w] for w in cpu0)
    return {"ds": ds, "wall": wall, "workers": workers, "load": os.getloadavg()[0], "cpu": cpu}


def per_worker(workers: list[dict[str, Any]], key: str) -> str:
    return " / ".join(f"{w[key]:.2f}" for w in workers)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="pwdb-200,tree-1000")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--plans", default="pinned,balanced,local")
    ap.add_argument("--vessels", type=int, default=31)
    ap.add_argument("--cycles", type=int, default=networks.CYCLES)
    ap.add_argument("--pts", type=int, default=networks.PTS_PER_CYCLE)
    args = ap.parse_args(argv)
    from distributed import Client, LocalCluster

    sizes = [B.Size(name, args) for name in args.sizes.split(",")]
    plans = args.plans.split(",")
    print("| ensemble | chunking | round | tasks per worker | wall (s) | / local | workers' CPU "
          "(s) | busy / wall per worker | CPU / wall per worker | idle tail / wall per worker "
          "| load |")
    print("|---|---|---:|---|---:|---:|---:|---|---|---|---:|")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        for size in sizes:  # the workers import oxyline and hold the model
            size.run(client=client)
            reference = size.run(workers=2)  # local threads: the cluster's results must equal
            for r in range(args.rounds):
                order = plans[r % len(plans):] + plans[:r % len(plans)]
                outs = {plan: run(size, client, plan) for plan in order}
                for plan in plans:
                    out = outs[plan]
                    xr.testing.assert_identical(out["ds"], reference)
                    ws = list(out["workers"].values())
                    ratio = (f"{out['wall'] / outs['local']['wall']:.2f}" if "local" in outs
                             else "")
                    print(f"| {size.name} | {plan} | {r + 1} | "
                          f"{' / '.join(str(w['tasks']) for w in ws)} | {out['wall']:.2f} | "
                          f"{ratio} | {out['cpu']:.2f} | "
                          f"{per_worker(ws, 'busy')} | {per_worker(ws, 'cpu')} | "
                          f"{per_worker(ws, 'tail')} | {out['load']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
