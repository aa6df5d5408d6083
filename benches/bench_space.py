"""`segments: auto` against fixed segmentations (docs/solvers.md, "Space"): per model, the
segments chosen, the cost (segments, circuit unknowns, assembly and one cycle of
generalized-alpha at dt = 1 ms) and the achieved error of the inlet impedance at the forcing's
significant harmonics (rtol 1e-3) against a refined reference: every geometric vessel a pi
ladder (the same transmission line in the limit), `auto` at rtol 1e-4, then every count doubled
(adan56-st: rtol 1e-3, doubled).

Rows: every geometric vessel (tree vessels included) at 1 segment (what a model that states
no segmentation got before `auto` was the default) and 8, the model's own segmentation, the
model with every segmentation key and its model-wide arrangement removed (`segments`,
`max_length`, a tree's `segments`/`max_length`, `arrangement`: the default, `auto` at rtol 1e-3
in pi sections), the same keeping the arrangement it states (the built-ins state inverted-L, or
L: `auto` at rtol 1e-3 in those first-order sections), `auto` at
rtol 1e-2 and 1e-3 in the model's own arrangements, and with every geometric vessel a pi ladder
(the arrangement `auto` is cheap in).

Run: python benches/bench_space.py [--run-big] [model ...]  (default: adan56 whole-body-140
pwdb-116 adan56-st; adan56-st loads 262,512 vessels per row: minutes, a few GB; its cycle is
run only with --run-big, and only for the 1-per-vessel, own and default rows).
"""

from __future__ import annotations

import copy
import os
import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

import oxyline
from oxyline import plot
from oxyline.convergence import refined

HEART_KEYS = ("valve", "chamber", "through_rc", "chamber_sphere", "heart_pulmonary",
              "coronary_bed", "lumped")


def geometric(v: Mapping[str, Any]) -> bool:
    return not any(k in v for k in HEART_KEYS)


def variant(data: dict[str, Any], segments: Any, rtol: float | None = None,
            arrangement: str | None = None) -> dict[str, Any]:
    """``data`` with every geometric vessel and structured tree cut into ``segments`` (an
    integer, or "auto" at ``rtol``), in ``arrangement`` (None: their own)."""
    out = copy.deepcopy(data)
    for v in out["vessels"]:
        if geometric(v):
            v["segments"] = segments
            if arrangement is not None:
                v["arrangement"] = arrangement
    trees = [bc for bc in (out.get("boundary_conditions") or {}).values()
             if isinstance(bc, dict) and bc.get("type") == "structured-tree"]
    for bc in trees:
        bc.pop("max_length", None)
        bc["segments"] = segments
    if trees and arrangement is not None:  # tree vessels take the model's arrangement
        out["arrangement"] = arrangement
    seg = dict(out.get("segmentation") or {})
    seg.pop("max_length", None)
    if rtol is not None:
        seg["rtol"] = rtol
    out["segmentation"] = seg
    return out


def without_segmentation(data: dict[str, Any], arrangement: bool = False) -> dict[str, Any]:
    """``data`` with every segmentation key removed: what the default (`auto`) cuts; with
    ``arrangement``, the model-wide arrangement too (a model written without either: its
    `auto` vessels are cut in pi sections; vessels that state their own keep it)."""
    out = copy.deepcopy(data)
    out.pop("segmentation", None)
    if arrangement:
        out.pop("arrangement", None)
    for v in out["vessels"]:
        if geometric(v):
            v.pop("segments", None)
    for bc in (out.get("boundary_conditions") or {}).values():
        if isinstance(bc, dict) and bc.get("type") == "structured-tree":
            bc.pop("segments", None)
            bc.pop("max_length", None)
    return out


def one_cycle_cpu(m: oxyline.Model) -> float:
    t0 = time.process_time()
    oxyline.simulate(m, cycles=1, dt=1e-3, method="generalized-alpha", output_every=1e-2,
                     until_periodic=None, segments=False, vessels="none")
    return time.process_time() - t0


