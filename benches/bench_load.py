"""Load time: ``load_model`` + core build per segment of the whole-tree family of
``bench_scale.py`` (with oxygen by default), and the structured-tree model ``adan56-st``
loaded by the previous route (trees calibrated and grown in Python, handed over as vessel
dicts) and by the current one (the core calibrates and grows them) in the same process, with
the current route's stages (growth, hand-over, core build) timed apart.

CPU seconds (``time.process_time``), best of ``--repeat`` loads. ``load_model`` builds the
core network (hand-over of the native dicts, parse, assembly, transport plan); the core build
from the canonical dicts (``oxyline.model._network``, the route of a model rebuilt from its
canonical description) is timed on its own after each load.

    python benches/bench_load.py --depths 12 15 18 --repeat 3
    python benches/bench_load.py --depths --st-repeat 2      # adan56-st only
    python benches/bench_load.py --depths 18 --st-repeat 3 --rounds 3 --baseline /path/to/old

``--baseline DIR``: another build of the package (a copy of ``python/oxyline`` with its compiled
core) measured in turn with this one, each round in fresh processes, best of all rounds; the
peak RSS column is each build's process after one ``adan56-st`` load (run first).
"""

from __future__ import annotations

import argparse
import gc
import math
import time
from typing import Any

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
    best["segments"] = segments
    return best


# ---------------------------------------------------------------- the previous route
#: the revision whose python/oxyline/structured_tree.py is the previous route: trees calibrated
#: and grown in Python, handed to the core as vessel dicts
BEFORE = "5179ade"


