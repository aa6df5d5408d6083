"""oxyline.plot rendered headless: valid non-empty PNG/SVG, labelled axes with units, no
overlapping text, profile values equal to the result's."""

from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from conftest import run_child

import oxyline

os.environ.setdefault("MPLBACKEND", "Agg")
matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
plot = pytest.importorskip("oxyline.plot")
MMHG = 133.322368


@pytest.fixture(scope="module")
def result() -> oxyline.Result:
    return oxyline.simulate("bifurcation", cycles=2)


@pytest.fixture(scope="module")
def model() -> oxyline.Model:
    return oxyline.load_model("bifurcation")


def _check_png(p: Path) -> None:
    data = p.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert width > 300 and height > 200
    # not a blank canvas: the decoded image has many distinct colours
    img = matplotlib.image.imread(p)
    assert len(np.unique(img.reshape(-1, img.shape[-1]), axis=0)) > 20


def _check_svg(p: Path) -> None:
    root = ET.parse(p).getroot()
    assert root.tag.endswith("svg")
    assert len(list(root.iter())) > 50


def _save(fig: object, tmp_path: Path, name: str) -> None:
    for ext, check in (("png", _check_png), ("svg", _check_svg)):
        p = tmp_path / f"{name}.{ext}"
        fig.savefig(p, dpi=100)  # type: ignore[attr-defined]
        check(p)


def _drawn_texts(fig: object) -> list[object]:
    """Texts matplotlib draws: tick labels in view, axis labels, titles, legends, annotations."""
    out = list(fig.texts)  # type: ignore[attr-defined]
    if fig._suptitle is not None:  # type: ignore[attr-defined]
        out.append(fig._suptitle)  # type: ignore[attr-defined]
    for leg in fig.legends:  # type: ignore[attr-defined]
        out += [*leg.get_texts(), leg.get_title()]
    for ax in fig.axes:  # type: ignore[attr-defined]
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_visible() and ax.axison:
                drawn = axis._update_ticks()  # the ticks inside the view, as draw() uses them
                out += [lab for tick in drawn for lab in (tick.label1, tick.label2)
                        if lab.get_visible()]
                out += [axis.label, axis.get_offset_text()]
        out += [ax.title, ax._left_title, ax._right_title, *ax.texts]
        if ax.get_legend() is not None:
            out += [*ax.get_legend().get_texts(), ax.get_legend().get_title()]
    return out


def _assert_no_text_overlap(fig: object) -> None:
    fig.canvas.draw()  # type: ignore[attr-defined]
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    unique = {id(t): t for t in _drawn_texts(fig)}.values()
    texts = [t for t in unique if t.get_visible() and t.get_text().strip()]
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in texts]
    for (ta, a), (tb, b) in combinations(boxes, 2):
        assert not a.overlaps(b), f"texts overlap: {ta!r} and {tb!r}"
    assert len(boxes) > 5


def test_waveforms(result: oxyline.Result, tmp_path: Path) -> None:
    fig = plot.waveforms(result, ["parent", "daughter1"])
    ax_p, ax_q = fig.axes[:2]
    assert ax_p.get_ylabel() == "pressure [mmHg]" and ax_q.get_ylabel() == "flow [mL/s]"
    assert ax_q.get_xlabel() == "time [s]"
    np.testing.assert_allclose(ax_p.lines[0].get_ydata(), result.vessel("parent").pressure_in
                               / MMHG)
    np.testing.assert_allclose(ax_q.lines[1].get_ydata(), result.vessel("daughter1").flow_in * 1e6)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["parent", "daughter1"]
    _assert_no_text_overlap(fig)
    _save(fig, tmp_path, "waveforms")
    with pytest.raises(ValueError, match="no per-vessel variable for 'po2'"):
        plot.waveforms(result, "parent", quantities=("po2",))
    with pytest.raises(KeyError, match="vessel 'nope'"):
        plot.waveforms(result, ["nope"])


