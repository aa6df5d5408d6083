"""oxyline's svZeroDSolver calibrator drop-in against ``svzerod.calibrate`` (PyPI ``svzerod``)
in the same process (docs/svzerod.md, "Calibrator").

For each stored calibrator input (``steadyFlow_calibration`` and the two VMR
``*_calibrate_from_0d`` cases): the wall time of ``oxyline.svzerod.calibrate(config)`` and of
``svzerod.calibrate(config)`` from the same in-memory dict (best of ``--repeat``; svzerod 3.2
needs ``calibrate`` lists, so both get every value listed, which is the classic selection),
their ratio, and the largest difference of any calibrated value, relative to that value's
scale (its largest magnitude over the model), between the two and against the stored
calibrated model.

    python benches/bench_svzerod_calibrate.py
    python benches/bench_svzerod_calibrate.py --repeat 10
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import gzip
import json
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from oxyline import svzerod as oxy

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "svzerod" / "cases"


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """svzerod prints every iteration on the C++ stdout: send file descriptor 1 away."""
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)


def _cases() -> list[tuple[str, dict[str, Any], dict[str, Any] | None]]:
    steady = json.loads((DATA / "steadyFlow_calibration.json").read_text())
    out: list[tuple[str, dict[str, Any], dict[str, Any] | None]] = [
        ("steadyFlow_calibration", steady, None)]
    for model in ("0104_0001", "0140_2001"):
        with gzip.open(DATA / "vmr" / "input" / f"{model}_calibrate_from_0d.json.gz", "rt") as f:
            cfg = json.load(f)
        ref = json.loads((DATA / "vmr" / "reference" / f"{model}_optimal_from_0d.json")
                         .read_text())
        out.append((model, cfg, ref))
    return out


def _listed(cfg: dict[str, Any]) -> dict[str, Any]:
    cfg = copy.deepcopy(cfg)
    for v in cfg["vessels"]:
        v["calibrate"] = ["R_poiseuille", "C", "L", "stenosis_coefficient"]
    for j in cfg.get("junctions", []):
        if len(j["outlet_vessels"]) > 1:
            j["calibrate"] = ["R_poiseuille", "L", "stenosis_coefficient"]
    return cfg


def _values(cfg: dict[str, Any]) -> dict[tuple[str, str, int], float]:
    out = {}
    for v in cfg["vessels"]:
        for k, x in v["zero_d_element_values"].items():
            out[(v["vessel_name"], k, 0)] = x
    for j in cfg.get("junctions", []):
        for k, xs in j.get("junction_values", {}).items():
            for i, x in enumerate(xs):
                out[(j["junction_name"], k, i)] = x
    return out


def _max_diff(a: dict[str, Any], b: dict[str, Any], cfg: dict[str, Any]) -> float:
    """Largest |a − b| of any value over that value's scale: max |b| of its kind, and for the
    stenosis coefficient at least the one that adds the largest R at the largest observed flow
    (steady data fit S ≈ 0)."""
    va, vb = _values(a), _values(b)
    q = max(abs(x) for k, xs in cfg["y"].items() if k.startswith("flow") for x in xs)
    r = max(abs(x) for (_, k, _), x in vb.items() if k == "R_poiseuille")
    scale: dict[str, float] = {"stenosis_coefficient": r / q}
    for (_, k, _), x in vb.items():
        scale[k] = max(scale.get(k, 1e-300), abs(x))
    return max(abs(va[key] - x) / scale[key[1]] for key, x in vb.items())


def _best(f: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per code (best is kept)")
    args = ap.parse_args()
    try:
        import svzerod
    except ImportError:
        svzerod = None
        print("svzerod is not installed (pip install svzerod): oxyline only")
    print(f"{'case':24s} {'oxyline s':>10s} {'svzerod s':>10s} {'speed-up':>9s} "
          f"{'max diff vs svzerod':>20s} {'max diff vs stored':>19s}")
    for name, cfg, ref in _cases():
        listed = _listed(cfg)
        t_oxy, mine = _best(lambda c=listed: oxy.calibrate(c), args.repeat)
        stored = f"{_max_diff(oxy.calibrate(cfg), ref, cfg):19.1e}" if ref else f"{'-':>19s}"
        if svzerod is None:
            print(f"{name:24s} {t_oxy:10.4f} {'-':>10s} {'-':>9s} {'-':>20s} {stored}")
            continue
        with _quiet():
            t_sv, theirs = _best(lambda c=listed: svzerod.calibrate(c),
                                 args.repeat)
        print(f"{name:24s} {t_oxy:10.4f} {t_sv:10.4f} {t_sv / t_oxy:8.1f}x "
              f"{_max_diff(mine, theirs, cfg):20.1e} {stored}")


if __name__ == "__main__":
    main()
