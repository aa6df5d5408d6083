"""Where does the memory of a whole-tree run go? Resident set size after each stage of loading
and running one tree of ``bench_scale.py``, in one fresh process.

    python benches/profile_memory.py --depth 16 --config o2-k

Stages: the user's model dict (``tree``), the Python copy and checks (``_copy`` + canonical),
the user's dict dropped (the model crosses once), the core network (``_core.Network``: parse, assembly, DAE, transport plan; the JSON text is
built and dropped inside), and ``simulate`` (one cycle of generalized-α at 1 ms, vessel output
every 10 ms). ``rss`` is the resident set after the stage, ``peak`` the high-water mark so far
(``VmHWM``), both in MB and in bytes per segment.
"""

from __future__ import annotations

import argparse
import gc
import time


def rss() -> tuple[float, float]:
    """(current, peak) resident set in bytes, from /proc/self/status."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            k, _, v = line.partition(":")
            if k in ("VmRSS", "VmHWM"):
                out[k] = float(v.split()[0]) * 1024.0
    return out["VmRSS"], out["VmHWM"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depth", type=int, default=14)
    ap.add_argument("--config", default="o2-k")
    ap.add_argument("--no-run", action="store_true")
    ap.add_argument("--series", action="store_true",
                    help="record the large-model variables as time series of every vessel "
                         "(the default before the per-vessel summary) instead of the default")
    ap.add_argument("--large-threshold", type=int, default=None,
                    help="set oxyline.run.LARGE_MODEL_SEGMENTS (e.g. 1 at depth 16: the "
                         "large-model default output on a 262 k-segment tree)")
    a = ap.parse_args()

    from bench_scale import tree

    import oxyline

    if a.large_threshold is not None:
        import oxyline.run

        oxyline.run.LARGE_MODEL_SEGMENTS = a.large_threshold
    segments = (2 ** a.depth - 1) * 4
    rows: list[tuple[str, float, float, float]] = []

    def mark(stage: str, t0: float) -> float:
        now, peak = rss()
        rows.append((stage, time.process_time() - t0, now, peak))
        return time.process_time()

    t = mark("interpreter + oxyline", time.process_time())
    model = tree(a.depth, 4, a.config)
    t = mark("user model dict", t)
    m = oxyline.load_model(model)
    del model  # the model crosses once: load_model keeps its own copy
    gc.collect()
    t = mark("load_model (copy, checks, core network), user dict dropped", t)
    if not a.no_run:
        samples: list[tuple[float, float, float, float]] = []  # (t, CPU, rss, peak)

        def progress(t: float, t_end: float) -> None:
            # the core reports every few hundred steps: the first report is after the run's
            # setup (steady state, LU, plan state), the last one just before the output is
            # handed to Python
            samples.append((t, time.process_time(), *rss()))

        kw = {}
        if a.series:
            from oxyline import run

            kw["variables"] = list(run.LARGE_MODEL_VARIABLES) + (
                list(run.LARGE_MODEL_SPECIES_VARIABLES) if m.transport_spec else [])
        res = oxyline.simulate(m, cycles=1, dt=1e-3, output_every=0.01, segments=False,
                               method="generalized-alpha", progress=progress, **kw)
        for label, (tt, cpu, now, peak) in (("run: first progress report", samples[0]),
                                            ("run: last progress report", samples[-1])):
            rows.append((f"{label} (t = {tt:.3f} s)", cpu - t, now, peak))
        t = mark("simulate (result kept)", t)
        print("recorded vessel variables:", *res.vessel_variables,
              *(v for sp in res.species.values() for v in sp.vessel_variables))
        out = res.data.nbytes + sum(sp.vessel_data.base.nbytes if sp.vessel_data.base is not None
                                    else sp.vessel_data.nbytes for sp in res.species.values())
        if res.vessel_summary is not None:  # the large-model default: per-vessel summary
            out += int(res.vessel_summary.memory_usage(deep=True).sum())
        del res
        gc.collect()
        t = mark("result dropped", t)
        print(f"output arrays: {out / 1e6:.0f} MB ({out / segments:.0f} B/segment)")
    print(f"# depth {a.depth}, {segments} segments, config {a.config}")
    print("| stage | CPU s | rss MB | B/seg | peak MB | peak B/seg |")
    print("|---|---:|---:|---:|---:|---:|")
    for stage, cpu, now, peak in rows:
        print(f"| {stage} | {cpu:.2f} | {now / 1e6:.0f} | {now / segments:.0f} "
              f"| {peak / 1e6:.0f} | {peak / segments:.0f} |")


if __name__ == "__main__":
    main()
