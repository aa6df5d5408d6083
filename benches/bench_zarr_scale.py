"""A large run's segment output streamed to Zarr, and the per-region O2 delivery from the store.

The tree is ``benches/bench_scale.py``'s symmetric binary tree (``2^depth - 1`` vessels in
heap order, ``--per-vessel`` segments each, Murray radii, RCR outlets) with O2 through a
constant-k wall (``o2-k``). One cycle, generalized-alpha at dt = 1 ms, is written by
``oxyline.simulate_to_zarr`` with one segment variable, the wall O2 flux
(``segment_wall_flux``, stored as ``segment_wall_o2_flux``), every ``--output-every`` seconds;
``time_chunk`` is left to the memory budget unless ``--time-chunk`` is given. Then, in a fresh
process, the store is opened lazily (``xarray.open_zarr(chunks={})``) and the O2 delivered to
each region is computed with Dask by ``oxyline.io.regions.region_sum``: a region is the
subtree of one vessel of generation ``--generation`` (2^g regions), plus the trunk above
them, from the integer region code of each vessel (its heap index's ancestor), never a
per-segment string.

Printed per size: segments, the run's CPU and wall time, its peak RSS (``VmHWM`` of a fresh
process: the model, its run and the streamed rows), the rows per chunk, the store's size on
disk, the analysis' CPU, wall and peak RSS, and two checks of the delivery:

* ``Σ regions / Σ segments``: the regions' sum against the whole tree's uptake summed over the
  segment axis directly (no grouping): conservation of the grouping, to rounding;
* ``Σ regions / balance``: against the core's own record of the O2 taken up through the walls
  over the cycle (``o2_mass_wall_uptake``, integrated over every step), which the trapezoidal
  mean of the output rows approximates (to ~1e-3 at 10 ms output spacing).

CPU times are the process's own (robust on a loaded machine); wall times are only meaningful
on an idle machine.

    python benches/bench_zarr_scale.py --depths 15 18               # 131 k and 1.05 M segments
    python benches/bench_zarr_scale.py --depths 21 --threads 2 --dir /big/disk   # 10.5 M
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

VARIABLE = "segment_wall_o2_flux"


def vm_hwm_mb() -> float:
    """Peak resident memory of this process (VmHWM), MB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) * 1024 / 1e6
    return float("nan")


def run(spec: dict[str, Any]) -> dict[str, Any]:
    """Load the tree and stream one cycle's wall O2 flux per segment to the store."""
    from bench_scale import tree

    import oxyline

    c0, w0 = time.process_time(), time.perf_counter()
    m = oxyline.load_model(tree(spec["depth"], spec["per_vessel"], "o2-k"))
    c1, w1 = time.process_time(), time.perf_counter()
    kw: dict[str, Any] = {"cycles": 1, "method": "generalized-alpha", "dt": 1e-3,
                          "output_every": spec["output_every"], "segments": True,
                          "variables": ["segment_wall_flux"]}
    if spec.get("threads"):
        kw["threads"] = spec["threads"]
    ds = oxyline.simulate_to_zarr(m, spec["path"], time_chunk=spec.get("time_chunk"),
                                  overwrite=True, **kw)
    c2, w2 = time.process_time(), time.perf_counter()
    return {"segments": int(ds.sizes["segment"]), "rows": int(ds.sizes["time"]),
            "chunk": list(ds[VARIABLE].encoding["chunks"]),
            "load_cpu": c1 - c0, "load_wall": w1 - w0, "run_cpu": c2 - c1, "run_wall": w2 - w1,
            "peak_mb": vm_hwm_mb()}


def vessel_regions(names: Any, generation: int) -> tuple[Any, list[str]]:
    """Region code of each vessel ``v{heap index}``: the index of its ancestor in
    ``generation`` among that generation's 2^g vessels, or 2^g (the trunk) above it."""
    import numpy as np

    heap = np.char.lstrip(np.asarray(names, dtype=str), "v").astype(np.int64)
    level = np.frexp(heap + 1)[1].astype(np.int64) - 1  # exact: floor(log2(heap + 1))
    first = 2**generation - 1
    below = level >= generation
    ancestor = ((heap + 1) >> np.where(below, level - generation, 0)) - 1
    codes = np.where(below, ancestor - first, 2**generation).astype(np.int32)
    labels = [f"v{first + k}" for k in range(2**generation)] + ["trunk"]
    return codes, labels


