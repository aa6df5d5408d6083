"""Byte-for-byte check that every run path's heart outputs are unchanged: each chamber's
volume and each valve's status (``Result.chamber_volume``, ``Result.valve_status``) with the
rows they came with, in memory, streamed to Zarr (97-row chunks: borders inside every valve
state) and per ensemble variant (``"full"`` and the ``"summary"`` statistics), for the
minimal native closed loop (tanh valves) and svZeroDSolver's closed-loop heart block (on/off
valves), both with generalized-α and RK4, the decomposed closed-loop heart (four chambers) and
the piecewise chamber-and-valve case (generalized-α). The ``.npz`` is a local before/after record, never a test
truth.

    python benches/compare_heart_outputs.py save /tmp/heart-before.npz      # old build
    python benches/compare_heart_outputs.py check /tmp/heart-before.npz     # new build
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASES_DIR = ROOT / "tests" / "data" / "svzerod" / "cases"
#: the cases also run with RK4
RK4 = ("minimal-loop", "closedLoopHeart_singleVessel")


def models() -> dict[str, Any]:
    """The cases' loaded models, by name."""
    import oxyline
    from oxyline import svzerod as svz

    sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # (the tests import their conftest)
    from tests.test_svzerod_chambers import CLOSED_LOOP

    out = {"minimal-loop": oxyline.load_model(copy.deepcopy(CLOSED_LOOP))}
    for case in ("closedLoopHeart_singleVessel", "closedLoopHeart_singleVessel_decomposed",
                 "piecewise_Chamber_and_Valve"):
        with open(CASES_DIR / f"{case}.json") as f:
            out[case] = svz.to_model(json.load(f))
    return out


def heart(prefix: str, res: Any) -> dict[str, np.ndarray]:
    """A result's rows, chamber volumes and valve statuses, keyed ``prefix/what``."""
    out = {f"{prefix}/time": np.asarray(res.time), f"{prefix}/data": np.asarray(res.data)}
    for group in ("chamber_volume", "valve_status"):
        for k, v in getattr(res, group).items():
            out[f"{prefix}/{group}/{k}"] = np.asarray(v)
    return out


def arrays() -> dict[str, np.ndarray]:
    """Every heart output of every case and path."""
    import oxyline

    got: dict[str, np.ndarray] = {}
    run = {"cycles": 3, "output_cycles": "all", "output_every": 1e-3}
    for name, model in models().items():
        # (RK4 where the default step is stable for it)
        for method in ("generalized-alpha", "rk4")[: 2 if name in RK4 else 1]:
            res = oxyline.simulate(model, method=method, **run)
            got.update(heart(f"{name}/{method}/memory", res))
        with tempfile.TemporaryDirectory() as tmp:
            oxyline.simulate_to_zarr(model, Path(tmp) / "h.zarr", time_chunk=97,
                                     method="generalized-alpha", **run)
            got.update(heart(f"{name}/zarr", oxyline.open_result(Path(tmp) / "h.zarr")))
        print(f"{name}: done", flush=True)
    base = models()["minimal-loop"]
    patches = [{}, {"vessels": {"systemic": {"lumped": {"resistance": 1.0e8}}}}]
    opts = {"method": "generalized-alpha", "progress": False, **run}
    for output in ("full", "summary"):
        ds = oxyline.simulate_ensemble(base, patches, output=output, **opts)
        for var in ds.data_vars:
            if var.startswith(("chamber_volume", "valve_status")) or var == "flow_in":
                got[f"ensemble/{output}/{var}"] = np.asarray(ds[var].values)
    print("ensemble: done", flush=True)
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["save", "check"])
    ap.add_argument("path")
    a = ap.parse_args()
    got = arrays()
    if a.mode == "save":
        np.savez(a.path, **got)
        print(f"{len(got)} arrays saved to {a.path}")
        return
    ref = np.load(a.path)
    bad = [k for k in ref.files
           if k not in got or ref[k].shape != got[k].shape or ref[k].dtype != got[k].dtype
           or ref[k].tobytes() != got[k].tobytes()]
    extra = [k for k in got if k not in ref.files]
    print(f"{len(got)} arrays compared: {len(bad)} differ, {len(extra)} new")
    for k in bad + extra:
        print("  differs" if k in bad else "  new", k)
    sys.exit(1 if bad or extra else 0)


if __name__ == "__main__":
    main()
