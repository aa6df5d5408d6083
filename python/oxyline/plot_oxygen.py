"""Oxygen figures: the paper's Fig. 4 (convective O2 flux at the end of each tube against time)
and the wall uptake along each vessel; the coronary flow impediment and its effect on the wall
uptake (``coronary_impediment``, ``python -m oxyline.plot_oxygen coronary OUTDIR``).

    from oxyline import plot_oxygen
    plot_oxygen.save_oxygen_figures(result, model, "figs/")
"""

from __future__ import annotations

import copy
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from oxyline.model import Model
from oxyline.plot_style import STYLES, prefixed, pyplot, same_curves, write_figures
from oxyline.result import Result


def _note(model: Model | None) -> str:
    desc = (model.source.get("description", "") if model is not None else "") or ""
    return "\n(radii and inflow waveform assumed, not the paper's)" if "assum" in desc else ""


def _titled(fig: Any, ax: Any, title: str) -> Any:
    """``fig`` with the legend and ``title`` on its top axes ``ax``, laid out."""
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


# vessels whose curves coincide (the daughters of a symmetric bifurcation) are drawn once and
# named together (plot.same_curves); the others get a line style on top of their colour


def _honest_axis(ax: Any, values: np.ndarray, unit: str) -> None:
    """Tick labels with the full values (no hidden '+2.1e3' offset), and a note when the curves
    only vary by a small fraction of their level, so that a flat flux does not look like a
    large swing."""
    ax.ticklabel_format(axis="y", useOffset=False, style="plain")
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return
    level, span = float(np.max(np.abs(finite))), float(np.ptp(finite))
    if level > 0 and span < 0.01 * level:
        ax.text(0.01, 0.97, f"varies by {100 * span / level:.2g} % of {level:.4g} {unit}",
                transform=ax.transAxes, va="top", fontsize=8)


def outlet_flux(result: Result, model: Model | None = None) -> Any:
    """Convective O2 flux Q·C at the end of each vessel against time (the paper's Fig. 4),
    with each vessel's wall uptake in a second panel (J_in − J_out also contains the change of
    the O2 stored in the compliant vessel, which dominates it). Each panel in mol/s with the
    SI prefix that suits its values; coinciding curves (symmetric daughters) drawn once.

    >>> import oxyline
    >>> from oxyline import plot_oxygen
    >>> res = oxyline.simulate("paper-bifurcated", cycles=1)
    >>> fig = plot_oxygen.outlet_flux(res)
    >>> [ax.get_ylabel() for ax in fig.axes]
    ['J$_{out}$ [µmol/s]', 'wall uptake [µmol/s]']
    """
    plt = pyplot()
    if result.oxygen is None:
        raise ValueError("this result has no oxygen section")
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    # one unit for the figure (the panels compare), its prefix from the larger values
    unit, k = prefixed("mol/s", np.concatenate([np.ravel(result.o2_flux_out),
                                                np.ravel(result.wall_o2_flux)]))
    for ax, data, what in ((a1, result.o2_flux_out, "J$_{out}$"),
                           (a2, result.wall_o2_flux, "wall uptake")):
        series = {name: np.asarray(data[:, i]) for i, name in enumerate(result.vessels)}
        for names, y in same_curves(series):
            i = list(result.vessels).index(names[0])
            ax.plot(result.time, y * k, STYLES[i % len(STYLES)], color=f"C{i % 10}",
                    label=" = ".join(names))
        ax.set_ylabel(f"{what} [{unit}]")
        _honest_axis(ax, np.asarray(data) * k, unit)
    a2.set_xlabel("time in cycle [s]")
    return _titled(fig, a1, f"{result.model_name}: convective O$_2$ flux at the vessel "
                   f"outlets{_note(model)}")


def wall_uptake(result: Result, model: Model | None = None) -> Any:
    """Cycle-mean wall O2 flux per unit length along each vessel, in mol/(m·s) with the SI
    prefix that suits the values.

    >>> import oxyline
    >>> from oxyline import plot_oxygen
    >>> res = oxyline.simulate("paper-bifurcated", cycles=1)
    >>> plot_oxygen.wall_uptake(res).axes[0].get_xlabel()
    'distance from the vessel inlet [mm]'
    """
    plt = pyplot()
    if result.oxygen is None or not result.has_segments:
        raise ValueError("needs an oxygen result with segment output")
    fig, ax = plt.subplots(figsize=(7, 4))
    w = result.species[result.oxygen].segment("wall_flux").mean(axis=0)
    pos = result.segment_position
    start = np.concatenate([[0], np.cumsum(result.segment_count)]).astype(int)
    lines = []
    for i, name in enumerate(result.vessels):
        a, b = start[i], start[i + 1]
        if b - a < 1:
            continue
        dx = 2 * pos[a] if b - a == 1 else pos[a + 1] - pos[a]
        lines.append((i, name, pos[a:b] * 1e3, w[a:b] / dx))
    unit, k = prefixed("mol/(m·s)", np.concatenate([y for *_, y in lines]) if lines else [])
    for i, name, x, y in lines:
        ax.plot(x, y * k, "o" + STYLES[i % len(STYLES)], color=f"C{i % 10}", label=name)
    ax.set_xlabel("distance from the vessel inlet [mm]")
    ax.set_ylabel(f"wall O$_2$ uptake [{unit}]")
    return _titled(fig, ax, f"{result.model_name}: cycle-mean wall uptake along each "
                   f"vessel{_note(model)}")


