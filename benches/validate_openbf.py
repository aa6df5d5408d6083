"""Validate oxyline against openBF's 1-D results (``tests/data/openbf``).

For each openBF model with a converted reference (``test_reference_csv/``), import the openBF
file with :func:`oxyline.io.openbf.read_openbf` in openBF-compatible mode, run oxyline
(inverted-L segments <= 1 cm) to periodicity, sample its pressures and flows at the reference
points (x = 0, 0.25, 0.5, 0.75, 1 of every vessel) and times, and compare mean pressure,
systolic, diastolic and pulse pressure, and mean flow.

Run ``python benches/validate_openbf.py`` to rewrite the tables in ``docs/validation.md`` and
the figure ``docs/figures/adan56_pressure.png``; ``--friction`` rewrites the Poiseuille vs
Womersley tables (ADAN56 and the circle of Willis, per vessel).
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
OPENBF = REPO / "tests" / "data" / "openbf"  # openBF models + reference CSVs (Apache-2.0)
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

    path = root / "test_reference_csv" / f"ref_{model}_{field}.csv"
    if not path.exists():  # tests/data stores them gzipped
        path = path.with_name(path.name + ".gz")
    df = pd.read_csv(path, comment="#")
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
    if cycles is None:  # the periodic start (exact for a linear circuit) then >= 3 cycles
        res = oxyline.simulate(m, until_periodic=1e-6, cycles=3, max_cycles=200,
                               start="periodic")
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


def drift(model: str, root: Path = OPENBF) -> float:
    """Median (P(end) - P(start)) / mean P over the reference cycle: 0 for a periodic cycle."""
    _, P = reference(model, "P", root)
    return float(np.median(np.concatenate([(p[-1] - p[0]) / p.mean(axis=0) for p in P.values()])))


QUANTITIES = (("mean_p", "mean P"), ("sys", "systolic"), ("dia", "diastolic"),
              ("pp", "pulse P"), ("mean_q", "mean Q"))


def table(results: dict[str, list[dict[str, Any]]]) -> str:
    """Markdown table: max / median |relative error| per quantity (percent)."""
    head = "| model | points | " + " | ".join(f"{q} max / median" for _, q in QUANTITIES) + " |"
    lines = [head, "|---|---:|" + "---:|" * len(QUANTITIES)]
    for name, rows in results.items():
        s = summary(rows)
        cells = " | ".join(f"{100 * s[k][0]:.2f} / {100 * s[k][1]:.2f}" for k, _ in QUANTITIES)
        lines.append(f"| {name} | {len(rows)} | {cells} |")
    return "\n".join(lines)


FIGURE_SITES = (("aortic_arch_I", 0.0, "ascending aorta (aortic arch I, x = 0)"),
                ("thoracic_aorta_III", 0.5, "thoracic aorta III (x = 0.5)"),
                ("common_carotid_L", 1.0, "left common carotid (x = 1)"),
                ("abdominal_aorta_V", 1.0, "abdominal aorta V (x = 1)"),
                ("radial_R", 1.0, "right radial (x = 1)"),
                ("anterior_tibial_R", 1.0, "right anterior tibial (x = 1)"))


def figure(c: dict[str, Any], out: Path) -> None:
    """Pressure waveforms at six ADAN56 sites, oxyline vs openBF."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, P, res, m = c["t"], c["P"], c["res"], c["model"]
    phase = t - t[0]
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), sharex=True, constrained_layout=True)
    for ax, (lab, x, title) in zip(axes.ravel(), FIGURE_SITES):
        j = POSITIONS.index(x)
        ox = sample(res, lab, "P", t, m.period)[:, j]
        ax.plot(phase, P[lab][:, j] / MMHG, "k--", lw=1.6, label="openBF (1-D, nonlinear)")
        ax.plot(phase, ox / MMHG, "C0", lw=1.6, label="oxyline (0-D, inverted-L, ≤ 1 cm)")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("pressure [mmHg]")
    for ax in axes[-1]:
        ax.set_xlabel("time in cycle [s]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9)
    fig.suptitle("ADAN56: pressure, oxyline vs openBF (last cycle)", fontsize=11)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def waveform_error(rows: list[dict[str, Any]], c: dict[str, Any]) -> None:
    """Add to each row ``wave_err``: the RMS difference of the pressure waveforms over the
    cycle, relative to openBF's pulse pressure at that point."""
    t, P, res, m = c["t"], c["P"], c["res"], c["model"]
    cache: dict[str, np.ndarray] = {}
    for r in rows:
        lab, j = r["vessel"], POSITIONS.index(r["x"])
        if lab not in cache:
            cache[lab] = sample(res, lab, "P", t, m.period)
        d = cache[lab][:, j] - P[lab][:, j]
        r["wave_err"] = float(np.sqrt(np.mean(d**2)) / r["pp_ref"])


def per_vessel(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per vessel, the signed error of largest magnitude over its five points: mean and pulse
    pressure, and the largest waveform error (``wave_err``)."""
    out: dict[str, dict[str, float]] = {}
    for r in rows:
        v = out.setdefault(r["vessel"], {"mean_p": 0.0, "pp": 0.0, "wave": 0.0})
        for key in ("mean_p", "pp"):
            if abs(r[f"{key}_err"]) > abs(v[key]):
                v[key] = r[f"{key}_err"]
        v["wave"] = max(v["wave"], r.get("wave_err", float("nan")))
    return out


FRICTIONS = {"Poiseuille": {}, "Womersley": {"wall_friction": "womersley"},
             # openBF's own viscoelastic wall law on every vessel (its stored results are elastic)
             "Womersley + viscoelastic": {"wall_friction": "womersley", "viscoelastic": True}}


def friction_comparison(models: tuple[str, ...] = ("adan56", "circle_of_willis")) -> str:
    """Poiseuille, Womersley and Womersley + viscoelastic segments against openBF, per model;
    Poiseuille vs Womersley per vessel (markdown)."""
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for name in models:
        runs[name] = {}
        for label, opts in FRICTIONS.items():
            c = compare(name, **opts)
            waveform_error(c["rows"], c)
            runs[name][label] = c["rows"]
            print(f"{name} {label}: {summary(c['rows'])}", flush=True)
    head = ("| model | friction | mean P max / median | pulse P max / median | "
            "waveform RMS / pulse P max / median |")
    out = [head, "|---|---|---:|---:|---:|"]
    for name, by in runs.items():
        for label, rows in by.items():
            s = summary(rows)
            w = np.array([r["wave_err"] for r in rows])
            out.append(f"| {name} | {label} | {100 * s['mean_p'][0]:.2f} / "
                       f"{100 * s['mean_p'][1]:.2f} | {100 * s['pp'][0]:.2f} / "
                       f"{100 * s['pp'][1]:.2f} | {100 * w.max():.2f} / "
                       f"{100 * np.median(w):.2f} |")
    for name, by in runs.items():
        pv = {label: per_vessel(rows) for label, rows in by.items()}
        out += ["", f"#### {name}, per vessel (worst of x = 0, 0.25, 0.5, 0.75, 1; %)", "",
                ("| vessel | mean P Pois. | mean P Wom. | pulse P Pois. | pulse P Wom. | "
                 "waveform Pois. | waveform Wom. |"), "|---|---:|---:|---:|---:|---:|---:|"]
        a, b = pv["Poiseuille"], pv["Womersley"]
        for lab in a:
            out.append(f"| {lab} | {100 * a[lab]['mean_p']:+.2f} | {100 * b[lab]['mean_p']:+.2f} "
                       f"| {100 * a[lab]['pp']:+.2f} | {100 * b[lab]['pp']:+.2f} | "
                       f"{100 * a[lab]['wave']:.2f} | {100 * b[lab]['wave']:.2f} |")
    return "\n".join(out)


def _replace_block(marker: str, gen: str) -> None:
    doc = REPO / "docs" / "validation.md"
    text = doc.read_text()
    a, b = f"<!-- GENERATED: {marker} -->", "<!-- END GENERATED -->"
    if a in text:
        end = text.index(b, text.index(a))
        text = text[: text.index(a) + len(a)] + "\n" + gen + "\n" + text[end:]
        doc.write_text(text)


def main() -> None:
    """Recompute everything in docs/validation.md (between the GENERATED markers) and the
    figure."""
    periodic = {name: compare(name) for name in MODELS}
    out = ["### Run to periodicity (openBF-compatible import)", "",
           table({k: v["rows"] for k, v in periodic.items()}), ""]
    same = {name: compare(name, same_cycle=True)["rows"]
            for name in ("cca", "ibif", "circle_of_willis")}
    out += [("### Same transient as openBF (from rest, same number of cycles; models with "
            "Pext = 0)"), "", table(same), ""]
    out += ["### Reference cycle drift (median (P_end - P_start)/mean P of openBF's cycle)", "",
            "| model | openBF cycles | drift |", "|---|---:|---:|"]
    out += [f"| {n} | {reference_cycles(n)} | {100 * drift(n):.2f} % |" for n in MODELS]
    sens = {
        "adan56, openBF-compatible (reference setup)": periodic["adan56"]["rows"],
        "adan56, linearize='pext' (radii at A0)": compare("adan56", linearize="pext")["rows"],
        "adan56, default import (file's taper, repaired inflow)": compare(
            "adan56", openbf_compat=False, repair_inlet=True)["rows"],
        "circle_of_willis, wk2='parallel'": compare(
            "circle_of_willis", wk2="parallel", openbf_compat=False, taper="openbf")["rows"],
    }
    out += ["", "### Sensitivity to the mapping (run to periodicity)", "", table(sens), ""]
    gen = "\n".join(out)
    print(gen)
    figure(periodic["adan56"], REPO / "docs" / "figures" / "adan56_pressure.png")
    _replace_block("benches/validate_openbf.py", gen)


if __name__ == "__main__":
    if sys.argv[1:] == ["--friction"]:
        gen = friction_comparison()
        print(gen)
        _replace_block("benches/validate_openbf.py --friction", gen)
    elif sys.argv[1:]:
        for name in sys.argv[1:]:
            print(name, summary(compare(name)["rows"]))
    else:
        main()
