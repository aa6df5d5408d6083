"""Load time of the whole-tree family of ``bench_scale.py`` (issue 9, item 3), split into the core
(``oxyline.model._network``: the hand-over of the canonical model — vessels and plain outlets
as the dicts themselves, the rest as JSON text — then parse, assembly and transport plan) and
the rest of the Python side (copy, checks, canonical dicts).

CPU seconds (``time.process_time``), best of ``--repeat`` loads in one process; the core part
is timed again on its own after each load.

    python benches/bench_load.py --depths 12 15 18 --repeat 3
"""

from __future__ import annotations

import argparse
import gc
import time

from bench_scale import tree


def measure(depth: int, config: str, repeat: int) -> dict[str, float]:
    import oxyline
    from oxyline.model import _network

    model = tree(depth, 4, config)
    best: dict[str, float] = {}
    segments = 0
    for _ in range(repeat):
        t0 = time.process_time()
        m = oxyline.load_model(model)
        t1 = time.process_time()
        segments = int(m.network.summary()["segments"])
        t2 = time.process_time()
        n = _network(m.canonical)
        t3 = time.process_time()
        for k, v in (("load", t1 - t0), ("core", t3 - t2)):
            best[k] = min(best.get(k, float("inf")), v)
        del m, n
        gc.collect()
    best["python"] = best["load"] - best["core"]
    best["segments"] = segments
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depths", type=int, nargs="+", default=[12, 15])
    ap.add_argument("--config", default="o2-k")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    print("| segments | load_model s | µs/seg | core µs/seg (hand-over, build) | rest µs/seg |")
    print("|---:|---:|---:|---:|---:|")
    for d in a.depths:
        r = measure(d, a.config, 1 if d >= 18 else a.repeat)
        us = 1e6 / r["segments"]
        print(f"| {r['segments']} | {r['load']:.3f} | {r['load'] * us:.2f} | {r['core'] * us:.2f} "
              f"| {r['python'] * us:.2f} |", flush=True)


if __name__ == "__main__":
    main()