def test_profile_follows_the_path(result: oxyline.Result, model: oxyline.Model,
                                  tmp_path: Path) -> None:
    assert plot.path(model, "ica_out") == ["parent", "daughter1"]
    assert plot.path(model, "daughter2") == ["parent", "daughter2"]
    d = plot.profile_data(result, model, "ica_out", "pressure")
    # 10 + 10 segments: 11 points on the parent, 11 on daughter1, ending at 12.68 cm
    assert len(d["distance"]) == 22 and d["distance"][-1] == pytest.approx(0.0645 + 0.0623)
    t = result.time
    p0 = np.trapezoid(result.vessel("parent").pressure_in, t) / t[-1]
    p_end = np.trapezoid(result.vessel("daughter1").pressure_out, t) / t[-1]
    assert d["mean"][0] == pytest.approx(p0, rel=1e-12)
    assert d["mean"][-1] == pytest.approx(p_end, rel=1e-12)
    assert np.all(np.diff(d["mean"]) <= 1e-9)  # mean pressure falls along the path
    fig = plot.profile(result, model, "ica_out", ["pressure", "flow"])
    assert fig.axes[0].get_ylabel() == "pressure [mmHg]"
    assert fig.axes[1].get_xlabel() == "distance from the inlet [cm]"
    _assert_no_text_overlap(fig)
    _save(fig, tmp_path, "profile")


def test_network_map(result: oxyline.Result, model: oxyline.Model, tmp_path: Path) -> None:
    fig = plot.network_map(model, result=result, values="pressure")
    cbar_ax = fig.axes[-1]
    assert cbar_ax.get_ylabel().endswith("[mmHg]")
    _assert_no_text_overlap(fig)
    _save(fig, tmp_path, "map")
    fig = plot.network_map(model, values={"parent": 1.0, "daughter1": 2.0, "daughter2": 3.0},
                           label="test value", units="a.u.", layout="tree")
    assert fig.axes[-1].get_ylabel() == "test value [a.u.]"
    with pytest.raises(ValueError, match="3 vessels"):
        plot.network_map(model, values=[1.0, 2.0])


def test_network_map_of_a_larger_tree_with_a_loop(tmp_path: Path) -> None:
    vessels = [{"name": "root", "from": "in", "to": "n", "length": 0.05, "radius": 0.01}]
    bcs = {"in": {"type": "flow", "value": 1e-5}}
    frontier = ["n"]
    for level in range(4):
        nxt = []
        for node in frontier:
            for k in range(2):
                child = f"{node}{k}"
                vessels.append({"name": f"v{child}", "from": node, "to": child, "length": 0.03,
                                "radius": 0.008 * 0.8**level})
                nxt.append(child)
        frontier = nxt
    for node in frontier:
        bcs[node] = {"type": "resistance", "resistance": 1e9}
    vessels.append({"name": "bridge", "from": "n00", "to": "n01", "length": 0.02, "radius": 0.002})
    m = oxyline.load_model({"name": "tree", "vessels": vessels, "boundary_conditions": bcs})
    fig = plot.network_map(m)  # a loop: networkx layout; labels that would collide are dropped
    _assert_no_text_overlap(fig)
    fig.savefig(tmp_path / "tree.png", dpi=60)
    _check_png(tmp_path / "tree.png")
    matplotlib.pyplot.close(fig)


def test_po2_is_plotted_when_present(result: oxyline.Result) -> None:
    class WithPO2(oxyline.Result):
        def to_xarray(self):  # type: ignore[no-untyped-def]
            ds = super().to_xarray()
            ds["po2_in"] = (("time", "vessel"), np.full(ds["pressure_in"].shape, 85.0),
                            {"units": "mmHg"})
            ds["po2_out"] = (("time", "vessel"), np.full(ds["pressure_in"].shape, 80.0),
                             {"units": "mmHg"})
            return ds

    r = WithPO2(result.model_name, result.vessels, result.time, result.data,
                result.segment_count, result.segment_position, result.settings)
    fig = plot.waveforms(r, "parent", quantities=("po2",))
    assert fig.axes[0].get_ylabel() == "PO$_2$ [mmHg]"
    d = plot.profile_data(r, "bifurcation", "ica_out", "po2")  # vessel ends only
    np.testing.assert_allclose(d["mean"], [85.0, 80.0, 85.0, 80.0])
    assert r.summary().loc["parent", "po2_out_mean"] == pytest.approx(80.0)