def save_oxygen_figures(result: Result, model: Model | None, outdir: str | os.PathLike[str],
                        formats: tuple[str, ...] = ("png", "svg")) -> list[Path]:
    """Write ``o2_outlet_flux`` and ``o2_wall_uptake`` figures; returns the files written.

    >>> import tempfile, oxyline
    >>> from oxyline import plot_oxygen
    >>> res = oxyline.simulate("paper-bifurcated", cycles=1)
    >>> with tempfile.TemporaryDirectory() as out:
    ...     [p.name for p in plot_oxygen.save_oxygen_figures(res, None, out, formats=("png",))]
    ['o2_outlet_flux.png', 'o2_wall_uptake.png']
    """
    figs = {"o2_outlet_flux": outlet_flux(result, model)}
    if result.has_segments:
        figs["o2_wall_uptake"] = wall_uptake(result, model)
    return write_figures(figs, outdir, formats, 150)


def without_intramyocardial_pressure(model: Model) -> dict[str, Any]:
    """The model's source with every `coronary` outlet's intramyocardial pressure set to 0:
    the same bed without the systolic squeeze (the reference case of the impediment).

    >>> import oxyline
    >>> from oxyline import plot_oxygen
    >>> m = oxyline.load_model("paper-curved-coronary")
    >>> src = plot_oxygen.without_intramyocardial_pressure(m)
    >>> {bc["intramyocardial_pressure"] for bc in src["boundary_conditions"].values()
    ...  if bc.get("type") == "coronary"}
    {0.0}
    """
    src = copy.deepcopy(model.source)
    for bc in src.get("boundary_conditions", {}).values():
        if isinstance(bc, dict) and bc.get("type") == "coronary":
            bc["intramyocardial_pressure"] = 0.0
    return src


def coronary_impediment(result: Result, rigid: Result, vessel: str | None = None,
                        systole: float | None = None) -> Any:
    """Inflow and wall O2 uptake of one vessel with the intramyocardial pressure (`result`) and
    without it (`rigid`, from :func:`without_intramyocardial_pressure`), with the systolic
    means in the legend (docs/oxygen.md "Coronary oxygen"). Flow in mL/s, uptake in nmol/s.

    >>> import oxyline
    >>> from oxyline import plot_oxygen
    >>> m = oxyline.load_model("paper-curved-coronary")
    >>> rigid = oxyline.load_model(plot_oxygen.without_intramyocardial_pressure(m))
    >>> fig = plot_oxygen.coronary_impediment(oxyline.simulate(m, cycles=1),
    ...                                       oxyline.simulate(rigid, cycles=1), systole=0.35)
    >>> fig.axes[1].get_ylabel()
    'wall O$_2$ uptake [nmol/s]'
    """
    plt = pyplot()
    name = vessel or result.vessels[0]
    i = list(result.vessels).index(name)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    t = np.asarray(result.time)
    tc = t - t[0]
    sys_mask = np.mod(tc, result.settings["period"]) < systole if systole else np.zeros(t.shape, bool)
    for res, label, style in ((result, "with P$_{im}$(t)", "-"), (rigid, "P$_{im}$ = 0", "--")):
        q = np.asarray(res.vessel(name).flow_in) * 1e6
        w = res.wall_o2_flux[:, i] * 1e9
        extra = (f", systolic mean {q[sys_mask].mean():.3f}" if sys_mask.any() else "")
        a1.plot(tc, q, style, label=f"{label}{extra}")
        extra = (f", systolic mean {w[sys_mask].mean():.6f}" if sys_mask.any() else "")
        a2.plot(tc, w, style, label=f"{label}{extra}")
    if systole:
        for ax in (a1, a2):
            ax.axvspan(0, systole, color="0.9", zorder=0)
    a1.set_ylabel(f"inflow of '{name}' [mL/s]")
    a2.set_ylabel("wall O$_2$ uptake [nmol/s]")
    _honest_axis(a2, np.concatenate([result.wall_o2_flux[:, i], rigid.wall_o2_flux[:, i]]) * 1e9,
                 "nmol/s")
    a2.set_xlabel("time in cycle [s]; grey: systole")
    a2.legend(fontsize=8, loc="lower right")
    return _titled(fig, a1, f"{result.model_name}: systolic flow impediment by "
                   "intramyocardial pressure")


def _main(argv: list[str]) -> int:
    """``python -m oxyline.plot_oxygen coronary OUTDIR``: the coronary figure of the README."""
    if len(argv) != 2 or argv[0] != "coronary":
        print("usage: python -m oxyline.plot_oxygen coronary OUTDIR", file=sys.stderr)
        return 2
    from oxyline import catalogue, simulate
    from oxyline.loader import load_model

    model = catalogue.load("paper-curved-coronary")
    fig = coronary_impediment(simulate(model), simulate(load_model(
        without_intramyocardial_pressure(model))), systole=0.35)
    out = Path(argv[1])
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "coronary_o2.png", dpi=120)
    return 0


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