def row(label: str, data: dict[str, Any], inlet: str, f: np.ndarray, z_ref: np.ndarray | None,
        run: bool) -> tuple[str, np.ndarray]:
    t0 = time.process_time()
    m = oxyline.load_model(data)
    s = m.network.summary()
    t_load = time.process_time() - t0
    z = oxyline.impedance(m, inlet, f)
    err = "" if z_ref is None else f"{np.max(np.abs(z / z_ref - 1.0)):10.2e}"
    cpu = f"{one_cycle_cpu(m):9.2f}" if run else f"{'-':>9}"
    table = m.network.segment_table()
    counts = np.bincount(np.asarray(table["vessel"], dtype=np.int64))
    counts = counts[counts > 0]
    spread = f"{counts.min()}/{int(np.median(counts))}/{counts.max()}"
    line = (f"{label:<18}{s['segments']:>10}{spread:>14}{s['unknowns']:>10}{t_load:>9.2f}"
            f"{cpu}{err:>11}")
    return line, z


def bench(name: str, run_big: bool = False) -> None:
    base = oxyline.catalogue.load(name)
    data = base.to_dict()
    inlet = next(iter(plot.inlets(base)))
    big = name.endswith("-st")
    f = oxyline.forcing_harmonics(base, 1e-3)
    f2 = oxyline.forcing_harmonics(base, 1e-2)
    print(f"\n{name}: inlet {inlet!r}, significant harmonics {len(f2)} (rtol 1e-2) / {len(f)} "
          f"(rtol 1e-3) of {1 / f[0]:g} s; load average {os.getloadavg()[0]:.1f}")
    t0 = time.process_time()
    # the reference: the geometric vessels as pi ladders (the same line in the limit), auto
    # at rtol 1e-4 and every count doubled (adan56-st: auto 1e-3, doubled)
    ref_rtol = 1e-3 if big else 1e-4
    ref = refined(oxyline.load_model(variant(data, "auto", ref_rtol, "pi")), 2)
    z_ref = oxyline.impedance(ref, inlet, f)
    print(f"reference: pi, auto {ref_rtol:g}, x 2: {ref.network.summary()['segments']} segments "
          f"({time.process_time() - t0:.1f} s CPU)")
    print(f"{'segmentation':<18}{'segments':>10}{'min/med/max':>14}{'unknowns':>10}"
          f"{'load s':>9}{'cycle s':>9}{'|dZ|/|Z|':>11}")
    rows = [("1 per vessel", variant(data, 1)), ("8 per vessel", variant(data, 8)),
            ("model's own", data), ("no keys: default", without_segmentation(data, True)),
            ("no seg. keys, own", without_segmentation(data)),
            ("auto 1e-2", variant(data, "auto", 1e-2)),
            ("pi, auto 1e-2", variant(data, "auto", 1e-2, "pi")),
            ("pi, auto 1e-3", variant(data, "auto", 1e-3, "pi"))]
    if big:  # 8 per tree vessel is 2.1 million segments, and the stated first-order
        # arrangement without segmentation keys 6-8 million: left out (memory of the machine)
        rows.pop(4)
        rows.pop(1)
    else:
        rows.insert(5, ("auto 1e-3", variant(data, "auto", 1e-3)))
    for label, d in rows:
        run = not big or (run_big and label in ("1 per vessel", "model's own",
                                                "no keys: default"))
        try:
            line, _ = row(label, d, inlet, f, z_ref, run=run)
        except oxyline.ResourceError as e:  # the memory limit refuses it before allocating
            line = f"{label:<18}refused: {e}"
        print(line, flush=True)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--run-big"]
    for model in args or ["adan56", "whole-body-140", "pwdb-116", "adan56-st"]:
        bench(model, run_big="--run-big" in sys.argv[1:])
