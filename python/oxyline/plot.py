"""Figures for papers: waveforms, profiles along a path, and a network map (matplotlib).

``import oxyline`` never imports this module or matplotlib; ``import oxyline.plot`` does not
import matplotlib either until a function is called. Every function returns the
:class:`matplotlib.figure.Figure`; axes are labelled ``quantity [unit]`` (pressures in mmHg,
flows in mL/s or a smaller prefix for microvascular flows, lengths in cm, O2 fluxes in mol/s
with the SI prefix that suits the figure's values), texts that would overlap are dropped.
Curves that coincide (the pressure at a node two vessels share) are drawn once, labelled with
every vessel; flows whose peaks differ by more than a decade go in separate panels, one per
decade; a colour bar spanning a narrow range says so in the title.

>>> import oxyline, oxyline.plot
>>> res = oxyline.simulate("bifurcation", cycles=2)
>>> fig = oxyline.plot.waveforms(res, ["parent", "daughter1"])
>>> fig = oxyline.plot.profile(res, "bifurcation", outlet="ica_out")
>>> fig = oxyline.plot.network_map("bifurcation", result=res, values="pressure_in")
"""

from __future__ import annotations

import contextlib
import math
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from oxyline import plot_oxygen
from oxyline.io.results import stats as time_stats
from oxyline.plot_style import STYLES, peak_magnitude, prefixed, pyplot, same_curves, write_figures
from oxyline.units import MMHG

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from oxyline.model import Model
    from oxyline.result import Result

# SI units -> (display units, factor)
DISPLAY = {
    "Pa": ("mmHg", 1.0 / MMHG),
    "m^3/s": ("mL/s", 1e6),
    "m": ("cm", 100.0),
    "mol/s": ("nmol/s", 1e9),
}
LABELS = {
    "pressure": "pressure", "flow": "flow", "po2": "PO$_2$", "o2_flux": "convective O$_2$ flux",
    "wall_o2_flux": "wall O$_2$ flux", "o2_concentration": "O$_2$ concentration",
    "radius": "radius",
}


def _model(model: Model | str | os.PathLike[str] | Mapping[str, Any]) -> Model:
    from oxyline.io.formats import as_model

    return as_model(model)


def display(units: str, values: Any = None) -> tuple[str, float]:
    """Display units and the factor from SI ``units``: Pa → mmHg; m³/s → mL/s (µL/s or nL/s
    when every value of ``values`` is below 0.01 mL/s); m → cm; mol/s with the SI prefix that
    suits ``values`` (nmol/s without them).

    >>> display("Pa")[0], display("mol/s", [3e-5])
    ('mmHg', ('µmol/s', 1000000.0))
    """
    if values is not None and units == "m^3/s" and 0 < peak_magnitude(values) < 1e-8:
        return ("µL/s", 1e9) if peak_magnitude(values) >= 1e-11 else ("nL/s", 1e12)
    if values is not None and units.startswith("mol/s"):
        return prefixed(units, values)
    return DISPLAY.get(units, (units, 1.0))


def _label(quantity: str) -> str:
    base = quantity.removesuffix("_in").removesuffix("_out").removeprefix("segment_")
    return LABELS.get(base, base.replace("_", " "))


def _vessel_variable(ds: Any, quantity: str, end: str = "in") -> str:
    """Name of the (time, vessel) variable for ``quantity`` ("pressure" → "pressure_in")."""
    for name in (quantity, f"{quantity}_{end}", f"{quantity}_in"):
        if name in ds.data_vars and ds[name].dims == ("time", "vessel"):
            return name
    have = sorted(n for n, v in ds.data_vars.items() if v.dims == ("time", "vessel"))
    raise ValueError(f"no per-vessel variable for '{quantity}' in this result (available: "
                     f"{', '.join(have)})")


def _has(ds: Any, quantity: str) -> bool:
    return any(n in ds.data_vars and ds[n].dims == ("time", "vessel")
               for n in (quantity, f"{quantity}_in"))


def _declutter(fig: Any, texts: Sequence[Any]) -> None:
    """Hide texts (in order) that overlap a text kept before them."""
    if sum(1 for t in texts if t.get_visible() and t.get_text()) < 2:
        return
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    kept: list[Any] = []
    for t in texts:
        if not t.get_visible() or not t.get_text():
            continue
        bb = t.get_window_extent(renderer).expanded(1.05, 1.1)
        if any(bb.overlaps(k) for k in kept):
            t.set_visible(False)
        else:
            kept.append(bb)


