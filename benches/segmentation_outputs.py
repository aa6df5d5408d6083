"""Every built-in's segmentation and outputs, saved by one build and compared by another: the
check that a change of the default segmentation leaves the built-ins that state their own
segmentation (`segments`, `max_length`, a tree's `segments`/`max_length`) byte-identical.

    python benches/segmentation_outputs.py save DIR      # with the build before the change
    python benches/segmentation_outputs.py compare DIR   # with the build after it

Per built-in: its segment count and segment table (R, L, C, lengths), and every output array
of a short run (the model's own run settings, two cycles without the periodicity test, so that
whole trees stay within minutes). `compare` prints, per built-in, the segments before/after,
how many were chosen by the `auto` rule, and whether every array is byte-equal (else the
largest relative difference and the arrays that differ).

Options: `--models a,b` (default: every built-in), `--no-run` (tables only).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import oxyline

TABLE_KEYS = ("vessel", "resistance", "inductance", "compliance", "length")


def arrays(name: str, run: bool) -> dict[str, np.ndarray]:
    """The built-in's segment table and (``run``) every output array of a short run."""
    m = oxyline.catalogue.load(name)
    s = m.summary()
    out = {"segments": np.array([s["segments"]]),
           "auto_segments": np.array([s.get("auto_segments", 0)])}
    table = m.network.segment_table()
    out.update({f"table/{k}": np.asarray(table[k]) for k in TABLE_KEYS})
    if run:
        res = oxyline.simulate(m, cycles=2, until_periodic=None, progress=False)
        ds = res.to_xarray()
        out.update({f"out/{k}": np.asarray(v.values) for k, v in ds.data_vars.items()})
        out["out/time"] = np.asarray(ds["time"].values)
    return out


def save(directory: Path, names: list[str], run: bool) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    for name in names:
        t0 = time.process_time()
        data = arrays(name, run)
        np.savez(directory / f"{name}.npz", **{k.replace("/", "__"): v for k, v in data.items()})
        print(f"{name:<28}{int(data['segments'][0]):>10} segments "
              f"({time.process_time() - t0:.1f} s CPU)", flush=True)


def differs(a: np.ndarray, b: np.ndarray) -> float | None:
    """None when byte-equal, else the largest relative difference (inf: shapes differ)."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return float("inf")
    if a.tobytes() == b.tobytes():
        return None
    if not np.issubdtype(a.dtype, np.number):
        return float("inf")
    scale = max(float(np.nanmax(np.abs(a))), 1e-300)
    return float(np.nanmax(np.abs(a.astype(float) - b.astype(float)))) / scale


def compare(directory: Path, names: list[str], run: bool) -> int:
    print(f"{'built-in':<28}{'before':>10}{'after':>10}{'auto':>10}  outputs")
    changed = 0
    for name in names:
        path = directory / f"{name}.npz"
        if not path.exists():
            print(f"{name:<28}  (not saved)")
            continue
        old = {k.replace("__", "/"): v for k, v in np.load(path).items()}
        new = arrays(name, run)
        bad = {k: differs(old[k], new[k]) for k in old if k in new and k != "auto_segments"}
        bad = {k: d for k, d in bad.items() if d is not None}
        what = "byte-identical" if not bad else (
            f"{len(bad)} arrays differ (max rel {max(bad.values()):.1e}): "
            + ", ".join(sorted(bad)[:6]))
        changed += bool(bad)
        print(f"{name:<28}{int(old['segments'][0]):>10}{int(new['segments'][0]):>10}"
              f"{int(new['auto_segments'][0]):>10}  {what}", flush=True)
    return changed


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mode", choices=("save", "compare"))
    p.add_argument("directory", type=Path)
    p.add_argument("--models", default="")
    p.add_argument("--no-run", action="store_true")
    a = p.parse_args(argv)
    names = a.models.split(",") if a.models else oxyline.catalogue.list()
    if a.mode == "save":
        save(a.directory, names, not a.no_run)
        return 0
    return 1 if compare(a.directory, names, not a.no_run) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
