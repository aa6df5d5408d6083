"""Peak memory of writing a large all-cycles output to Zarr: in memory then ``Result.to_zarr``,
versus ``oxyline.simulate_to_zarr`` (written during the run, one chunk at a time).

Each path runs in a fresh subprocess (model built before the clock starts) on a ``tree N``
network of ``networks.py`` with every cycle output; the child reports wall time, peak RSS
(``ru_maxrss``, including the interpreter and imports) and its growth above the RSS just before
the run::

    python benches/bench_zarr.py                      # tree 1e4, 3 cycles, 1000 points/cycle
    python benches/bench_zarr.py --n 1000 --cycles 10 --time-chunk 256
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def _current_rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def child(mode: str, n: int, cycles: int, time_chunk: int, out: str) -> None:
    sys.path.insert(0, str(HERE))
    import networks

    import oxyline

    model = oxyline.load_model(networks.tree(n, cycles=cycles))
    opts = {"cycles": cycles, "output_cycles": "all", "progress": False}
    before = _current_rss_mb()
    t0 = time.perf_counter()
    if mode == "stream":
        ds = oxyline.simulate_to_zarr(model, out, time_chunk=time_chunk, **opts)
        rows, cols = ds.sizes["time"], ds.sizes["vessel"]
    else:
        res = oxyline.simulate(model, **opts)
        res.to_zarr(out, time_chunk=time_chunk)
        rows, cols = len(res.time), len(res.vessels)
    wall = time.perf_counter() - t0
    size = sum(f.stat().st_size for f in Path(out).rglob("*") if f.is_file())
    print(json.dumps({"mode": mode, "wall_s": wall, "peak_rss_mb": _rss_mb(),
                      "growth_mb": _rss_mb() - before, "rows": rows, "columns": cols,
                      "store_mb": size / 2**20}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=float, default=1e4, help="vessels of the tree (default 1e4)")
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--time-chunk", type=int, default=256)
    ap.add_argument("--child", nargs=2, metavar=("MODE", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], int(args.n), args.cycles, args.time_chunk, args.child[1])
        return
    tmp = Path(tempfile.mkdtemp(prefix="bench_zarr_"))
    try:
        rows = []
        for mode in ("memory", "stream"):
            out = tmp / f"{mode}.zarr"
            p = subprocess.run([sys.executable, __file__, "--n", str(args.n), "--cycles",
                                str(args.cycles), "--time-chunk", str(args.time_chunk),
                                "--child", mode, str(out)],
                               check=True, capture_output=True, text=True)
            rows.append(json.loads(p.stdout.strip().splitlines()[-1]))
            shutil.rmtree(out, ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    r = rows[0]
    print(f"tree {int(args.n)}, {args.cycles} cycles all output: {r['rows']} rows, "
          f"time chunk {args.time_chunk}, store {r['store_mb']:.0f} MB")
    print(f"{'path':<8}{'wall [s]':>10}{'peak RSS [MB]':>15}{'growth [MB]':>13}")
    for r in rows:
        print(f"{r['mode']:<8}{r['wall_s']:>10.1f}{r['peak_rss_mb']:>15.0f}{r['growth_mb']:>13.0f}")


if __name__ == "__main__":
    main()