def previous_module(rev: str) -> Any:
    """``oxyline.structured_tree`` as it was at ``rev`` (read with git), run against the
    installed package."""
    import importlib.util
    import pathlib
    import subprocess
    import tempfile

    repo = pathlib.Path(__file__).resolve().parent.parent
    text = subprocess.run(["git", "show", f"{rev}:python/oxyline/structured_tree.py"],
                          cwd=repo, capture_output=True, text=True, check=True).stdout
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "structured_tree_before.py"
        path.write_text(text)
        spec = importlib.util.spec_from_file_location("structured_tree_before", path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    return mod


def previous_route(base: dict[str, Any], old: Any) -> tuple[Any, dict[str, float]]:
    """adan56-st by the previous route: (model, terminal resistance per outlet)."""
    from oxyline import model as M
    from oxyline.description import copy_description

    data = old.replace_windkessels(base)
    leaf_r = {n: bc["terminal"]["resistance"] for n, bc in data["boundary_conditions"].items()
              if bc.get("type") == "structured-tree"}
    return old.build_with_trees(copy_description(dict(data)), M._build_native), leaf_r


def current_route(base: dict[str, Any], old: Any) -> tuple[Any, dict[str, float]]:
    from oxyline import model as M
    from oxyline.structured_tree import replace_windkessels

    data = replace_windkessels(base)
    leaf_r = {n: bc["terminal"]["resistance"] for n, bc in data["boundary_conditions"].items()
              if bc.get("type") == "structured-tree"}
    return M.build_model(data), leaf_r


def current_stages(base: dict[str, Any]) -> dict[str, float]:
    """CPU seconds of the current route's stages: the trees checked and grown by the core
    (``StructuredTrees``), the rest of the model read and the trees moved into its parts
    (``read_model``, ``move_into``), and the core build (``Network.from_parts``: graph,
    segments, circuit, DAE; its spec dropped)."""
    import importlib
    import json

    from oxyline import _core
    from oxyline.description import copy_description

    st = importlib.import_module("oxyline.structured_tree")
    data = copy_description(dict(st.replace_windkessels(base)))
    rest, trees = st._split(data)
    terminals = [json.dumps(_core.read_conditions({n: st._terminal(n, bc)}, "SI")[0][n])
                 for n, bc, _ in trees]
    gc.collect()
    t0 = time.process_time()
    grown = _core.StructuredTrees(trees, 1.0, 1.0, None, len(data["vessels"]))
    t1 = time.process_time()
    parts = _core.read_model({**data, "boundary_conditions": rest})[0]
    grown.move_into(parts, terminals)
    t2 = time.process_time()
    net = _core.Network.from_parts(parts, None)
    t3 = time.process_time()
    del net
    return {"trees grown": t1 - t0, "read + moved in": t2 - t1, "core build": t3 - t2}


def adan56_st(repeat: int, before: str) -> dict[str, Any]:
    """Both routes of adan56-st, best of ``repeat`` each, and the current route's stages."""
    import copy

    import oxyline

    base = oxyline.catalogue.load_dict("adan56")
    old = previous_module(before)
    best: dict[str, float] = {}
    results = {}
    for _ in range(repeat):
        for name, route in (("previous", previous_route), ("current", current_route)):
            data = copy.deepcopy(base)
            gc.collect()
            t0 = time.process_time()
            m, leaf = route(data, old)
            best[name] = min(best.get(name, math.inf), time.process_time() - t0)
            results[name] = (m.network.summary()["segments"], m.vessel_names, leaf)
            del m
    (s0, n0, l0), (s1, n1, l1) = results["previous"], results["current"]
    # the same tree: vessel names and order, segments; the terminal resistances by the same
    # bisection on sums in another order (rounding)
    assert n0 == n1 and s0 == s1, (len(n0), len(n1), s0, s1)
    worst = max(abs(l1[k] / l0[k] - 1.0) for k in l0)
    assert worst < 1e-12, worst
    stages: dict[str, float] = {}
    for _ in range(repeat):
        for k, v in current_stages(copy.deepcopy(base)).items():
            stages[k] = min(stages.get(k, math.inf), v)
    return {"vessels": len(n1), "segments": s1, "worst": worst, "routes": best,
            "stages": stages}


def peak_after_load() -> float:
    """Peak RSS (MiB) of this process after one load of adan56-st by the current route (run
    first in a fresh process, so that the peak is the load's own plus the interpreter's)."""
    import resource

    import oxyline

    m = oxyline.load_model("adan56-st")
    del m
    gc.collect()
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(a: argparse.Namespace) -> dict[str, Any]:
    """Every measurement of one build, in this process."""
    out: dict[str, Any] = {"peak MiB": peak_after_load() if a.st_repeat else None}
    out["trees"] = [measure(d, a.config, 1 if d >= 18 else a.repeat) for d in a.depths]
    out["st"] = adan56_st(a.st_repeat, a.before) if a.st_repeat else None
    return out


def run_child(argv: list[str], baseline: str | None) -> dict[str, Any]:
    """``child`` in a fresh process; ``baseline``: a directory holding another build of the
    ``oxyline`` package, put first on its path."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ)
    if baseline:
        env["PYTHONPATH"] = os.pathsep.join([baseline, *filter(None, [env.get("PYTHONPATH")])])
    r = subprocess.run([sys.executable, __file__, *argv, "--child"], env=env,
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def best_of(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The smallest time of every figure over the rounds (peak RSS: its smallest too)."""
    b = runs[0]
    for r in runs[1:]:
        if b["peak MiB"] is not None:
            b["peak MiB"] = min(b["peak MiB"], r["peak MiB"])
        for t0, t1 in zip(b["trees"], r["trees"], strict=True):
            for k in ("load", "core"):
                t0[k] = min(t0[k], t1[k])
        if b["st"]:
            for part in ("routes", "stages"):
                for k, v in r["st"][part].items():
                    b["st"][part][k] = min(b["st"][part][k], v)
    return b


def report(builds: dict[str, dict[str, Any]], config: str, before: str) -> None:
    """The tables: one column per build (``this``, and ``baseline`` when given)."""
    names = list(builds)
    tag = (lambda n: "" if len(names) == 1 else f" ({n})")
    first = builds[names[0]]
    if first["trees"]:
        print(f"tree family ({config})")
        print("| segments | build | load_model + core build s | µs/seg | core build from "
              "canonical dicts µs/seg |\n|---:|---|---:|---:|---:|")
        for i, row in enumerate(first["trees"]):
            for n in names:
                r = builds[n]["trees"][i]
                us = 1e6 / r["segments"]
                print(f"| {r['segments']} | {n} | {r['load']:.3f} | {r['load'] * us:.2f} | "
                      f"{r['core'] * us:.2f} |", flush=True)
    if not first["st"]:
        return
    st = first["st"]
    print(f"\nadan56-st: {st['vessels']} vessels, {st['segments']} segments; terminal "
          f"resistances agree to {st['worst']:.1e}; previous route: structured_tree.py at "
          f"{before}")
    print("| route | load s (CPU) | µs/segment |\n|---|---:|---:|")
    for n in names:
        r = builds[n]["st"]["routes"]
        for route in ("previous", "current"):
            print(f"| {route}{tag(n)} | {r[route]:.2f} | {r[route] * 1e6 / st['segments']:.2f} |")
        print(f"| speed-up{tag(n)} | {r['previous'] / r['current']:.1f}x | |")
    print("\n| current route stage | " + " | ".join(f"CPU s{tag(n)}" for n in names)
          + " |\n|---|" + "---:|" * len(names))
    for k in st["stages"]:
        print(f"| {k} | " + " | ".join(f"{builds[n]['st']['stages'][k]:.3f}" for n in names)
              + " |")
    print("\n| peak RSS after one adan56-st load, MiB | "
          + " | ".join(f"{builds[n]['peak MiB']:.0f}{tag(n)}" for n in names) + " |")


def main() -> None:
    import json
    import sys

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depths", type=int, nargs="*", default=[12, 15, 18])
    ap.add_argument("--config", default="o2-k")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--st-repeat", type=int, default=2, help="adan56-st loads per route (0: none)")
    ap.add_argument("--before", default=BEFORE, help="revision of the previous route")
    ap.add_argument("--baseline", metavar="DIR",
                    help="a directory holding another build of the oxyline package: measured "
                         "in turn with this one, in fresh processes")
    ap.add_argument("--rounds", type=int, default=1,
                    help="fresh processes per build (best of all rounds)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a)))
        return
    argv = [a for a in sys.argv[1:] if a not in ("--child",)]
    argv = strip_option(strip_option(argv, "--baseline"), "--rounds")
    builds: dict[str, list[dict[str, Any]]] = {}
    for _ in range(a.rounds):
        for name, path in [("this", None), *([("baseline", a.baseline)] if a.baseline else [])]:
            builds.setdefault(name, []).append(run_child(argv, path))
    report({n: best_of(runs) for n, runs in builds.items()}, a.config, a.before)


def strip_option(argv: list[str], option: str) -> list[str]:
    """``argv`` without ``option`` and its value."""
    out, skip = [], False
    for x in argv:
        if skip:
            skip = False
        elif x == option:
            skip = True
        elif not x.startswith(option + "="):
            out.append(x)
    return out


if __name__ == "__main__":
    main()