def decade_groups(peaks: Mapping[str, float]) -> list[list[str]]:
    """Names grouped, largest peak first, so that the peaks within a group lie within a
    factor of 10: a flow of 0.5 mL/s on the axis of a 400 mL/s aortic flow is a flat line,
    so each group gets its own panel.

    >>> decade_groups({"aorta": 4e-4, "iliac": 6e-5, "digital": 2e-7})
    [['aorta', 'iliac'], ['digital']]
    """
    groups: list[list[str]] = []
    for n in sorted(peaks, key=lambda k: -peaks[k]):
        if groups and peaks[n] * 10.0 >= peaks[groups[-1][0]]:
            groups[-1].append(n)
        else:
            groups.append([n])
    return groups


def waveforms(result: Result, vessels: Sequence[str] | str | None = None,
              quantities: Sequence[str] = ("pressure", "flow"), end: str = "in") -> Figure:
    """Waveforms of ``quantities`` (one panel each, e.g. "pressure", "flow", "po2", or a result
    variable name) at the ``end`` ("in"/"out") of each of ``vessels`` (default: up to 6).
    A quantity whose peaks differ by more than a decade between the vessels gets one panel
    per decade (:func:`decade_groups`); coinciding curves are drawn once
    (:func:`same_curves`), labelled ``a = b``.

    >>> import oxyline, oxyline.plot
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> fig = oxyline.plot.waveforms(res, ["parent", "daughter1"])
    >>> [ax.get_ylabel() for ax in fig.axes]
    ['pressure [mmHg]', 'flow [mL/s]']
    """
    plt = pyplot()
    ds = result.to_xarray()
    if isinstance(vessels, str):
        vessels = [vessels]
    names = list(vessels) if vessels is not None else list(result.vessels[:6])
    for n in names:
        if n not in result.vessels:
            raise KeyError(f"vessel '{n}' has no output (vessels: {', '.join(result.vessels[:10])}"
                           f"{', ...' if len(result.vessels) > 10 else ''})")
    panels: list[tuple[str, dict[str, np.ndarray], tuple[str, float], bool]] = []
    for var in (_vessel_variable(ds, q, end) for q in quantities):
        series = {n: np.asarray(ds[var].sel(vessel=n).values, dtype=float) for n in names}
        # one unit per quantity in the figure, from all its values (its panels compare)
        unit = display(str(ds[var].attrs.get("units", "")),
                       np.concatenate([y.ravel() for y in series.values()]))
        groups = decade_groups({n: peak_magnitude(y) for n, y in series.items()})
        panels += [(var, {n: series[n] for n in g}, unit, len(groups) > 1) for g in groups]
    fig, axes = plt.subplots(len(panels), 1, sharex=True, squeeze=False,
                             figsize=(7.0, 2.4 * len(panels) + 0.8), layout="constrained")
    for ax, (var, series, unit, split) in zip(axes[:, 0], panels):
        _waveform_panel(ax, result.time, var, series, unit, names, split)
    axes[-1, 0].set_xlabel("time [s]")
    by_label: dict[str, Any] = {}
    for ax in axes[:, 0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            by_label.setdefault(lab, h)
    # below the panels: long vessel names (whole-body-140) beside them squeezed the axes and
    # covered the title
    longest = max((len(x) for x in by_label), default=0)
    fig.legend(list(by_label.values()), list(by_label), loc="outside lower center", fontsize=8,
               title="vessel", ncols=1 if longest > 40 else min(3, max(1, len(by_label))))
    fig.suptitle(f"{result.model_name}: waveforms", fontsize=11)
    return fig


def _waveform_panel(ax: Any, time: Any, var: str, series: Mapping[str, np.ndarray],
                    unit: tuple[str, float], names: Sequence[str], split: bool) -> None:
    """One panel of :func:`waveforms`: the curves of ``series`` in the display ``unit``
    (name, factor from SI), each vessel in the colour and style of its place in ``names``."""
    units, k = unit
    for merged, y in same_curves(series):
        i = names.index(merged[0])
        ax.plot(time, y * k, label=" = ".join(merged), lw=1.4, color=f"C{i % 10}",
                ls=STYLES[(i // 10) % len(STYLES)])
    ax.set_ylabel(f"{_label(var)} [{units}]" if units else _label(var))
    end_txt = {"in": "inlet", "out": "outlet"}.get(var.rsplit("_", 1)[-1], "")
    title = f"{_label(var)} at the vessel {end_txt}" if end_txt else ""
    if split:
        peaks = [peak_magnitude(y) * k for y in series.values()]
        title += f"{', ' if title else ''}peaks {min(peaks):.3g} to {max(peaks):.3g} {units}"
    if title:
        ax.set_title(title, fontsize=10, loc="left")
    ax.grid(alpha=0.3)


def _graph(model: Model) -> tuple[dict[str, list[tuple[str, str]]], dict[str, dict[str, Any]]]:
    """Adjacency (node -> [(vessel, next node)]) and vessels by name from the canonical model."""
    adj: dict[str, list[tuple[str, str]]] = {}
    vessels = {v["name"]: v for v in model.canonical["vessels"]}
    for v in model.canonical["vessels"]:
        adj.setdefault(v["from"], []).append((v["name"], v["to"]))
        adj.setdefault(v["to"], [])
    return adj, vessels


def _ends(model: Model) -> tuple[set[str], set[str]]:
    """The nodes where vessels start, and those where they end."""
    vessels = model.canonical["vessels"]
    return {v["from"] for v in vessels}, {v["to"] for v in vessels}


def inlets(model: Model) -> list[str]:
    """Nodes with a flow or pressure condition at the start of a vessel.

    >>> import oxyline, oxyline.plot as plot
    >>> plot.inlets(oxyline.load_model("bifurcation"))
    ['inlet']
    """
    starts, ends = _ends(model)
    found = [n for n, bc in model.canonical["boundary_conditions"].items()
             if n in starts and n not in ends and bc["type"] in ("flow", "pressure")]
    return found or [n for n in starts if n not in ends]


def outlets(model: Model) -> list[str]:
    """Nodes with a boundary condition at the end of a vessel.

    >>> import oxyline, oxyline.plot as plot
    >>> plot.outlets(oxyline.load_model("bifurcation"))
    ['ica_out', 'eca_out']
    """
    starts, ends = _ends(model)
    return [n for n in model.canonical["boundary_conditions"] if n in ends and n not in starts]


def path(model: Model, outlet: str, inlet: str | None = None) -> list[str]:
    """Vessel names along the (fewest-vessel) path from ``inlet`` (default: the inlet that
    reaches it) to ``outlet`` (an outlet node or a vessel name), following vessel direction.

    >>> import oxyline, oxyline.plot as plot
    >>> plot.path(oxyline.load_model("bifurcation"), "eca_out")
    ['parent', 'daughter2']
    """
    adj, vessels = _graph(model)
    target = vessels[outlet]["to"] if outlet in vessels else outlet
    if target not in adj:
        raise KeyError(f"'{outlet}' is neither a node nor a vessel of model '{model.name}'")
    for start in ([inlet] if inlet else inlets(model)):
        prev: dict[str, tuple[str, str] | None] = {start: None}
        queue = [start]
        while queue:
            node = queue.pop(0)
            if node == target:
                out: list[str] = []
                while prev[node] is not None:
                    vessel, node = prev[node]  # type: ignore[misc]
                    out.append(vessel)
                return out[::-1]
            for vessel, nxt in adj.get(node, []):
                if nxt not in prev:
                    prev[nxt] = (vessel, node)
                    queue.append(nxt)
    raise KeyError(f"no path from {inlet or 'an inlet'} to '{outlet}' along the vessel directions")


def internal_vessels(model: Model) -> set[str]:
    """Vessels that are internal branches of a model, not arteries: dead ends (one end touches
    no other vessel and has no boundary condition), e.g. the '.wall' branches that put a wall
    viscosity in series with a capacitance (whole-body-140).

    >>> import oxyline, oxyline.plot as plot
    >>> plot.internal_vessels(oxyline.load_model("bifurcation"))
    set()
    """
    count = Counter(end for v in model.canonical["vessels"] for end in (v["from"], v["to"]))
    bcs = model.canonical["boundary_conditions"]

    def closed(node: str) -> bool:  # no condition, or a zero inflow: nothing passes there
        bc = bcs.get(node)
        return bc is None or (bc["type"] == "flow" and bc["flow"].get("kind") == "constant"
                              and bc["flow"].get("value") == 0.0)

    return {v["name"] for v in model.canonical["vessels"]
            if any(count[end] == 1 and closed(end) for end in (v["from"], v["to"]))}


def representative_vessels(result: Result, model: Model, n: int = 5) -> list[str]:
    """Up to ``n`` vessels that show a network: the inlet vessel, then outlet vessels, each the
    one whose path from the inlet overlaps least with the paths already chosen (largest mean
    flow first among equals), so that the figure spans the regions of the network (e.g. the
    brain, an arm and the legs) rather than one of them; never an internal branch
    (:func:`internal_vessels`). Falls back to the first vessels that are not internal.

    >>> import oxyline, oxyline.plot as plot
    >>> m = oxyline.load_model("bifurcation")
    >>> plot.representative_vessels(oxyline.simulate(m, cycles=1), m, n=2)
    ['parent', 'daughter1']
    """
    skip = internal_vessels(model)
    named = [v for v in result.vessels if v not in skip]
    paths: dict[str, set[str]] = {}
    for o in outlets(model):
        try:
            p = [v for v in path(model, o) if v not in skip]
        except KeyError:
            continue
        if p and p[-1] in result.vessels and p[-1] not in skip:
            paths.setdefault(p[-1], set(p))
            first = p[0]
    if not paths:
        return named[:n] or list(result.vessels[:n])
    flowing = "flow_in" in result.vessel_variables
    flow = {v: abs(float(np.mean(result.flow_in[:, result.vessels.index(v)]))) if flowing
            else 0.0 for v in paths}
    chosen = [first] if first in result.vessels else []
    taken = [paths[first]] if first in paths else [{first}]

    def overlap(v: str) -> float:  # the largest Jaccard index with a chosen path
        return max(len(paths[v] & t) / len(paths[v] | t) for t in taken)

    while len(chosen) < n and len(chosen) < len(paths) + 1:
        left = [v for v in paths if v not in chosen]
        if not left:
            break
        best = min(left, key=lambda v: (round(overlap(v), 6), -flow[v], v))
        chosen.append(best)
        taken.append(paths[best])
    return chosen


def _vessel_length(v: Mapping[str, Any]) -> float:
    return float(v["geometry"]["length"]) if "geometry" in v else 0.0


def profile_data(result: Result, model: Model | str, outlet: str, quantity: str = "pressure",
                 inlet: str | None = None) -> dict[str, np.ndarray]:
    """Distance [m] from the inlet and time mean/min/max of ``quantity`` (SI) along the path to
    ``outlet``; uses per-segment output when present, else the vessel ends. Lumped vessels
    have no length; a path of lumped vessels only counts one unit per vessel
    (``distance_units`` "vessel" instead of "m").

    >>> import oxyline, oxyline.plot as plot
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> d = plot.profile_data(res, "bifurcation", "ica_out")
    >>> round(float(d["distance"][-1]), 4), str(d["units"])
    (0.1268, 'Pa')
    """
    m = _model(model)
    ds = result.to_xarray()
    _, vessels = _graph(m)
    # vessels without output are left out: the junction branches of an svZeroDSolver
    # BloodVesselJunction (lumped, no length) are model vessels but no result columns
    names = [n for n in path(m, outlet, inlet) if n in result.vessels]
    if not names:
        raise ValueError(f"no vessel on the path to '{outlet}' has output (recorded vessels: "
                         f"{', '.join(result.vessels[:10])})")
    seg_in, seg_out, seg_mid = (f"segment_{quantity}{end}" for end in ("_in", "_out", ""))
    seg_in, seg_out = (v if v in ds.data_vars else None for v in (seg_in, seg_out))
    seg_mid = seg_mid if seg_in is None and seg_mid in ds.data_vars else None
    xs: list[float] = []
    series: list[np.ndarray] = []
    x0 = 0.0
    lumped_path = all(_vessel_length(vessels[n]) == 0.0 for n in names)
    for n in names:
        # a path of lumped vessels only has no length: one unit per vessel instead
        length = 1.0 if lumped_path else _vessel_length(vessels[n])
        v = result.vessel(n)
        nseg = 0 if v.segment_flow is None else v.segment_flow.shape[1]
        sel = np.flatnonzero(ds["segment_vessel"].values == n) if "segment_vessel" in ds else []
        if nseg and (seg_in or seg_mid) and len(sel) == nseg:
            if seg_mid:
                pos = np.asarray(v.segment_position, dtype=float)
                if not np.all(np.isfinite(pos)):
                    pos = np.full(nseg, length / 2)
                xs += [x0 + pos[j] for j in range(nseg)]
            else:  # the segments' inlets, then the last one's outlet
                xs += [x0 + length * j / nseg for j in range(nseg)]
            series += [ds[seg_mid or seg_in].values[:, i] for i in sel]
            if seg_out and not seg_mid:
                xs.append(x0 + length)
                series.append(ds[seg_out].values[:, sel[-1]])
        else:
            var_in = _vessel_variable(ds, quantity, "in")
            var_out = var_in[:-3] + "_out" if var_in.endswith("_in") else None
            if var_out and var_out in ds.data_vars:
                xs += [x0, x0 + length]
                series += [ds[var_in].sel(vessel=n).values, ds[var_out].sel(vessel=n).values]
            else:
                xs.append(x0 + length / 2)
                series.append(ds[var_in].sel(vessel=n).values)
        x0 += length
    a = np.array(series).T  # (time, point)
    t = np.asarray(result.time, dtype=float)
    mean = time_stats(a, t)[0]
    bounds = np.cumsum([0.0] + [1.0 if lumped_path else _vessel_length(vessels[n])
                                for n in names])
    var = seg_in or seg_mid or _vessel_variable(ds, quantity)
    return {"distance": np.array(xs), "mean": mean, "min": a.min(axis=0), "max": a.max(axis=0),
            "vessels": np.array(names, dtype=object), "vessel_start": bounds,
            "units": np.array(str(ds[var].attrs.get("units", ""))),
            "distance_units": np.array("vessel" if lumped_path else "m")}


def profile(result: Result, model: Model | str, outlet: str,
            quantity: str | Sequence[str] = "pressure", inlet: str | None = None) -> Figure:
    """Time-mean ``quantity`` (with its min–max band over the cycle) against distance along the
    path from the inlet to ``outlet`` (node or vessel name). ``quantity`` may be a list, one panel
    each; "pressure", "flow", "po2", "o2_flux" or any result variable. Vessel boundaries are
    marked and named.

    >>> import oxyline, oxyline.plot as plot
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> fig = plot.profile(res, "bifurcation", "ica_out", ["pressure", "flow"])
    >>> fig.axes[-1].get_xlabel()
    'distance from the inlet [cm]'
    """
    plt = pyplot()
    m = _model(model)
    quantities = [quantity] if isinstance(quantity, str) else list(quantity)
    fig, axes = plt.subplots(len(quantities), 1, sharex=True, squeeze=False,
                             figsize=(7.5, 2.6 * len(quantities) + 1.2), layout="constrained")
    texts = []
    for row, (ax, q) in enumerate(zip(axes[:, 0], quantities)):
        d = profile_data(result, m, outlet, q, inlet)
        units, k = display(str(d["units"]), np.concatenate([d["min"], d["max"]]))
        xk = 1.0 if str(d["distance_units"]) == "vessel" else 100.0
        x = d["distance"] * xk
        ax.fill_between(x, d["min"] * k, d["max"] * k, color="C0", alpha=0.2,
                        label="min–max over the cycle")
        ax.plot(x, d["mean"] * k, "-", color="C0", marker="." if len(x) < 80 else None,
                label="time mean")
        ax.set_ylabel(f"{_label(q)} [{units}]" if units else _label(q))
        ax.grid(alpha=0.3)
        for xb in d["vessel_start"][1:-1] * xk:
            ax.axvline(xb, color="0.6", lw=0.7, ls=":")
        if row == 0:
            starts = d["vessel_start"] * xk  # each vessel's name above its middle
            texts += [ax.annotate(str(n), (0.5 * (a + b), 1.0), xycoords=("data", "axes fraction"),
                                  xytext=(0, 3), textcoords="offset points", ha="center",
                                  va="bottom", fontsize=7, rotation=0)
                      for n, a, b in zip(d["vessels"], starts[:-1], starts[1:])]
            ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("distance from the inlet [cm]" if xk == 100.0 else
                           "lumped vessels along the path (no length) [vessel]")
    names = path(m, outlet, inlet)
    fig.suptitle(f"{m.name}: from the inlet to {names[-1]}"
                 + (f" (node {outlet})" if outlet != names[-1] else ""), fontsize=11)
    _declutter(fig, texts)
    return fig


def _tree_layout(model: Model) -> dict[str, tuple[float, float]]:
    """Tidy layered layout: x = number of vessels from the inlet, leaves evenly spaced in y,
    a parent centred on its children (a BFS spanning tree for networks with loops)."""
    adj, _ = _graph(model)
    und: dict[str, list[str]] = {n: [] for n in adj}
    for a, outs in adj.items():
        for _, b in outs:
            und[a].append(b)
            und[b].append(a)
    roots = inlets(model) or list(adj)[:1]
    depth: dict[str, int] = {}
    children: dict[str, list[str]] = {n: [] for n in adj}
    for r in roots + list(adj):
        if r in depth:
            continue
        depth[r] = 0
        queue = [r]
        while queue:
            n = queue.pop(0)
            for c in und[n]:
                if c not in depth:
                    depth[c] = depth[n] + 1
                    children[n].append(c)
                    queue.append(c)
    pos: dict[str, tuple[float, float]] = {}
    counter = [0.0]

    def place(n: str) -> float:
        if not children[n]:
            y = counter[0]
            counter[0] += 1.0
        else:
            y = float(np.mean([place(c) for c in children[n]]))
        pos[n] = (float(depth[n]), -y)
        return y

    import sys

    sys.setrecursionlimit(max(1000, 4 * len(adj) + 100))
    for r in [n for n, d in depth.items() if d == 0]:  # the roots, in the order they were found
        place(r)
    return pos


def _layout(model: Model, layout: str) -> dict[str, tuple[float, float]]:
    starts, ends = _ends(model)
    # a connected graph is a tree iff edges = nodes - 1 (per component; checked globally)
    loop = len(model.canonical["vessels"]) > len(starts | ends) - 1
    if layout == "tree" or (layout == "auto" and not loop):
        return _tree_layout(model)
    try:
        import networkx as nx
    except ImportError:
        return _tree_layout(model)
    from oxyline.io.graph import to_networkx

    G = nx.Graph(to_networkx(model))
    if layout in ("auto", "kamada-kawai"):
        try:
            p = nx.kamada_kawai_layout(G)
        except ImportError:  # needs scipy
            p = nx.spring_layout(G, seed=1)
    elif layout == "spring":
        p = nx.spring_layout(G, seed=1)
    else:
        raise ValueError(f"layout must be 'auto', 'tree', 'spring' or 'kamada-kawai', got {layout!r}")
    return {str(k): (float(v[0]), float(v[1])) for k, v in p.items()}


def _mean_radii(model: Model) -> np.ndarray:
    """Each vessel's mean radius (m; NaN for a lumped vessel), in model order."""
    return np.array([0.5 * (v["geometry"]["radius_in"] + v["geometry"]["radius_out"])
                     if "geometry" in v else math.nan for v in model.canonical["vessels"]])


def _values(model: Model, values: Any, result: Result | None, label: str | None,
            units: str | None) -> tuple[np.ndarray, str, str, str]:
    """Per-vessel values in model order, colour-bar label and units, and a title note."""
    names = model.vessel_names
    if values is None and result is not None:
        values = "pressure"
    if values is None:
        return _mean_radii(model) * 1000, label or "mean radius", units or "mm", ""
    if isinstance(values, str):
        if result is None:
            raise ValueError(f"values={values!r} names a result variable: pass result=")
        ds = result.to_xarray()
        var = _vessel_variable(ds, values)
        t = np.asarray(result.time, dtype=float)
        a = ds[var].values
        both = var == f"{values}_in" and f"{values}_out" in ds.data_vars
        if both:  # the vessel's mean: average of its two ends
            a = 0.5 * (a + ds[f"{values}_out"].values)
        mean = time_stats(a, t)[0]
        u, k = display(str(ds[var].attrs.get("units", "")), mean)
        by = dict(zip(result.vessels, mean * k))
        return (np.array([by.get(n, math.nan) for n in names]),
                label or f"time-mean {_label(var)}", units if units is not None else u,
                " (mean of the vessel's two ends)" if both else "")
    if isinstance(values, Mapping) or hasattr(values, "to_dict"):
        d = dict(values.to_dict() if hasattr(values, "to_dict") else values)
        arr = np.array([float(d.get(n, math.nan)) for n in names])
    else:
        arr = np.asarray(values, dtype=float)
        if arr.shape != (len(names),):
            raise ValueError(f"values has {arr.size} entries but the model has {len(names)} "
                             "vessels")
    return arr, label or "value", units or "", ""


def network_map(model: Model | str | os.PathLike[str], values: Any = None,
                label: str | None = None, units: str | None = None, result: Result | None = None,
                layout: str = "auto", labels: bool | None = None, cmap: str = "viridis") -> Figure:
    """Draw the network, vessels coloured by a per-vessel quantity, with a colour bar.

    ``values``: a mapping or pandas Series vessel → value, a sequence in model vessel order, the
    name of a result variable (time mean, display units; needs ``result``), or None (mean
    pressure when ``result`` is given, else the vessel radius in mm). ``label``/``units`` name
    the colour bar. ``layout``: "auto" (a tidy tree layout for trees; networkx Kamada-Kawai for
    networks with loops when networkx is installed), "tree", "spring", "kamada-kawai". Line width
    follows the radius; lumped vessels are dashed; vessel names are drawn when they fit
    (``labels=None``: up to 150 vessels), and any that would overlap are dropped.

    >>> import oxyline, oxyline.plot as plot
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> fig = plot.network_map("bifurcation", result=res)
    >>> fig.axes[-1].get_ylabel()
    'time-mean pressure [mmHg]'
    """
    plt = pyplot()
    from matplotlib import colors as mcolors
    from matplotlib.collections import LineCollection

    m = _model(model)
    pos = _layout(m, layout)
    vals, label, units, note = _values(m, values, result, label, units)
    vessels = m.canonical["vessels"]
    segs = [[pos[v["from"]], pos[v["to"]]] for v in vessels]
    radii = _mean_radii(m)
    if np.all(np.isnan(radii)):
        widths = np.full(len(vessels), 2.0)
    else:
        rmax = np.nanmax(radii)
        widths = np.where(np.isnan(radii), 1.5, 1.0 + 5.0 * np.sqrt(radii / rmax))
    n_leaves = max(1, len(outlets(m)))
    height = min(16.0, max(5.0, 0.22 * n_leaves + 1.5))
    fig, ax = plt.subplots(figsize=(8.0, height), layout="constrained")
    finite = vals[np.isfinite(vals)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if vmax <= vmin:
        vmin, vmax = vmin - 0.5 * abs(vmin or 1.0), vmax + 0.5 * abs(vmax or 1.0)
    norm = mcolors.Normalize(vmin, vmax)
    cm = plt.get_cmap(cmap)
    cols = [cm(norm(x)) if np.isfinite(x) else (0.6, 0.6, 0.6, 1.0) for x in vals]
    styles = ["--" if "lumped" in v else "-" for v in vessels]
    ax.add_collection(LineCollection(segs, colors=cols, linewidths=widths, linestyles=styles,
                                     capstyle="round"))
    xy = np.array(list(pos.values()))
    ax.scatter(xy[:, 0], xy[:, 1], s=6, color="0.25", zorder=3)
    starts = inlets(m)
    for node in (n for n in m.canonical["boundary_conditions"] if n in pos):
        ax.scatter(*pos[node], marker=">" if node in starts else "s", s=28, color="k", zorder=4)
    for c, limits in enumerate((ax.set_xlim, ax.set_ylim)):
        pad = 0.05 * max(1e-9, float(np.ptp(xy[:, c])) or 1.0)
        limits(xy[:, c].min() - pad, xy[:, c].max() + pad)
    ax.set_axis_off()
    cb = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cm), ax=ax, shrink=0.8, pad=0.02)
    cb.set_label(f"{label} [{units}]" if units else label)
    cb.ax.yaxis.get_major_formatter().set_useOffset(False)  # full values, no hidden offset
    shown = labels or (labels is None and len(vessels) <= 150)
    texts = [ax.text(0.5 * (x0 + x1), 0.5 * (y0 + y1), v["name"], fontsize=7, ha="center",
                     va="bottom", color="0.1", zorder=3.5,
                     bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none",
                           "alpha": 0.7})
             for v, ((x0, y0), (x1, y1)) in zip(vessels, segs)] if shown else []
    ax.set_title(f"{m.name}: {label}{note}{narrow_range_note(vmin, vmax, units)}", fontsize=11)
    _declutter(fig, texts)
    return fig


def narrow_range_note(vmin: float, vmax: float, units: str) -> str:
    """A note for a colour bar whose range is narrow (under 5 % of its level): the full
    colour scale then stands for a small difference, and the reader must be told.

    >>> narrow_range_note(99.96, 100.0, "mmHg")
    '\\n(colours span only 0.04 mmHg: 99.96 to 100 mmHg)'
    """
    level = max(abs(vmin), abs(vmax))
    span = vmax - vmin
    if not (level > 0 and 0 < span < 0.05 * level):
        return ""
    return f"\n(colours span only {span:.2g} {units}: {vmin:.6g} to {vmax:.6g} {units})"


def save_figures(result: Result, model: Model | str | os.PathLike[str],
                 outdir: str | os.PathLike[str], formats: Sequence[str] = ("png", "svg"),
                 dpi: int = 150) -> list[Path]:
    """Write the standard figures as PNG and SVG into ``outdir``: ``waveforms`` (inlet vessel and
    up to 4 terminal vessels; pressure, flow and PO2 when present), ``profile`` (inlet to the
    outlet farthest from it; pressure, PO2, convective and wall O2 flux when present, flow) and
    ``network_map`` (time-mean pressure).
    Returns the files written.

    >>> import oxyline, oxyline.plot as plot
    >>> import tempfile
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> with tempfile.TemporaryDirectory() as out:
    ...     sorted(p.name for p in plot.save_figures(res, "bifurcation", out, formats=("png",)))
    ['network_map.png', 'profile.png', 'waveforms.png']
    """
    m = _model(model)
    ds = result.to_xarray()
    quantities = [q for q in ("pressure", "flow", "po2") if _has(ds, q)]
    paths = {}
    for o in outlets(m):
        with contextlib.suppress(KeyError):
            paths[o] = path(m, o)
    _, vessels = _graph(m)
    figures = {"waveforms": waveforms(result, representative_vessels(result, m), quantities)}
    if paths:
        far = max(paths, key=lambda o: sum(_vessel_length(vessels[n]) for n in paths[o]))
        along = [q for q in ("pressure", "po2", "o2_flux", "wall_o2_flux", "flow") if _has(ds, q)]
        figures["profile"] = profile(result, m, far, along)
    figures["network_map"] = network_map(m, result=result)
    if getattr(result, "oxygen", None) is not None:
        # the paper's Fig. 4 (outlet convective O2 flux) and the wall uptake along each vessel
        figures["o2_outlet_flux"] = plot_oxygen.outlet_flux(result, m)
        if result.has_segments:
            figures["o2_wall_uptake"] = plot_oxygen.wall_uptake(result, m)
    return write_figures(figures, outdir, formats, dpi)


def impedance(frequencies: Any, z: Any, label: str | None = None,
              ax: Sequence[Any] | None = None) -> Figure:
    """Modulus (Pa·s/m³, log scale) and phase (rad) of input impedances ``z`` (complex, from
    :func:`oxyline.impedance`) against frequency (Hz). Curves go on the axes ``ax`` (modulus,
    phase) of an earlier call when given, to compare networks.

    >>> import oxyline, oxyline.plot as plot
    >>> f = [0.5, 1.0, 2.0]
    >>> fig = plot.impedance(f, oxyline.impedance("bifurcation", "inlet", f))
    >>> fig.axes[0].get_ylabel()
    '|Z| [Pa·s/m³]'
    """
    plt = pyplot()
    if ax is None:
        fig, ax = plt.subplots(2, 1, sharex=True, figsize=(6.0, 5.0), layout="constrained")
        ax[0].set_ylabel("|Z| [Pa·s/m³]")
        ax[0].set_yscale("log")
        ax[1].set_ylabel("phase [rad]")
        ax[1].set_xlabel("frequency [Hz]")
        ax[1].axhline(0.0, color="0.6", lw=0.8)
    fig = ax[0].figure
    f, zz = np.asarray(frequencies, dtype=float), np.asarray(z, dtype=complex)
    ax[0].plot(f, np.abs(zz), label=label)
    ax[1].plot(f, np.angle(zz), label=label)
    if label:
        ax[0].legend()
    return fig
