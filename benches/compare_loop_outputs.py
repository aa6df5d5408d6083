"""Before/after check of a change of the solves of networks with loops: every output array
of the built-in models with loops, flow and oxygen (where the model allows it), within a
relative tolerance.

A network with loops has its pendant trees eliminated around its loop-carrying core (the flow
solve and the oxygen step, docs/solvers.md): the same linear systems as the general sparse LU
and the flow-order sweep over the whole network, solved in another order, so the outputs move
at rounding only. ``save`` runs one cycle of each case at a fixed step and stores every
output array (``compare_load_outputs.arrays``) in a local ``.npz``; ``check`` runs them on
the installed package and reports, per array, max|new − old| / max|old| (0 where the array is
all zero), failing above ``--rtol`` (default 1e-10: a solve's rounding, ~1e-16 relative,
carried over a cycle's 1000 steps through well-damped systems stays many decades below it,
while any change of the discretisation or a lost term moves results by 1e-6 or more).

    python benches/compare_loop_outputs.py save /tmp/loops-before.npz     # old build
    python benches/compare_loop_outputs.py check /tmp/loops-before.npz    # new build
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np
from bench_scale import WALLS
from compare_load_outputs import arrays

OPTIONS = {"cycles": 1, "dt": 1e-3, "output_every": 1e-2, "until_periodic": None}


def with_oxygen(name: str) -> dict[str, Any]:
    """The built-in model ``name`` (native dict) with the bench's constant-k oxygen wall."""
    import oxyline

    m: dict[str, Any] = oxyline.catalogue.load_dict(name)
    wall, hb = WALLS["o2-k"]
    m["oxygen"] = {
        "inlet": {"po2": 95.0},
        "wall": wall,
        "hemoglobin": hb,
        "reference_pressure": 85.0,
    }
    return m


#: (model, with oxygen): whole-body-140's lumped aortic root has no lumen volume for transport
CASES = [
    ("circle-of-willis", False),
    ("circle-of-willis", True),
    ("whole-body-140", False),
    ("whole-body-140-st", False),
    ("whole-body-140-st", True),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["save", "check"])
    ap.add_argument("path")
    ap.add_argument("--rtol", type=float, default=1e-10)
    a = ap.parse_args()
    got: dict[str, np.ndarray] = {}
    for name, o2 in CASES:
        source = with_oxygen(name) if o2 else name
        got.update(arrays(f"{name}{'-o2' if o2 else ''}", source, OPTIONS))
        print(f"{name}{' + O2' if o2 else ''}: done", flush=True)
    if a.mode == "save":
        np.savez(a.path, **got)
        print(f"{len(got)} arrays saved to {a.path}")
        return
    ref = np.load(a.path)
    worst, bad = 0.0, []
    for k in ref.files:
        old, new = ref[k], got.get(k)
        if new is None or old.shape != new.shape:
            bad.append(f"{k}: missing or reshaped")
            continue
        if old.dtype.kind not in "fc":
            if old.tobytes() != new.tobytes():
                bad.append(f"{k}: differs")
            continue
        scale = np.nanmax(np.abs(old)) if old.size else 0.0
        diff = np.nanmax(np.abs(new - old)) if old.size else 0.0
        rel = diff / scale if scale > 0 else diff
        same_nan = np.array_equal(np.isnan(old), np.isnan(new))
        worst = max(worst, rel)
        if rel > a.rtol or not same_nan:
            bad.append(f"{k}: {rel:.2e}")
    print(
        f"{len(ref.files)} arrays compared: worst relative difference {worst:.2e}, "
        f"{len(bad)} beyond {a.rtol:g}"
    )
    for b in bad:
        print("  ", b)
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