def analyse(spec: dict[str, Any]) -> dict[str, Any]:
    """The per-region cycle-mean O2 delivery from the store, lazily with Dask."""
    import xarray as xr

    from oxyline.io.regions import region_sum

    c0, w0 = time.process_time(), time.perf_counter()
    ds = xr.open_zarr(spec["path"], chunks={})
    codes, labels = vessel_regions(ds["vessel"].values, spec["generation"])
    per_region = region_sum(ds, VARIABLE, codes, labels)
    t = ds["time"].values
    period = float(t[-1] - t[0])
    delivery = (per_region.integrate("time") / period).compute()
    c1, w1 = time.process_time(), time.perf_counter()
    whole = float((ds[VARIABLE].sum("segment").integrate("time") / period).compute())
    uptake = ds["o2_mass_wall_uptake"].values
    balance = float(uptake[-1] - uptake[0]) / period
    total = float(delivery.sum())
    return {"analysis_cpu": c1 - c0, "analysis_wall": w1 - w0, "analysis_peak_mb": vm_hwm_mb(),
            "regions": len(labels), "delivery_mol_s": total,
            "vs_segments": total / whole - 1.0, "vs_balance": total / balance - 1.0,
            "largest_region": f"{labels[int(delivery.argmax())]} "
                              f"{float(delivery.max()) / total:.3f}"}


def child(kind: str, spec: dict[str, Any]) -> dict[str, Any]:
    p = subprocess.run([sys.executable, __file__, "--child", kind, json.dumps(spec)],
                       capture_output=True, text=True, check=False)
    if p.returncode != 0:
        raise SystemExit(f"{kind} failed:\n{p.stderr[-4000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def du_mb(path: str) -> float:
    return sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file()) / 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    ap.add_argument("--depths", type=int, nargs="+", default=[15, 18])
    ap.add_argument("--per-vessel", type=int, default=4)
    ap.add_argument("--output-every", type=float, default=0.01, help="s (default 0.01)")
    ap.add_argument("--time-chunk", type=int, default=None,
                    help="rows per chunk (default: chosen from the memory budget)")
    ap.add_argument("--generation", type=int, default=3, help="regions: subtrees of this "
                    "generation's vessels (2^g of them) and the trunk above")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--dir", default=None, help="where the stores go (default: a temporary "
                    "directory, removed after each size)")
    a = ap.parse_args()
    if a.child:
        print(json.dumps({"run": run, "analyse": analyse}[a.child[0]](json.loads(a.child[1]))))
        return
    print(f"{'segments':>10} {'rows':>5} {'chunk':>11} {'run CPU s':>9} {'run wall s':>10} "
          f"{'run peak MB':>11} {'store MB':>9} {'anal. CPU s':>11} {'anal. wall s':>12} "
          f"{'anal. peak MB':>13} {'Σreg/Σseg-1':>11} {'Σreg/bal-1':>10}", flush=True)
    for depth in a.depths:
        d = tempfile.mkdtemp(prefix="zarr-scale-", dir=a.dir)
        try:
            spec = {"depth": depth, "per_vessel": a.per_vessel, "output_every": a.output_every,
                    "time_chunk": a.time_chunk, "threads": a.threads,
                    "generation": a.generation, "path": os.path.join(d, f"tree{depth}.zarr")}
            r = child("run", spec)
            size = du_mb(spec["path"])
            q = child("analyse", spec)
            print(f"{r['segments']:>10} {r['rows']:>5} {'x'.join(map(str, r['chunk'])):>11} "
                  f"{r['run_cpu']:>9.1f} {r['run_wall']:>10.1f} {r['peak_mb']:>11.0f} "
                  f"{size:>9.1f} {q['analysis_cpu']:>11.2f} {q['analysis_wall']:>12.2f} "
                  f"{q['analysis_peak_mb']:>13.0f} {q['vs_segments']:>11.1e} "
                  f"{q['vs_balance']:>10.1e}", flush=True)
            print(f"    load {r['load_cpu']:.1f} s CPU; {q['regions']} regions, delivery "
                  f"{q['delivery_mol_s']:.4e} mol/s, largest share {q['largest_region']}",
                  flush=True)
        finally:
            if a.dir is None:
                shutil.rmtree(d, ignore_errors=True)


if __name__ == "__main__":
    main()
