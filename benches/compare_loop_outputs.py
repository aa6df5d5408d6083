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
while any change of the discretisation or a lost term moves results by 1e-6 or more). The
species' per-segment transmission-line resistance and inductance (``tl_*``, which grow without
bound where a segment's flow crosses zero: scales of 1e10) amplify the flows' rounding near
those crossings, so they are held to ``--rtol-tl`` (default 1e-8) instead; measured 4.7e-9
on circle-of-willis with O2, with its flows within 3e-15.

    python benches/compare_loop_outputs.py save /tmp/loops-before.npz     # old build
    python benches/compare_loop_outputs.py check /tmp/loops-before.npz    # new build
    python benches/compare_loop_outputs.py save /tmp/b.npz --cases whole-body-140-st+o2
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


def compare(old: np.ndarray, new: np.ndarray) -> float:
    """max|new - old| / max|old| (the difference itself where ``old`` is all zero)."""
    if not old.size:
        return 0.0
    scale = np.nanmax(np.abs(old))
    diff = np.nanmax(np.abs(new - old))
    return float(diff / scale if scale > 0 else diff)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["save", "check"])
    ap.add_argument("path")
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--rtol-tl", type=float, default=1e-8)
    ap.add_argument(
        "--cases",
        nargs="+",
        metavar="CASE",
        help="only these cases (a model's name, '+o2' for its oxygen run: "
        "e.g. whole-body-140-st+o2)",
    )
    a = ap.parse_args()
    got: dict[str, np.ndarray] = {}
    for name, o2 in CASES:
        if a.cases and f"{name}{'+o2' if o2 else ''}" not in a.cases:
            continue
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
        if k.endswith("/segment_data") and new is not None and old.shape == new.shape:
            # the last axis: concentration, flux, wall flux, then the two tl_* columns
            tl = compare(old[..., 3:], new[..., 3:])
            if tl > a.rtol_tl:
                bad.append(f"{k} tl_*: {tl:.2e}")
            old, new = old[..., :3], new[..., :3]
        if new is None or old.shape != new.shape:
            bad.append(f"{k}: missing or reshaped")
            continue
        if old.dtype.kind not in "fc":
            if old.tobytes() != new.tobytes():
                bad.append(f"{k}: differs")
            continue
        rel = compare(old, new)
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
