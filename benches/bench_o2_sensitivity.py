"""Cost of exact oxygen sensitivities relative to the run they differentiate.

A binary tree of 2^depth - 1 compliant vessels (`bench_oxygen.tree`: 3 segments each,
pulsatile inflow, RCR outlets) with Hill's law and a mass-transfer wall. The same call of
`oxyline.sensitivities` with no parameter (the primal alone: the flow to its periodic state,
then the oxygen field over that cycle to its own) and with the tangents of 1 and 3 oxygen
parameters (wall k, wall PO2, P50), best of `--repeat` in one process (CPU time: the
machine is shared); and `oxyline.simulate` of the same model (flow and oxygen together) for
as many cycles as the oxygen field needs to be periodic.

`--adjoint`: the adjoint (`mode="adjoint"`: one backward sweep per output) against the
forward tangents for 1 and 10 oxygen parameters (the section's wall k, P50 and the own
walls' k of vessels given one), and for 10 flow and oxygen parameters (the wall k, P50, the
inflow, resistance and compliance scales, radii, lengths and a stiffness: the flow's
tangents forward, the species adjoint backward), in the same run, for the same outputs.

`--loops N`: N anastomoses between sibling vessels' far ends one level above the outlets
(a network whose flow graph has loops: the species step takes the flow-order sweep, and
the adjoint transposes that sweep's system).

    python benches/bench_o2_sensitivity.py [--depth 6] [--repeat 3] [--adjoint] [--loops 0]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import oxyline

sys.path.insert(0, str(Path(__file__).parent))
from bench_oxygen import tree

PARAMETERS = ["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50"]
#: flow parameters: through the flow's own tangent, the face flows and transport volumes
FLOW_PARAMETERS = ["scale.resistance", "scale.inflow", "scale.compliance"]


def best(f: object, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.process_time()
        f()  # type: ignore[operator]
        times.append(time.process_time() - t)
    return min(times)


def add_loops(m: dict, n: int, depth: int) -> None:
    """Join the far ends of `n` pairs of sibling vessels one level above the outlets by an
    anastomosis (half their radius, as long as they are)."""
    pairs = [v for v in m["vessels"] if len(v["name"]) == depth - 1 and v["name"][-1] == "a"]
    if n > len(pairs):
        raise SystemExit(f"--loops: at most {len(pairs)} at depth {depth}")
    for v in pairs[:n]:
        sibling = v["name"][:-1] + "b"
        m["vessels"].append({**v, "name": f"{v['name']}_{sibling}", "from": f"{v['name']}_end",
                             "to": f"{sibling}_end", "radius": 0.5 * v["radius"],
                             "wall_thickness": 0.5 * v["wall_thickness"]})


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--depth", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--adjoint", action="store_true")
    ap.add_argument("--loops", type=int, default=0)
    a = ap.parse_args()
    m = tree(a.depth, {"model": "mass-transfer", "k": 1e-4, "po2": 60.0}, "hill")
    add_loops(m, a.loops, a.depth)
    m["oxygen"]["hill"] = {"p50": 26.8}
    if a.adjoint:
        return adjoint(m, a)
    m["simulation"] = {"dt": 1.0 / a.steps, "method": "generalized-alpha"}
    model = oxyline.load_model(m)
    outputs = ["VO2", "VO2.v", "v.wall_uptake.max"]
    run = oxyline.sensitivities(model, [], outputs)
    print(f"tree depth {a.depth}: {len(m['vessels'])} vessels, {a.steps} steps a cycle, "
          f"{run.cycles} flow cycles, {run.tangent_cycles} oxygen cycles to 1e-12")
    base = best(lambda: oxyline.sensitivities(model, [], outputs), a.repeat)
    sim = best(lambda: oxyline.simulate(model, cycles=run.tangent_cycles, progress=False),
               a.repeat)
    print(f"{'call':<34}{'CPU s':>9}{'/ primal':>10}")
    print(f"{f'simulate, {run.tangent_cycles} cycles':<34}{sim:>9.3f}{sim / base:>10.2f}")
    print(f"{'primal (no parameter)':<34}{base:>9.3f}{1.0:>10.2f}")
    for kind, paths in (("oxygen", PARAMETERS), ("flow", FLOW_PARAMETERS)):
        for n in (1, 3):
            t = best(lambda n=n, p=paths: oxyline.sensitivities(model, p[:n], outputs),
                     a.repeat)
            print(f"{f'tangents of {n} {kind} parameter(s)':<34}{t:>9.3f}{t / base:>10.2f}"
                  f"   ({(t - base) / base / n:.2f} primal per parameter)")


def adjoint(m: dict, a: argparse.Namespace) -> None:
    """Forward tangents against the adjoint, 1 and 10 oxygen parameters, one process."""
    own = [v["name"] for v in m["vessels"][1:9]]
    m["oxygen"]["per_vessel"] = {v: {"wall": {"model": "mass-transfer", "k": 1.5e-4,
                                              "po2": 50.0}} for v in own}
    m["simulation"] = {"dt": 1.0 / a.steps, "method": "generalized-alpha"}
    model = oxyline.load_model(m)
    paths = (["oxygen.wall.k", "oxygen.hill.p50"]
             + [f"oxygen.per_vessel.{v}.wall.k" for v in own])
    mixed = ["oxygen.wall.k", "oxygen.hill.p50", *FLOW_PARAMETERS,
             f"vessels.{own[0]}.radius", f"vessels.{own[1]}.radius",
             f"vessels.{own[2]}.length", f"vessels.{own[3]}.length",
             f"vessels.{own[4]}.youngs_modulus"]
    outputs = ["VO2", "VO2.v", "v.wall_uptake.max"]
    base = best(lambda: oxyline.sensitivities(model, [], outputs), a.repeat)
    print(f"tree depth {a.depth}, {a.loops} loops: {len(m['vessels'])} vessels, {a.steps} "
          f"steps a cycle, {len(outputs)} outputs; CPU s, best of {a.repeat}")
    print(f"{'parameters':<16}{'forward':>10}{'adjoint':>10}{'fwd/primal':>12}"
          f"{'adj/primal':>12}{'max |adj-fwd|/scale':>22}")
    for name, p in (("1 oxygen", paths[:1]), ("10 oxygen", paths), ("10 flow+oxygen", mixed)):
        fwd = oxyline.sensitivities(model, p, outputs)
        adj = oxyline.sensitivities(model, p, outputs, mode="adjoint")
        f = fwd.jacobian * fwd.parameter_values
        err = (abs(adj.jacobian * adj.parameter_values - f).max(axis=1)
               / abs(f).max(axis=1)).max()
        tf = best(lambda p=p: oxyline.sensitivities(model, p, outputs), a.repeat)
        ta = best(lambda p=p: oxyline.sensitivities(model, p, outputs, mode="adjoint"),
                  a.repeat)
        print(f"{name:<16}{tf:>10.3f}{ta:>10.3f}{tf / base:>12.2f}{ta / base:>12.2f}"
              f"{err:>22.1e}")
    print(f"primal (no parameter) {base:.3f} s")


if __name__ == "__main__":
    main()