def test_import_oxyline_does_not_import_matplotlib() -> None:
    code = ("import sys, oxyline, oxyline.io; "
            "print('matplotlib' in sys.modules, 'oxyline.plot' in sys.modules)")
    out = run_child([sys.executable, "-c", code], timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


def test_oxygen_profile_of_the_paper_bifurcation(tmp_path: Path) -> None:
    catalogue = pytest.importorskip("oxyline.catalogue")
    if "paper-bifurcated" not in catalogue.list():
        pytest.skip("no paper-bifurcated built-in model")
    m = catalogue.load("paper-bifurcated")
    res = oxyline.simulate(m, cycles=1)
    ds = res.to_xarray()
    if "segment_po2" not in ds:
        pytest.skip("this build has no oxygen output")
    d = plot.profile_data(res, m, "ICA", "po2")
    sel = np.flatnonzero(ds["segment_vessel"].values == "ICA")
    t = res.time
    expected = np.trapezoid(ds["segment_po2"].values[:, sel], t, axis=0) / t[-1]
    np.testing.assert_allclose(d["mean"][-len(sel):], expected, rtol=1e-12)
    assert np.all(np.diff(d["distance"]) > 0)  # cell centres in order along CCA then ICA
    fig = plot.profile(res, m, "ICA", ["pressure", "po2", "o2_flux"])
    # the O2 flux in the prefix that puts its values in [1, 1000): ~3 µmol/s, not nmol/s in
    # the thousands
    assert [ax.get_ylabel() for ax in fig.axes] == ["pressure [mmHg]", "PO$_2$ [mmHg]",
                                                     "convective O$_2$ flux [µmol/s]"]
    peak = max(np.abs(c.get_paths()[0].vertices[:, 1]).max() for c in fig.axes[2].collections)
    assert 1.0 <= peak < 1000.0
    _assert_no_text_overlap(fig)
    fig.savefig(tmp_path / "o2.png", dpi=60)
    _check_png(tmp_path / "o2.png")


def test_profile_of_lumped_vessels_counts_vessels() -> None:
    m = oxyline.load_model({
        "name": "lumped",
        "vessels": [{"name": "a", "from": "in", "to": "j", "lumped": {"resistance": 1e8}},
                    {"name": "b", "from": "j", "to": "out", "lumped": {"resistance": 3e8}}],
        "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                "out": {"type": "pressure", "value": 0.0}}})
    res = oxyline.simulate(m, cycles=1, method="generalized-alpha")
    d = plot.profile_data(res, m, "out", "pressure")
    assert str(d["distance_units"]) == "vessel"
    np.testing.assert_allclose(d["distance"], [0, 1, 1, 2])
    np.testing.assert_allclose(d["mean"], [400.0, 300.0, 300.0, 0.0], atol=1e-6)  # Q R drops


JUNCTION_CASE = (Path(__file__).parent / "data" / "svzerod" / "cases"
                 / "steadyFlow_blood_vessel_junction.json")


def test_profile_through_an_svzerod_blood_vessel_junction() -> None:
    """A BloodVesselJunction's branches are model vessels without output: the profile skips
    them and shows the analytical pressures of the case's own description (dyn/cm² -> Pa)."""
    m = oxyline.load_model(JUNCTION_CASE)
    res = oxyline.simulate(m)
    d = plot.profile_data(res, m, "branch1_seg0", "pressure")
    assert list(d["vessels"]) == ["branch0_seg0", "branch1_seg0"]
    # inlet 3462.5; branch 0 outlet 3462.5 - 5 * 300; branch 1 inlet (junction 1) 1580 and
    # outlet 432.5, from the file's "analytical results"; a steady case, to round-off
    np.testing.assert_allclose(d["mean"], np.array([3462.5, 1962.5, 1580.0, 432.5]) * 0.1,
                               rtol=1e-9)


def test_cli_plot_of_an_svzerod_file_with_junctions(tmp_path: Path) -> None:
    from oxyline.cli import main

    out = tmp_path / "figs"
    out.mkdir()
    assert main(["run", str(JUNCTION_CASE), "--plot", str(out), "--quiet"]) == 0
    assert {"waveforms.png", "profile.png", "network_map.png"} <= {p.name for p in out.iterdir()}


# ---- paper-ready defaults: checked on the figure's properties, not its pixels --------------

def _lines(ax: object) -> list[tuple[str, np.ndarray]]:
    return [(ln.get_label(), np.asarray(ln.get_ydata())) for ln in ax.get_lines()]  # type: ignore[attr-defined]


def test_vessels_leaving_one_node_are_one_curve_named_for_both(result: oxyline.Result) -> None:
    """daughter1 and daughter2 leave node J1: their inlet pressure is J1's, drawn twice it was
    one line hiding the other."""
    fig = plot.waveforms(result, ["parent", "daughter1", "daughter2"])
    ax_p, ax_q = fig.axes[:2]
    labels = [lab for lab, _ in _lines(ax_p)]
    assert labels == ["parent", "daughter1 = daughter2"]
    np.testing.assert_allclose(_lines(ax_p)[1][1], result.vessel("daughter2").pressure_in / MMHG)
    assert [lab for lab, _ in _lines(ax_q)] == ["parent", "daughter1", "daughter2"]  # flows differ
    for ax in fig.axes:  # no two lines of a panel alike
        ys = [y for _, y in _lines(ax)]
        assert all(not np.allclose(a, b) for i, a in enumerate(ys) for b in ys[i + 1:])
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend == ["parent", "daughter1 = daughter2", "daughter1", "daughter2"]
    matplotlib.pyplot.close(fig)


def test_flows_that_differ_by_decades_get_a_panel_each_decade() -> None:
    d = oxyline.catalogue.load_dict("bifurcation")
    d["boundary_conditions"]["eca_out"]["resistance"] *= 300  # ECA flow 1/100 of the ICA's
    res = oxyline.simulate(d, cycles=1)
    fig = plot.waveforms(res, ["parent", "daughter1", "daughter2"])
    flow_axes = [ax for ax in fig.axes if ax.get_ylabel().startswith("flow")]
    assert len(flow_axes) == 2
    assert [lab for lab, _ in _lines(flow_axes[0])] == ["parent", "daughter1"]
    assert [lab for lab, _ in _lines(flow_axes[1])] == ["daughter2"]
    for ax in flow_axes:  # within a panel the peaks lie within a decade
        peaks = [np.abs(y).max() for _, y in _lines(ax)]
        assert max(peaks) <= 10 * min(peaks)
        assert "peaks" in ax.get_title(loc="left")
        assert ax.get_ylabel() == "flow [mL/s]"  # one unit for the quantity in the figure
    q2 = res.vessel("daughter2").flow_in * 1e6
    np.testing.assert_allclose(_lines(flow_axes[1])[0][1], q2)
    matplotlib.pyplot.close(fig)


def test_units_get_the_prefix_that_suits_the_values() -> None:
    assert plot.display("mol/s", [2.5e-6]) == ("µmol/s", 1e6)
    assert plot.display("mol/s", [3e-3, -7e-3]) == ("mmol/s", 1e3)
    assert plot.display("mol/s", [4e-13]) == ("fmol/s", 1e15)
    assert plot.display("m^3/s", [5e-4]) == ("mL/s", 1e6)  # arteries: mL/s as clinicians read
    assert plot.display("m^3/s", [2e-10]) == ("µL/s", 1e9)  # an arteriole's
    assert plot.display("Pa", [1e4]) == ("mmHg", 1 / MMHG)
    for peak in (1e-14, 3e-9, 7.7e-5, 2.0):
        unit, k = plot.prefixed("mol/s", [peak])
        assert 1.0 <= peak * k < 1000.0, (peak, unit)


def test_a_narrow_colour_range_is_stated(model: oxyline.Model) -> None:
    fig = plot.network_map(model, values={"parent": 100.0, "daughter1": 99.98,
                                          "daughter2": 99.96}, label="mean pressure",
                           units="mmHg")
    title = fig.axes[0].get_title()
    assert "colours span only 0.04 mmHg" in title and "99.96 to 100 mmHg" in title
    assert not fig.axes[-1].yaxis.get_major_formatter().get_useOffset()  # full tick values
    _assert_no_text_overlap(fig)
    fig = plot.network_map(model, values={"parent": 100.0, "daughter1": 80.0,
                                          "daughter2": 60.0}, units="mmHg")
    assert "span only" not in fig.axes[0].get_title()
    matplotlib.pyplot.close("all")


def test_every_axis_label_names_its_unit_one_way(result: oxyline.Result,
                                                   model: oxyline.Model) -> None:
    """`quantity [unit]` on every axis of every figure (before: `(nmol/s)`, `(Pa s/m$^3$)`
    beside `[mmHg]`)."""
    import re

    from oxyline import plot_oxygen

    o2 = oxyline.simulate("paper-bifurcated", cycles=1)
    figs = [plot.waveforms(result), plot.profile(result, model, "ica_out", ["pressure", "flow"]),
            plot.network_map(model, result=result), plot_oxygen.outlet_flux(o2),
            plot_oxygen.wall_uptake(o2), plot.impedance([1.0, 2.0], [1e8 + 1e7j, 9e7 - 2e7j])]
    labels = [lab for fig in figs for ax in fig.axes
              for lab in (ax.get_xlabel(), ax.get_ylabel()) if lab]
    assert len(labels) >= 12
    for lab in labels:
        assert re.fullmatch(r"[^()\[\]]+( \([^)]*\))? \[[^\]]+\]( ?;.*)?", lab), lab
    matplotlib.pyplot.close("all")
