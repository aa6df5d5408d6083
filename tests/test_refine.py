"""Transport refinement: ``cells_per_segment`` m transport cells per flow segment (docs/physics.md §5).

Truths: the tanks-in-series law of N·m tanks (scipy's regularised incomplete gamma), the
discrete constant-k law, exact identities (m = 1 is the unrefined model), conservation.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from conftest import tube
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.special import gammainc
from test_oxygen import check_mass_balance_and_positivity, networks

import oxyline
from oxyline import catalogue

R, DX, Q, N = 3e-3, 0.01, 2e-6, 10
V = Q / (math.pi * R * R)


def dye_tube(m: int | None, **transport: object) -> dict:
    model: dict = {
        "period": 1.0,
        "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": N,
                     "length": N * DX, "radius": R}],
        "boundary_conditions": {"in": {"type": "flow", "value": Q},
                                "out": {"type": "resistance", "resistance": 1e8}},
        "species": [{"name": "dye", "inlet": {"concentration": 1.0}, "initial": 0.0}],
    }
    if m is not None:
        transport["cells_per_segment"] = m
    if transport:
        model["transport"] = transport
    return model


def outlet_error(m: int, dt: float) -> float:
    """max over time of |c_out − P(N m, v t m/dx)| (backward-Euler transport)."""
    res = oxyline.simulate(dye_tube(m), method="generalized-alpha", dt=dt, cycles=3,
                           output_every=0.05, output_cycles="all")
    c = res.segment_dye_concentration[:, N - 1]
    exact = gammainc(N * m, V * res.time * m / DX)
    return float(np.max(np.abs(c - exact)))


@pytest.mark.parametrize("m", [1, 2, 4])
def test_outlet_is_the_tanks_in_series_law_of_n_times_m_tanks(m: int) -> None:
    # the implicit path's time error is first order: halving dt halves it
    e1, e2 = outlet_error(m, 4e-3), outlet_error(m, 2e-3)
    assert e1 < 0.03 and e2 < 0.015
    assert e1 / e2 == pytest.approx(2.0, abs=0.15)


def test_one_cell_per_segment_is_the_unrefined_model() -> None:
    kw = {"method": "generalized-alpha", "dt": 2e-3, "cycles": 2}
    a = oxyline.simulate(dye_tube(None), **kw)
    b = oxyline.simulate(dye_tube(1), **kw)
    for key in ("vessel_data", "segment_data"):
        assert np.array_equal(getattr(a.species["dye"], key), getattr(b.species["dye"], key))


def test_cell_counts_and_per_vessel_overrides() -> None:
    assert oxyline.load_model(dye_tube(3)).network.transport_layout()["cells"] == 3 * N
    m = dye_tube(None, cells_per_vessel={"tube": 2})
    assert oxyline.load_model(m).network.transport_layout()["cells"] == 2 * N
    # oxygen section: cells_per_segment and per_vessel {cells_per_segment} (keeps the wall)
    ox = catalogue.load("paper-bifurcated").source
    base = oxyline.load_model(ox).network.transport_layout()["cells"]
    ox2 = copy.deepcopy(ox)
    ox2["oxygen"]["cells_per_segment"] = 2
    assert oxyline.load_model(ox2).network.transport_layout()["cells"] == 2 * base
    ox3 = copy.deepcopy(ox)
    name = ox3["vessels"][-1]["name"]
    ox3["oxygen"]["per_vessel"] = {name: {"cells_per_segment": 4}}
    assert oxyline.load_model(ox3).network.transport_layout()["cells"] > base


def test_refined_paper_example_keeps_the_exact_mass_balance() -> None:
    m = copy.deepcopy(catalogue.load("paper-bifurcated").source)
    m["oxygen"]["cells_per_segment"] = 3
    res = oxyline.simulate(m, cycles=2)
    mb = res.o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-12 * mb["inflow"][-1]
    assert np.all(res.wall_o2_flux > 0)


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "four"])
def test_bad_cells_per_segment_names_key_and_value(bad: object) -> None:
    with pytest.raises(oxyline.ModelError, match=f"cells_per_segment.*{bad!r}"):
        oxyline.load_model(dye_tube(bad))  # type: ignore[arg-type]
    ox = copy.deepcopy(catalogue.load("paper-straight").source)
    ox["oxygen"]["cells_per_segment"] = bad
    with pytest.raises(oxyline.ModelError, match=f"oxygen.*cells_per_segment.*{bad!r}"):
        oxyline.load_model(ox)


def test_unknown_vessel_in_cells_per_vessel() -> None:
    with pytest.raises(oxyline.ModelError, match="cells_per_vessel.*'nope'"):
        oxyline.load_model(dye_tube(None, cells_per_vessel={"nope": 2}))


# ---------------------------------------------------------------------------------------------
# random networks (trees, loops, reversal) with refinement and the relaxed Lévêque shear

@st.composite
def refined_networks(draw: st.DrawFn) -> dict:
    model = draw(networks())
    model["oxygen"]["cells_per_segment"] = draw(st.integers(1, 3))
    if draw(st.booleans()):
        model["oxygen"]["wall"] = {"model": "leveque", "po2": 40.0, "shear": "relaxed",
                                   "enhancement": 50.0}
    if draw(st.booleans()):
        model["oxygen"]["per_vessel"] = {"v0": {"cells_per_segment": draw(st.integers(1, 4))}}
    return model


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(refined_networks())
def test_property_refined_mass_balance_and_positivity(model: dict) -> None:
    check_mass_balance_and_positivity(oxyline.simulate(model, output_every=0.01))


@pytest.mark.parametrize("m", [1, 3])
def test_relaxed_shear_equals_cycle_mean_in_steady_flow(m: int) -> None:
    """Constant inflow: the relaxed boundary-layer shear stays at its cycle-mean start."""
    out = []
    for shear in ("cycle-mean", "relaxed"):
        ox = {"inlet": {"po2": 85.0}, "cells_per_segment": m,
              "wall": {"model": "leveque", "po2": 48.0, "shear": shear, "enhancement": 20.0}}
        res = oxyline.simulate(tube(9, oxygen=ox, radius=1.5e-3, length=0.0346, flow=1.6e-6,
                                    cycles=20), output_every=0.1)
        out.append(res.segment_po2[-1])
    assert np.allclose(out[0], out[1], rtol=1e-12, atol=0)
    assert out[0][-1] < 84.0


def test_bad_shear_names_the_options() -> None:
    ox = {"inlet": {"po2": 85.0}, "wall": {"model": "leveque", "po2": 48.0, "shear": "slow"}}
    with pytest.raises(oxyline.ModelError, match="relaxed.*'slow'"):
        oxyline.load_model(tube(3, oxygen=ox))
