"""Where does the load time of a whole tree go? ``oxyline.load_model`` of one
``bench_scale.py`` tree split into its phases, each in user + system CPU and minor page
faults, in several fresh processes (the load of one fresh process varied by
more than the target's margin).

    python benches/load_phases.py --depths 14 16 18 --configs o2-k o2-leveque --repeat 3

    python benches/load_phases.py --depths 16 --route json --repeat 2
    python benches/load_phases.py --depths --builtin adan56-st --repeat 2

Phases (the same calls ``load_model`` makes, in its order): ``copy`` (the private copy of the
user's dict, ``copy_description``) or ``read`` (``--route json|yaml``: the tree written once as a
native file, read by ``oxyline.io.native.read_mapping``), ``canonical`` (checks and SI
conversion: ``_core.read_model``, which reads the whole model and the plain vessels and
outlets straight into the network's parts), ``core`` (``_core.Network.from_parts``: the core assembles the
circuit, the DAE and the transport plan), ``release`` (the output-layout check and
``release_canonical``). ``total`` is ``load_model`` as ``bench_scale.py`` times it (process
CPU); ``steady`` the steady solve a run starts from (not part of the load). A page fault of
fresh memory costs the kernel a zeroed page: its time is system CPU. ``--builtin`` times
``load_model`` of a built-in whole tree (the structured-tree builder's route). The same
script runs against an older checkout with ``PYTHONPATH=<its python dir>:benches``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from typing import Any


def usage() -> tuple[float, float, int]:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime, r.ru_stime, r.ru_minflt


def child(depth: int, config: str, route: str) -> dict[str, Any]:
    from bench_scale import tree

    from oxyline import model as M
    from oxyline.io.native import read_mapping
    from oxyline.memory import gc_paused

    out: dict[str, Any] = {"segments": (2 ** depth - 1) * 4}
    if route == "dict":
        user = tree(depth, 4, config)
    c0 = time.process_time()
    last = usage()

    def mark(phase: str) -> None:
        nonlocal last
        now = usage()
        out[phase] = (now[0] - last[0], now[1] - last[1], now[2] - last[2])
        last = now

    # the steps of loader.load_model, one by one
    with gc_paused():
        if route == "dict":
            # the private copy (oxyline.description on this branch, model._copy before)
            copy = getattr(M, "_copy", None) or M.copy_description
            data = copy(dict(user))
        else:  # a file the parent wrote: read_mapping is load_model's reader
            data = read_mapping(_file(depth, config, route))
    mark("copy" if route == "dict" else "read")
    with gc_paused():
        if hasattr(M._core, "read_model"):  # this branch: the core reads the model once
            parts, *_ = M._core.read_model(data)
            mark("canonical")
            network = M._core.Network.from_parts(parts, None)
            mark("core")
        elif hasattr(M, "_NativeReader"):  # the core reads the plain elements
            reader = M._NativeReader()
            m = M._unassembled(data, reader.vessels, reader.boundary_conditions)
            names = reader.parts.names()
            mark("canonical")
            m._network = M._network(m.canonical, None, reader.parts)
            mark("core")
            m.release_canonical(names)
            network = m.network
        else:  # before: a canonical dict per element, read by the binding
            m = M._unassembled(data)
            mark("canonical")
            network = m.network
            mark("core")
            m.release_canonical()
    mark("release")
    out["total"] = time.process_time() - c0
    network.steady_state()
    mark("steady")
    return out


def child_builtin(name: str) -> dict[str, Any]:
    """``load_model`` of a built-in whole tree (its compact dict with structured-tree
    conditions, grown on load): the structured-tree builder's route."""
    import oxyline

    d = oxyline.catalogue.load_dict(name)
    out: dict[str, Any] = {}
    last = usage()
    m = oxyline.load_model(d)
    now = usage()
    out["load"] = (now[0] - last[0], now[1] - last[1], now[2] - last[2])
    out["segments"] = m.network.summary()["segments"]
    out["vessels"] = len(m.vessel_names)
    return out


def _file(depth: int, config: str, route: str) -> str:
    return os.path.join(tempfile.gettempdir(), f"oxyline-load-phases-{depth}-{config}.{route}")


