"""Rough edges a new user meets."""

from __future__ import annotations

import argparse
import pickle

import numpy as np
import pytest

import oxyline
from oxyline import cli


def _actions(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.Action]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += [(f"{name} {n}", a) for n, a in _actions(sub)]
        elif not isinstance(action, argparse._HelpAction):
            out.append((action.dest, action))
    return out


def test_every_cli_option_has_help_text() -> None:
    missing = [name for name, action in _actions(cli._parser()) if not action.help]
    assert missing == []


def test_solver_failure_is_said_once(monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    def fail(*args: object, **kwargs: object) -> None:
        raise oxyline.SolverError("solver failed: Newton did not converge at t = 0.1 s")

    monkeypatch.setattr(oxyline, "simulate", fail)
    assert cli.main(["run", "bifurcation", "--quiet"]) == 1
    assert capsys.readouterr().err == \
        "error: solver failed: Newton did not converge at t = 0.1 s\n"


@pytest.mark.parametrize("name", ["bifurcation", "paper-bifurcated"])
def test_pickled_result_is_its_data_once(name: str) -> None:
    """A Result pickles its arrays once (the vessel/segment blocks are views of ``data``,
    rebuilt on loading); before, each view was pickled as a copy (twice the data)."""
    res = oxyline.simulate(name, cycles=1)
    data = res.data.nbytes + sum(s.vessel_data.nbytes + s.segment_data.nbytes
                                 + s.balance_data.nbytes for s in res.species.values())
    blob = pickle.dumps(res)
    assert len(blob) <= 1.05 * data + 50_000  # names, settings and pickle framing
    back = pickle.loads(blob)
    assert np.array_equal(back.segment_flow, res.segment_flow)
    assert np.array_equal(back.pressure_out, res.pressure_out)
    assert back.settings == res.settings and back.vessels == res.vessels
    if res.species:
        assert np.array_equal(back.po2_out, res.po2_out, equal_nan=True)


class _Bar:
    """A stand-in for tqdm that records what the progress bar would show."""

    def __init__(self, total: float | None = None, **kwargs: object) -> None:
        self.total, self.n, self.shown = total, 0.0, []
        self.format = str(kwargs.get("bar_format", ""))

        self.desc = str(kwargs.get("desc", ""))

    def refresh(self) -> None:
        self.shown.append((self.n, self.total))

    def set_description(self, desc: str, refresh: bool = True) -> None:
        self.desc = desc

    def close(self) -> None:
        pass


@pytest.mark.parametrize(("model", "options"), [
    ("paper-bifurcated", {}),  # oxygen: the core restarts its time after a flow pre-run
    ("bifurcation", {"until_periodic": 1e-6, "max_cycles": 200}),
])
def test_progress_counts_cycles_and_never_goes_back(monkeypatch: pytest.MonkeyPatch,
                                                    model: str, options: dict) -> None:
    from oxyline import run

    bars: list[_Bar] = []

    def make(**kwargs: object) -> _Bar:
        bars.append(_Bar(**kwargs))
        return bars[-1]

    monkeypatch.setattr(run, "tqdm_class", lambda: make)
    res = oxyline.simulate(model, progress=True, **options)
    shown = bars[0].shown
    counts = [n for n, _ in shown]
    assert counts == sorted(counts)  # before: the oxygen run's bar jumped from 3.0 s back to 0.3 s
    # the count ends at the cycles run: before, an oxygen run's flow-only pass was added and
    # a 3-cycle run counted 6
    assert counts[-1] == pytest.approx(res.settings["cycles_run"], abs=1e-9)
    assert max(counts) <= res.settings["cycles_run"] + 1e-9
    assert bars[0].desc == "run"
    if "until_periodic" in options:  # before: a percentage of max_cycles, stuck at a few %
        assert all(total is None for _, total in shown)
        assert "until the cycle-to-cycle change < 1e-06" in bars[0].format
    else:
        assert "cycles" in bars[0].format


def test_progress_bar_in_a_notebook_without_ipywidgets_is_the_text_bar(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """tqdm.auto in Jupyter without ipywidgets warned "IProgress not found" on every run."""
    import sys
    import types
    import warnings

    import tqdm.std

    from oxyline import run

    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))
    monkeypatch.setitem(sys.modules, "ipywidgets", None)  # import fails: not installed
    assert run.tqdm_class() is tqdm.std.tqdm
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        oxyline.simulate("bifurcation", cycles=1, progress=True)


