"""Structured trees grown by the core on load, and the facilitation factor from the core,
against independent truths: the growth rule's count written out here, the same tree in cgs
and SI units, the guard refusing a huge tree before growing it, and the closed form of the
linearised facilitation factor with the Hill secant computed here."""

from __future__ import annotations

import math
import time

import pytest

import oxyline
from oxyline import _core

FEED = {"name": "feed", "from": "in", "to": "out", "length": 0.05, "radius": 1e-3,
        "wall_thickness": 1e-4, "youngs_modulus": 1e6}


def count(r: float, rmin: float, a: float = 0.9, b: float = 0.6) -> int:
    return sum(1 + count(k * r, rmin) for k in (a, b) if k * r >= rmin)


def model(units: str = "SI", scale: float = 1.0, **tree: object) -> oxyline.Model:
    feed = {k: (v * scale if k in ("length", "radius", "wall_thickness") else v)
            for k, v in FEED.items()}
    feed["youngs_modulus"] = FEED["youngs_modulus"] * (10.0 if units == "cgs" else 1.0)
    return oxyline.load_model({
        "name": "st", "units": units, "period": 1.0, "vessels": [feed],
        "boundary_conditions": {"in": {"type": "flow", "value": 1e-7 * scale**3},
                                "out": {"type": "structured-tree", **tree}}})


def test_the_core_grows_the_counted_tree_in_the_models_units() -> None:
    si = model(min_radius=2e-4, stiffness={"youngs_modulus": 1.5e6, "thickness_ratio": 0.1})
    cgs = model("cgs", 100.0, min_radius=2e-2,
                stiffness={"youngs_modulus": 1.5e7, "thickness_ratio": 0.1})
    n = count(1e-3, 2e-4)
    assert len(si.vessel_names) == len(cgs.vessel_names) == 1 + n
    assert si.vessel_names == cgs.vessel_names
    # the same circuit: Z(0) equal up to the unit factors' rounding (cm -> m, dyn/cm^2 -> Pa)
    z_si = complex(oxyline.impedance(si, "in", 0.0)).real
    z_cgs = complex(oxyline.impedance(cgs, "in", 0.0)).real
    assert abs(z_cgs / z_si - 1.0) < 1e-12


def test_a_huge_tree_is_refused_on_load_before_growing() -> None:
    t0 = time.process_time()
    with pytest.raises(oxyline.ModelError, match="boundary condition 'out' .*the tree has "
                                                 "137512188294 vessels, more than max_vessels"):
        model(min_radius=1e-7)  # Σ C(i+j, i) over α^i β^j r0 >= r_min, by Python's integers
    assert time.process_time() - t0 < 5.0  # not grown (1.4e11 vessels)


def test_linearized_factor_is_the_closed_form_with_the_hill_secant() -> None:
    alpha, d, d_hb, cap, p50, n = 1.4e-3, 2e-9, 5.5e-12, 8.97, 26.8, 2.7

    def s(p: float) -> float:
        return p**n / (p**n + p50**n)

    for p_in, p_w in ((95.0, 60.0), (85.0, 48.0)):
        k = cap * (s(p_in) - s(p_w)) / (alpha * (p_in - p_w))
        exact = (1 + k) ** (1 / 3) * (1 + k * d_hb / d) ** (2 / 3)
        got = _core.facilitation_factor(p_in, p_w, alpha, d, d_hb, cap, p50, n, True)
        assert got == pytest.approx(exact, rel=1e-13)  # two evaluations of the same formula
        assert _core.linear_facilitation_factor(k, d, d_hb) == pytest.approx(exact, rel=1e-14)
    # the nonlinear factor lies below the secant one (docs/validation-oxygen.md §7)
    hill = _core.facilitation_factor(85.0, 48.0, alpha, d, d_hb, cap, p50, n, False)
    assert 1.0 < hill < _core.facilitation_factor(85.0, 48.0, alpha, d, d_hb, cap, p50, n, True)
    assert math.isfinite(hill)