def _write(depth: int, config: str, route: str) -> None:
    """The tree as a native model file (JSON or YAML), written once per depth."""
    from bench_scale import tree

    path = _file(depth, config, route)
    if os.path.exists(path):
        return
    m = tree(depth, 4, config)
    m["boundary_conditions"] = {k: dict(v) for k, v in m["boundary_conditions"].items()}
    with open(path, "w") as f:
        if route == "json":
            json.dump(m, f)
        else:
            import yaml

            yaml.safe_dump(m, f, sort_keys=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depths", type=int, nargs="*", default=[15, 16])
    ap.add_argument("--configs", nargs="+", default=["o2-k"],
                    help="bench_scale.py configs (o2-k; o2-leveque: the default closure)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--route", choices=["dict", "json", "yaml"], default="dict",
                    help="the model as a dict (copied, as load_model does) or a file")
    ap.add_argument("--builtin", nargs="*", default=[],
                    help="also time load_model of these built-in whole trees (adan56-st)")
    ap.add_argument("--child", nargs=3)
    ap.add_argument("--child-builtin")
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(int(a.child[0]), a.child[1], a.child[2])))
        return
    if a.child_builtin:
        print(json.dumps(child_builtin(a.child_builtin)))
        return
    for name in a.builtin:
        for i in range(a.repeat):
            p = subprocess.run([sys.executable, __file__, "--child-builtin", name],
                               capture_output=True, text=True, check=True)
            r = json.loads(p.stdout.strip().splitlines()[-1])
            n, (u, s, f) = r["segments"], r["load"]
            print(f"# built-in {name}: {r['vessels']} vessels, {n} segments, run {i + 1}: "
                  f"load_model {1e6 * (u + s) / n:.2f} µs/segment ({1e6 * s / n:.2f} system), "
                  f"{1e3 * f / n:.0f} faults/kseg")
    for config in a.configs:
        table(a.depths, config, a.route, a.repeat)


def table(depths: list[int], config: str, route: str, repeat: int) -> None:
    """The phase table of one config and route, and the log-log slope of the total load time
    against segments (best run per size; the scale work's target <= 1.1)."""
    phases = ["copy" if route == "dict" else "read", "canonical", "core", "release"]
    print(f"# load_model phases, config {config}, route {route}; µs per segment: user+sys "
          "CPU (sys in brackets), minor page faults per 1000 segments; each row a fresh "
          "process; `steady`: the steady solve a run starts from (not in the total); "
          f"load average {os.getloadavg()[0]:.1f}")
    print("| segments | run | " + " | ".join(phases)
          + " | total µs/seg | faults/kseg | steady |")
    print("|---:|---:|" + "---:|" * (len(phases) + 3))
    best: dict[int, float] = {}
    for depth in depths:
        if route != "dict":
            _write(depth, config, route)
        for i in range(repeat):
            p = subprocess.run([sys.executable, __file__, "--child", str(depth), config, route],
                               capture_output=True, text=True, check=True)
            r = json.loads(p.stdout.strip().splitlines()[-1])
            n = r["segments"]
            best[n] = min(best.get(n, math.inf), r["total"])
            cells = [f"{1e6 * (r[k][0] + r[k][1]) / n:.2f} ({1e6 * r[k][1] / n:.2f})"
                     for k in phases]
            faults = sum(r[k][2] for k in phases)
            print(f"| {n} | {i + 1} | " + " | ".join(cells)
                  + f" | {1e6 * r['total'] / n:.2f} | {1e3 * faults / n:.0f} | "
                  f"{1e6 * (r['steady'][0] + r['steady'][1]) / n:.2f} |")
    if len(best) > 1:
        x = [math.log(n) for n in best]
        y = [math.log(t) for t in best.values()]
        mx, my = sum(x) / len(x), sum(y) / len(y)
        slope = (sum((a - mx) * (b - my) for a, b in zip(x, y))
                 / sum((a - mx) ** 2 for a in x))
        print(f"# load slope (log-log, best of {repeat} per size, {min(best)}-{max(best)} "
              f"segments): {slope:.3f}; load average {os.getloadavg()[0]:.1f}")

if __name__ == "__main__":
    main()
