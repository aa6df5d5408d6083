"""Byte-for-byte check that a change of the load path leaves every output unchanged.

``save`` runs a short simulation of each case and stores every output array (time, the data
block, segment positions, species arrays, chamber volumes, valve states, the network's summary
and segment table) in a local ``.npz``; ``check`` runs the same cases on the installed package
and compares every array bit for bit (``np.array_equal`` on the raw bytes: the load path's
arithmetic is the same, so nothing may move, not even by one ulp). The ``.npz`` is a local
before/after record, never committed as a test truth.

    python benches/compare_load_outputs.py save /tmp/before.npz      # on the old build
    python benches/compare_load_outputs.py check /tmp/before.npz     # on the new build
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np
from bench_scale import tree

#: (case, model source, simulate options): short runs, the arithmetic of a whole one
CASES: list[tuple[str, Any, dict[str, Any]]] = [
    ("adan56", "adan56", {"cycles": 1, "dt": 1e-3, "output_every": 1e-2}),
    ("adan56-st", "adan56-st", {"cycles": 1, "dt": 2e-2, "output_every": 4e-2}),
    ("whole-body-140-st", "whole-body-140-st",
     {"cycles": 1, "dt": 1e-2, "output_every": 2e-2}),
    ("tree10-o2", None, {"cycles": 1, "dt": 1e-3, "output_every": 1e-2}),
]


def arrays(name: str, source: Any, options: dict[str, Any]) -> dict[str, np.ndarray]:
    """Every output array of one case, keyed ``case/what``."""
    import oxyline

    model = oxyline.load_model(tree(10, 4, "o2-k") if source is None else source)
    net = model.network
    out: dict[str, np.ndarray] = {}
    summary = net.summary()
    out["summary"] = np.array([float(summary[k] or 0.0) for k in sorted(summary)])
    table = net.segment_table() if hasattr(net, "segment_table") else {}
    for k, v in dict(table).items():
        out[f"table/{k}"] = np.asarray(v)
    res = oxyline.simulate(model, method="generalized-alpha", **options)
    out["time"], out["data"] = res.time, res.data
    out["segment_position"] = np.asarray(res.segment_position)
    out["segment_count"] = np.asarray(res.segment_count)
    out["vessels"] = np.asarray(res.vessels)
    for sp_name, sp in res.species.items():
        for k, v in vars(sp).items():
            if isinstance(v, np.ndarray):
                out[f"species/{sp_name}/{k}"] = v
    for group in ("chamber_volume", "valve_status"):
        for k, v in getattr(res, group).items():
            out[f"{group}/{k}"] = np.asarray(v)
    return {f"{name}/{k}": v for k, v in out.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["save", "check"])
    ap.add_argument("path")
    ap.add_argument("--cases", nargs="*", default=[c[0] for c in CASES])
    a = ap.parse_args()
    got: dict[str, np.ndarray] = {}
    for name, source, options in CASES:
        if name in a.cases:
            got.update(arrays(name, source, options))
            print(f"{name}: done", flush=True)
    if a.mode == "save":
        np.savez(a.path, **got)
        print(f"{len(got)} arrays saved to {a.path}")
        return
    ref = np.load(a.path)
    bad = [k for k in ref.files if k.split("/")[0] in a.cases
           and (k not in got or ref[k].shape != got[k].shape
                or ref[k].dtype != got[k].dtype or ref[k].tobytes() != got[k].tobytes())]
    extra = [k for k in got if k not in ref.files]
    print(f"{len(got)} arrays compared: {len(bad)} differ, {len(extra)} new")
    for k in bad + extra:
        print("  differs" if k in bad else "  new", k)
    sys.exit(1 if bad or extra else 0)


if __name__ == "__main__":
    main()
