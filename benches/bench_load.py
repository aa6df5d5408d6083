"""Load time: ``load_model`` + core build per segment of the whole-tree family of
``bench_scale.py`` (with oxygen by default), and the structured-tree model ``adan56-st``
loaded by the previous route (trees calibrated and grown in Python, handed over as vessel
dicts) and by the current one (the core calibrates and grows them) in the same process.

CPU seconds (``time.process_time``), best of ``--repeat`` loads; the core part of a tree load
(``oxyline.model._network``: hand-over, parse, assembly, transport plan) is timed again on its
own after each load.

    python benches/bench_load.py --depths 12 15 18 --repeat 3
    python benches/bench_load.py --depths --st-repeat 2      # adan56-st only
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
    best["python"] = best["load"] - best["core"]
    best["segments"] = segments
    return best


# ---------------------------------------------------------------- the previous route
# The structured-tree code as it was before the core grew the trees (python/oxyline, kept here
# verbatim as the baseline of the comparison only): calibration per radius class and growth
# into native vessel dicts in Python, then a load of the expanded plain model.

OLUFSEN = {"k1": 2.0e6, "k2": -2253.0, "k3": 8.65e4}


def _previous_dc_resistance(r0: float, a: float, b: float, lrr: float, rmin: float, mu: float,
                            r_leaf: float) -> float:
    memo: dict[tuple[int, int], float] = {}

    def below(i: int, j: int) -> float:
        if (i, j) not in memo:
            g = 0.0
            for di, dj in ((1, 0), (0, 1)):
                r = a ** (i + di) * b ** (j + dj) * r0
                if r >= rmin:
                    g += 1.0 / (8.0 * mu * lrr / (math.pi * r**3) + below(i + di, j + dj))
            memo[(i, j)] = r_leaf if g == 0.0 else 1.0 / g
        return memo[(i, j)]

    return below(0, 0)


def _previous_condition(r0: float, total: float, mu: float) -> tuple[float, float]:
    a, lrr = 0.9, 50.0
    rmin = min(1e-4, a * r0)
    while _previous_dc_resistance(r0, a, 0.6, lrr, rmin, mu, 0.0) > 0.9 * total:
        rmin *= 1.05
    lo, hi = 0.0, total * 2.0 ** 20
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _previous_dc_resistance(r0, a, 0.6, lrr, rmin, mu, mid) < total:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-15 * hi:
            break
    return rmin, 0.5 * (lo + hi)


def _previous_grow(node: str, r0: float, rmin: float, dx: float | None) -> list[dict[str, Any]]:
    a, b, lrr = 0.9, 0.6, 50.0
    prefix = f"{node}/st/"
    out: list[dict[str, Any]] = []
    stack = [("b", b * r0), ("a", a * r0)]
    while stack:
        path, r = stack.pop()
        if r < rmin:
            continue
        length = lrr * r
        ehr = OLUFSEN["k1"] * math.exp(OLUFSEN["k2"] * r) + OLUFSEN["k3"]
        v: dict[str, Any] = {"name": prefix + path,
                             "from": node if len(path) == 1 else prefix + path[:-1],
                             "to": prefix + path, "length": length, "radius": r,
                             "wall_thickness": 0.1 * r, "youngs_modulus": ehr / 0.1}
        if dx is not None:
            v["segments"] = max(1, math.ceil(length / dx - 1e-9))
        out.append(v)
        stack.append((path + "b", b * r))
        stack.append((path + "a", a * r))
    return out


def previous_route(base: dict[str, Any]) -> tuple[Any, dict[str, float]]:
    """adan56-st by the previous route: (model, terminal resistance per outlet)."""
    import oxyline

    mu = float((base.get("blood") or {}).get("viscosity", 3.5e-3))
    ends = {v["to"]: v for v in base["vessels"]}
    vessels, bcs, leaf_r = list(base["vessels"]), {}, {}
    for node, bc in base["boundary_conditions"].items():
        if bc.get("type") != "rcr":
            bcs[node] = bc
            continue
        v = ends[node]
        r0 = float(v.get("radius_out", v.get("radius")))
        rmin, leaf = _previous_condition(r0, bc["proximal_resistance"] + bc["distal_resistance"],
                                         mu)
        leaf_r[node] = leaf
        grown = _previous_grow(node, r0, rmin, None)
        sources = {g["from"] for g in grown}
        for g in grown:
            if g["to"] not in sources:
                bcs[g["to"]] = {"type": "resistance", "resistance": leaf,
                                "pressure": bc.get("pressure", 0.0)}
        vessels.extend(grown)
    data = {**base, "vessels": vessels, "boundary_conditions": bcs}
    return oxyline.load_model(data), leaf_r


def current_route(base: dict[str, Any]) -> tuple[Any, dict[str, float]]:
    import oxyline
    from oxyline.structured_tree import replace_windkessels

    data = replace_windkessels(base)
    leaf_r = {n: bc["terminal"]["resistance"] for n, bc in data["boundary_conditions"].items()
              if bc.get("type") == "structured-tree"}
    return oxyline.load_model(data), leaf_r


def adan56_st(repeat: int) -> None:
    import copy

    import oxyline

    base = oxyline.models.load_dict("adan56")
    best: dict[str, float] = {}
    results = {}
    for _ in range(repeat):
        for name, route in (("previous", previous_route), ("current", current_route)):
            data = copy.deepcopy(base)
            gc.collect()
            t0 = time.process_time()
            m, leaf = route(data)
            best[name] = min(best.get(name, math.inf), time.process_time() - t0)
            results[name] = (m.network.summary()["segments"], m.vessel_names, leaf)
            del m
    (s0, n0, l0), (s1, n1, l1) = results["previous"], results["current"]
    # the same tree: vessel names and order, segments; the terminal resistances by the same
    # bisection on sums in another order (rounding)
    assert n0 == n1 and s0 == s1, (len(n0), len(n1), s0, s1)
    worst = max(abs(l1[k] / l0[k] - 1.0) for k in l0)
    assert worst < 1e-12, worst
    print(f"\nadan56-st: {len(n1)} vessels, {s1} segments; terminal resistances agree to "
          f"{worst:.1e}")
    print("| route | load s (CPU) | µs/segment |")
    print("|---|---:|---:|")
    for name in ("previous", "current"):
        print(f"| {name} | {best[name]:.2f} | {best[name] * 1e6 / s1:.2f} |")
    print(f"| speed-up | {best['previous'] / best['current']:.1f}x | |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depths", type=int, nargs="*", default=[12, 15, 18])
    ap.add_argument("--config", default="o2-k")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--st-repeat", type=int, default=2, help="adan56-st loads per route (0: none)")
    a = ap.parse_args()
    if a.depths:
        print(f"tree family ({a.config})")
        print("| segments | load_model s | µs/seg | core µs/seg (hand-over, build) | "
              "rest µs/seg |")
        print("|---:|---:|---:|---:|---:|")
    for d in a.depths:
        r = measure(d, a.config, 1 if d >= 18 else a.repeat)
        us = 1e6 / r["segments"]
        print(f"| {r['segments']} | {r['load']:.3f} | {r['load'] * us:.2f} | {r['core'] * us:.2f} "
              f"| {r['python'] * us:.2f} |", flush=True)
    if a.st_repeat:
        adan56_st(a.st_repeat)


if __name__ == "__main__":
    main()
