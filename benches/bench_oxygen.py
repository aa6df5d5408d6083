"""Cost of oxygen transport relative to flow only (target <= 1.6x).

A binary tree of 2^depth - 1 compliant vessels (3 segments each), pulsatile inflow, RCR
outlets; the same run with and without the `oxygen` section. Closures: constant k (single
pass) and Lévêque with cycle-mean shear (two passes: a flow-only pass for the mean |Q|).

    python benches/bench_oxygen.py [--depth 10] [--cycles 2] [--method rk4]
"""

from __future__ import annotations

import argparse
import time

import oxyline


def tree(depth: int, wall: dict | None, hemoglobin: str = "none") -> dict:
    vessels = []
    bcs: dict = {"in": {"type": "flow", "fourier": {"period": 1.0, "mean": 2e-5,
                                                    "sin": [2e-5], "cos": [5e-6]}}}
    r0 = 8e-3

    def add(name: str, start: str, level: int) -> None:
        end = f"{name}_end"
        r = r0 * 0.79 ** level
        vessels.append({"name": name, "from": start, "to": end, "length": 0.04 * 0.9 ** level,
                        "radius": r, "wall_thickness": 0.2 * r, "youngs_modulus": 1e6,
                        "segments": 3})
        if level + 1 < depth:
            add(name + "a", end, level + 1)
            add(name + "b", end, level + 1)
        else:
            n_out = 2 ** (depth - 1)
            bcs[end] = {"type": "rcr", "proximal_resistance": 1e8 * n_out / 16,
                        "capacitance": 1e-10 * 16 / n_out, "distal_resistance": 1e9 * n_out / 16}

    add("v", "in", 0)
    m = {"name": f"tree{depth}", "period": 1.0, "vessels": vessels, "boundary_conditions": bcs}
    if wall is not None:
        m["oxygen"] = {"inlet": {"po2": 95.0}, "wall": wall, "hemoglobin": hemoglobin,
                       "reference_pressure": 80.0}
    return m


def timed(model: dict, **kw: object) -> tuple[float, oxyline.Result]:
    """CPU time of the run (user + system of this process): robust on a shared machine, where
    wall time depends on the other jobs."""
    m = oxyline.load_model(model)
    t = time.process_time()
    res = oxyline.simulate(m, **kw)
    return time.process_time() - t, res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--depth", type=int, default=10)
    ap.add_argument("--cycles", type=int, default=2)
    ap.add_argument("--method", default="rk4")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    kw = {"cycles": a.cycles, "method": a.method, "output_every": 1e-2, "segments": False}
    if a.method != "rk4":
        kw["dt"] = 1e-3
    cases = {
        "flow only": (None, "none"),
        "+ O2, constant k": ({"model": "mass-transfer", "k": 1e-5, "po2": 60.0}, "none"),
        "+ O2, Hill, constant k": ({"model": "mass-transfer", "k": 1e-5, "po2": 60.0}, "hill"),
        "+ O2, Leveque cycle-mean (2 passes)": ({"model": "leveque", "po2": 60.0}, "none"),
    }
    base = None
    n_vessels = 2 ** a.depth - 1
    print(f"binary tree, {n_vessels} vessels x 3 segments, {a.cycles} cycles, method {a.method}"
          " (best CPU time of the repeats, runs interleaved)")
    best: dict[str, float] = {k: float("inf") for k in cases}
    results: dict[str, oxyline.Result] = {}
    for _ in range(a.repeat):
        for label, (wall, hb) in cases.items():
            t, results[label] = timed(tree(a.depth, wall, hb), **kw)
            best[label] = min(best[label], t)
    for label in cases:
        res = results[label]
        base = base or best[label]
        extra = ""
        if res.species:
            mb = res.o2_mass_balance
            extra = f"  mass residual/inflow {mb['residual'][-1] / mb['inflow'][-1]:.1e}"
        print(f"{label:<38} {best[label]:8.3f} s  x{best[label] / base:5.2f}  "
              f"dt {res.settings['dt']:.2e}{extra}")


if __name__ == "__main__":
    main()
