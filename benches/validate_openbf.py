"""Validate oxyline against openBF's 1-D results (``../shared/networks/openbf``).

For each openBF model with a converted reference (``test_reference_csv/``), import the openBF
file with :func:`oxyline.io.openbf.read_openbf` in openBF-compatible mode, run oxyline
(inverted-L segments <= 1 cm) to periodicity, sample its pressures and flows at the reference
points (x = 0, 0.25, 0.5, 0.75, 1 of every vessel) and times, and compare mean pressure,
systolic, diastolic and pulse pressure, and mean flow.

Run ``python benches/validate_openbf.py`` to rewrite the table in ``docs/validation.md``'s data
file (``docs/validation_table.md``) and the figure ``docs/figures/adan56_pressure.png``.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import oxyline
from oxyline.io.openbf import read_openbf

REPO = Path(__file__).resolve().parents[1]
OPENBF = REPO.parent / "shared" / "networks" / "openbf"
MODELS = {
    "cca": "models/boileau2015/cca/cca.yaml",
    "ibif": "models/boileau2015/ibif/ibif.yaml",
    "adan56": "models/boileau2015/adan56/adan56.yaml",
    "circle_of_willis": "models/alastruey2007/circle_of_willis.yaml",
}
POSITIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
MMHG = 133.322368
# what openBF actually ran (see docs/validation.md): its own taper and WK2 conventions, the
# inlet file as shipped (the ADAN56 reference was computed with the corrupted exponents)
COMPAT = {"openbf_compat": True, "repair_inlet": False, "linearize": "mean"}


def reference(model: str, field: str, root: Path = OPENBF) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """openBF reference: times [s] and, per vessel label, a (time, 5) array at ``POSITIONS``."""
    import pandas as pd

    df = pd.read_csv(root / "test_reference_csv" / f"ref_{model}_{field}.csv", comment="#")
    t = df["t_s"].to_numpy()
    labels = list(dict.fromkeys(c.split("@")[0] for c in df.columns[1:]))
    out = {lab: np.column_stack([df[f"{lab}@x={x:g}"].to_numpy() for x in POSITIONS])
           for lab in labels}
    return t, out


def simulate(model: str, root: Path = OPENBF, cycles: int | None = None,
             **options: Any) -> tuple[oxyline.Model, oxyline.Result]:
    """Import ``model`` (openBF-compatible unless overridden) and run it to periodicity, or,
    with ``cycles``, from rest (P = 0, Q = 0, as openBF starts) for that many cycles."""
    opts = {**COMPAT, **options}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = read_openbf(root / MODELS[model], **opts)
    if cycles is None:
        res = oxyline.simulate(m, until_periodic=1e-6, cycles=5, max_cycles=200)
    else:
        res = oxyline.simulate(m, start="zero", cycles=cycles, until_periodic=None)
    return m, res


def sample(res: oxyline.Result, label: str, field: str, t_ref: np.ndarray,
           period: float) -> np.ndarray:
    """oxyline ``field`` ("P" or "Q") of vessel ``label`` at the reference times (periodic) and
    positions: a (time, 5) array."""
    v = res.vessel(label)
    n = v.segment_flow.shape[1]
    if field == "P":  # pressures at the segment nodes x = k dx, k = 0..n
        values = np.column_stack([v.segment_pressure_in, v.segment_pressure_out[:, -1]])
        xs = np.linspace(0.0, 1.0, n + 1)
    else:  # branch flows, at the segment midpoints
        values = v.segment_flow
        xs = (np.arange(n) + 0.5) / n
    space = np.column_stack([
        np.array([np.interp(x, xs, row) for row in values]) for x in POSITIONS])
    tt = np.asarray(res.time)
    phase = np.mod(t_ref, period)
    return np.column_stack([np.interp(phase, tt[:-1], space[:-1, j], period=period)
                            for j in range(space.shape[1])])


def _mean(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.trapezoid(y, t, axis=0) / (t[-1] - t[0])


def reference_cycles(model: str, root: Path = OPENBF) -> int:
    """Number of cycles openBF had run at the end of its reference cycle."""
    import yaml

    t, _ = reference(model, "P", root)
    path = root / MODELS[model]
    cfg = yaml.safe_load(path.read_text())
    inlet = path.with_name(cfg.get("inlet_file", f"{cfg['project_name']}_inlet.dat"))
    return round(t[-1] / float(np.loadtxt(inlet)[-1, 0]))


def compare(model: str, root: Path = OPENBF, same_cycle: bool = False,
            **options: Any) -> dict[str, Any]:
    """Per-point comparison. Returns a dict with ``rows`` (one per vessel and position: the
    reference and oxyline values and relative errors) and ``res``/``model``/``ref``.

    ``same_cycle``: run oxyline from rest for as many cycles as openBF had run (its reference
    cycle is not yet periodic), instead of to periodicity."""
    cycles = reference_cycles(model, root) if same_cycle else None
    m, res = simulate(model, root, cycles=cycles, **options)
    t, P = reference(model, "P", root)
    _, Q = reference(model, "Q", root)
    q_in = None
    rows = []
    for lab in P:
        p_ox = sample(res, lab, "P", t, m.period)
        q_ox = sample(res, lab, "Q", t, m.period)
        pr, qr = P[lab], Q[lab]
        if q_in is None or lab == m.vessel_names[0]:
            q_in = abs(float(np.mean(_mean(Q[m.vessel_names[0]], t))))
        for j, x in enumerate(POSITIONS):
            r = {"vessel": lab, "x": x}
            for key, f in (("mean_p", lambda y: _mean(y, t)), ("sys", np.max), ("dia", np.min),
                           ("pp", lambda y: np.max(y) - np.min(y)), ("mean_q", lambda y: _mean(y, t))):
                src_r, src_o = (qr, q_ox) if key == "mean_q" else (pr, p_ox)
                r[f"{key}_ref"] = float(f(src_r[:, j]))
                r[f"{key}_ox"] = float(f(src_o[:, j]))
            for key in ("mean_p", "sys", "dia", "pp"):
                r[f"{key}_err"] = (r[f"{key}_ox"] - r[f"{key}_ref"]) / abs(r[f"{key}_ref"])
            r["mean_q_err"] = (r["mean_q_ox"] - r["mean_q_ref"]) / abs(r["mean_q_ref"])
            r["mean_q_share"] = abs(r["mean_q_ref"]) / q_in
            rows.append(r)
    return {"rows": rows, "res": res, "model": m, "t": t, "P": P, "Q": Q}


def summary(rows: list[dict[str, Any]], min_share: float = 0.0) -> dict[str, tuple[float, float]]:
    """(max, median) of |relative error| per quantity; flows of vessels carrying less than
    ``min_share`` of the inflow are left out of the mean-flow statistics."""
    out = {}
    for key in ("mean_p", "sys", "dia", "pp", "mean_q"):
        e = np.array([abs(r[f"{key}_err"]) for r in rows
                      if key != "mean_q" or r["mean_q_share"] >= min_share])
        out[key] = (float(np.max(e)), float(np.median(e)))
    return out


if __name__ == "__main__":
    for name in (sys.argv[1:] or MODELS):
        c = compare(name)
        s = summary(c["rows"])
        print(name, c["res"].settings["method"], c["res"].settings["cycles_run"],
              {k: (f"{a * 100:.2f}%", f"{b * 100:.2f}%") for k, (a, b) in s.items()})
