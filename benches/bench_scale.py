"""Whole-tree scaling of flow and oxygen transport (issue 9, items 3, 4, 6, 7).

The tree family: a symmetric binary tree of ``2^depth - 1`` geometric vessels, Murray radii
r_child = r_parent 2^(-1/3) from a 1 cm root, lengths l = 10 r, Olufsen's wall law
Eh/r = k1 exp(k2 r) + k3 (k1 = 2e6 Pa, k2 = -2253 1/m, k3 = 8.65e4 Pa; Olufsen et al. 2000,
the CGS constants of ``benches/networks.py`` in SI), ``--per-vessel`` segments per vessel,
a half-sine systolic inflow of mean 90 mL/s and one RCR per leaf (parallel totals
R = 1.33e8 Pa s/m^3, 10 % proximal, C = 1e-8 m^3/Pa). Models are native dicts loaded through
the public API (``oxyline.load_model``), run with ``oxyline.simulate``.

Runs: one cycle, generalized-alpha dt = 1 ms (RK4: automatic dt, smaller trees only),
vessel-level output every 10 ms (``segments=False``: no per-segment flow columns).
Configurations: flow only; + O2 with a constant-k wall; + O2 with the default Lévêque closure
(cycle-mean shear: needs the cycle-mean |Q| of a flow-only pass); + O2 with Hill haemoglobin
(constant k).

Every configuration runs in a fresh subprocess, so that its peak RSS (``ru_maxrss``) is its
own. Times are CPU times of that process (user + system; robust on a shared machine) —
``load`` = ``load_model`` (validation, assembly, transport plan), ``run`` = ``simulate``.

    python benches/bench_scale.py                       # depths 8, 10, 12, 14, 16
    python benches/bench_scale.py --depths 8 10 12 14 16 18 --rk4-max-depth 12
    python benches/bench_scale.py --depths 18 --configs flow o2-k     # the 1e6-segment run
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from typing import Any

K1, K2, K3 = 2.0e6, -2253.0, 8.65e4  # Olufsen 2000, Eh/r in Pa with r in m
R_ROOT = 0.01  # m
LENGTH_PER_RADIUS = 10.0
MEAN_FLOW = 9.0e-5  # m^3/s
PERIOD = 1.0
T_SYSTOLE = 0.3
R_TOTAL = 1.33e8  # Pa s/m^3, parallel total of the outlets
C_TOTAL = 1.0e-8  # m^3/Pa
WALLS = {
    "o2-k": ({"model": "mass-transfer", "k": 1.0e-5, "po2": 60.0}, "none"),
    "o2-leveque": ({"model": "leveque", "po2": 60.0}, "none"),
    "o2-hill-k": ({"model": "mass-transfer", "k": 1.0e-5, "po2": 60.0}, "hill"),
}
CONFIGS = ["flow", *WALLS]


def inflow() -> dict[str, Any]:
    """Half-sine systole, zero diastole, time mean exactly MEAN_FLOW (as a 201-point table)."""
    n = 201
    t = [PERIOD * i / (n - 1) for i in range(n)]
    shape = [math.sin(math.pi * ti / T_SYSTOLE) if ti < T_SYSTOLE else 0.0 for ti in t]
    shape = [max(s, 0.0) for s in shape]
    mean = sum((shape[i] + shape[i + 1]) / 2.0 for i in range(n - 1)) / (n - 1)
    return {"type": "flow", "time": t, "flow": [MEAN_FLOW * s / mean for s in shape]}


def tree(depth: int, per_vessel: int, config: str) -> dict[str, Any]:
    """The tree of ``2^depth - 1`` vessels as a native model dict (SI)."""
    vessels: list[dict[str, Any]] = []
    n_leaves = 2 ** (depth - 1)
    bcs: dict[str, Any] = {"in": inflow()}
    rcr = {"type": "rcr", "proximal_resistance": 0.1 * R_TOTAL * n_leaves,
           "capacitance": C_TOTAL / n_leaves, "distal_resistance": 0.9 * R_TOTAL * n_leaves}
    # heap order: vessel i has children 2i+1, 2i+2; its end node is "n{i}"
    for i in range(2 ** depth - 1):
        level = int(math.log2(i + 1))
        r = R_ROOT * 2.0 ** (-level / 3.0)
        h = 0.1 * r
        eh_r = K1 * math.exp(K2 * r) + K3
        start = "in" if i == 0 else f"n{(i - 1) // 2}"
        vessels.append({"name": f"v{i}", "from": start, "to": f"n{i}",
                        "length": LENGTH_PER_RADIUS * r, "radius": r, "wall_thickness": h,
                        "youngs_modulus": eh_r * r / h, "segments": per_vessel})
        if level == depth - 1:
            bcs[f"n{i}"] = rcr
    m: dict[str, Any] = {"name": f"tree{depth}", "period": PERIOD, "vessels": vessels,
                         "boundary_conditions": bcs}
    if config in WALLS:
        wall, hb = WALLS[config]
        m["oxygen"] = {"inlet": {"po2": 95.0}, "wall": wall, "hemoglobin": hb,
                       "reference_pressure": 85.0}
    return m


def child(spec: dict[str, Any]) -> dict[str, Any]:
    """One configuration, measured in this (fresh) process."""
    import oxyline

    model = tree(spec["depth"], spec["per_vessel"], spec["config"])
    kw: dict[str, Any] = {"cycles": 1, "output_every": 0.01, "segments": False,
                          "method": spec["method"]}
    if spec["method"] == "generalized-alpha":
        kw["dt"] = 1e-3
    c0, w0 = time.process_time(), time.perf_counter()
    m = oxyline.load_model(model)
    c1, w1 = time.process_time(), time.perf_counter()
    res = oxyline.simulate(m, **kw)
    c2, w2 = time.process_time(), time.perf_counter()
    out = {"load_cpu": c1 - c0, "load_wall": w1 - w0, "run_cpu": c2 - c1, "run_wall": w2 - w1,
           "segments": int(m.network.summary()["segments"]),
           "dt": float(res.settings["dt"]),
           "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
    if res.species:
        mb = res.o2_mass_balance
        out["residual"] = float(mb["residual"][-1] / mb["inflow"][-1])
    return out


def measure(spec: dict[str, Any]) -> dict[str, Any]:
    """Run ``spec`` in a fresh interpreter; best (smallest CPU) of ``repeat`` runs."""
    best: dict[str, Any] | None = None
    for _ in range(spec["repeat"]):
        p = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)],
                           capture_output=True, text=True, check=False)
        if p.returncode != 0:
            return {"error": (p.stderr.strip().splitlines() or ["?"])[-1]}
        r = json.loads(p.stdout.strip().splitlines()[-1])
        if best is None or r["run_cpu"] + r["load_cpu"] < best["run_cpu"] + best["load_cpu"]:
            best = r
    assert best is not None
    return best


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of log y against log x."""
    lx = [math.log(x) for x in xs]
    ly = [math.log(max(y, 1e-9)) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    den = sum((a - mx) ** 2 for a in lx)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / den if den > 0 else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--depths", type=int, nargs="+", default=[8, 10, 12, 14, 16])
    ap.add_argument("--per-vessel", type=int, default=4)
    ap.add_argument("--configs", nargs="+", default=CONFIGS, choices=CONFIGS)
    ap.add_argument("--methods", nargs="+", default=["generalized-alpha", "rk4"],
                    choices=["generalized-alpha", "rk4"])
    ap.add_argument("--rk4-max-depth", type=int, default=12,
                    help="largest tree run with RK4 (its stable dt shrinks with the vessels)")
    ap.add_argument("--fit-min-segments", type=float, default=1e4,
                    help="smallest tree included in the log-log fits")
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(json.loads(a.child))))
        return
    print(f"# binary trees, {a.per_vessel} segments per vessel, one cycle, vessel output every "
          f"10 ms; CPU s (best of {a.repeat}), peak RSS of a fresh process; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    print("| method | config | segments | load s | run s | ns/seg-step | peak MB | O2/flow "
          "| load µs/seg | mass residual |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for method in a.methods:
        for depth in a.depths:
            if method == "rk4" and depth > a.rk4_max_depth:
                continue
            flow_run = None
            for config in a.configs:
                r = measure({"depth": depth, "per_vessel": a.per_vessel, "config": config,
                             "method": method, "repeat": a.repeat})
                if "error" in r:
                    print(f"| {method} | {config} | depth {depth} | failed: {r['error']} |")
                    continue
                steps = round(PERIOD / r["dt"])
                ns = 1e9 * r["run_cpu"] / (r["segments"] * steps)
                if config == "flow":
                    flow_run = r["run_cpu"]
                ratio = f"{r['run_cpu'] / flow_run:.2f}" if flow_run and config != "flow" else "–"
                res = f"{r['residual']:.1e}" if "residual" in r else "–"
                print(f"| {method} | {config} | {r['segments']} | {r['load_cpu']:.3f} | "
                      f"{r['run_cpu']:.3f} | {ns:.1f} | {r['peak_mb']:.0f} | {ratio} | "
                      f"{1e6 * r['load_cpu'] / r['segments']:.2f} | {res} |", flush=True)
                rows.setdefault((method, config), []).append(r)
    print("\nlog-log slopes against segments (trees of >= "
          f"{a.fit_min_segments:.0e} segments; target <= 1.1):")
    for (method, config), rs in rows.items():
        rs = [r for r in rs if r["segments"] >= a.fit_min_segments]
        if len(rs) < 2:
            continue
        n = [r["segments"] for r in rs]
        print(f"  {method:<18} {config:<11} load {slope(n, [r['load_cpu'] for r in rs]):.2f}"
              f"  run {slope(n, [r['run_cpu'] / (PERIOD / r['dt']) for r in rs]):.2f}"
              " (per step)")


if __name__ == "__main__":
    main()