CEREBRAL = ("MCA", "ACA", "PCA", "Basilar", "int-carotid", "cerebral")


def test_default_figures_show_arteries_of_several_regions() -> None:
    pytest.importorskip("matplotlib")
    from oxyline import plot

    m = oxyline.load_model("circle-of-willis")
    chosen = plot.representative_vessels(oxyline.simulate(m, cycles=1), m)
    # before: the inlet and the first 4 outlets (aorta, arms), no cerebral vessel
    assert chosen[0] == "1-Ascendingaorta" and len(chosen) == 5
    assert any(any(c in v for c in CEREBRAL) for v in chosen), chosen
    wb = oxyline.load_model("whole-body-140")
    res = oxyline.simulate(wb, cycles=1, until_periodic=None, method="generalized-alpha")
    internal = plot.internal_vessels(wb)
    assert len(internal) == 242 and all(".wall" in v for v in internal)
    chosen = plot.representative_vessels(res, wb)
    assert not set(chosen) & internal and len(set(chosen)) == 5
    assert any(any(c in v for c in CEREBRAL) for v in chosen), chosen
    import matplotlib.pyplot as plt

    fig = plot.waveforms(res, chosen)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(r)
    # before: the legend of the long names covered the title and squeezed the panels
    assert not legend.overlaps(fig._suptitle.get_window_extent(r))
    assert not any(legend.overlaps(ax.get_window_extent(r)) for ax in fig.axes)
    plt.close(fig)


def test_console_table_leaves_out_internal_branches(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "whole-body-140", "--cycles", "1"]) == 0
    out = capsys.readouterr().out.splitlines()
    head = next(i for i, line in enumerate(out) if line.startswith("vessel"))
    rows = out[head + 1:head + 21]
    assert len(rows) == 20 and not any(".wall" in r for r in rows)  # before: 9 of 20
    assert out[head + 21] == "... 323 more vessels and 242 internal branches (e.g. wall " \
                             "viscosity) not shown"


def test_oxygen_figure_one_unit_full_tick_values_distinct_styles() -> None:
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from oxyline import plot_oxygen

    res = oxyline.simulate("paper-bifurcated", cycles=1)
    fig = plot_oxygen.outlet_flux(res)
    a1, a2 = fig.axes[:2]
    # before: nmol/s above, pmol/s below; the wall-uptake axis hid a +2.1e3 offset; then
    # nmol/s values in the thousands: one unit, with the prefix that suits the figure
    unit = a1.get_ylabel().split("[")[1].rstrip("]")
    assert a2.get_ylabel().endswith(f"[{unit}]") and unit.endswith("mol/s")
    k = {"mmol/s": 1e3, "µmol/s": 1e6, "nmol/s": 1e9, "pmol/s": 1e12}[unit]
    assert 1.0 <= k * max(np.abs(res.o2_flux_out).max(), np.abs(res.wall_o2_flux).max()) < 1000
    for ax in (a1, a2):
        assert not ax.yaxis.get_major_formatter().get_useOffset()
    # coinciding curves (the symmetric daughters) drawn once and named together; every vessel
    # named once; the curves left are all different
    labels = [line.get_label() for line in a1.get_lines()]
    assert sorted(n for lab in labels for n in lab.split(" = ")) == sorted(res.vessels)
    ys = [line.get_ydata() for line in a1.get_lines()]
    assert all(not np.allclose(a, b) for i, a in enumerate(ys) for b in ys[i + 1:])
    wall = res.wall_o2_flux * k
    level = np.max(np.abs(wall))
    plotted = np.concatenate([ln.get_ydata() for ln in a2.get_lines()])
    merged = [lab for lab in (ln.get_label() for ln in a2.get_lines())]
    expected = np.concatenate([wall[:, list(res.vessels).index(lab.split(" = ")[0])]
                               for lab in merged])
    assert np.allclose(plotted, expected)  # the values, in the unit named
    if np.ptp(wall) < 0.01 * level:  # a flat uptake says how flat it is
        assert any("varies by" in t.get_text() for t in a2.texts)
    plt.close(fig)
