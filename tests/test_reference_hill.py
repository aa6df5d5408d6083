"""Haemoglobin facilitation with Hill binding: the 2-D reference with Hill
binding in the fluid (`validation.hill`), the nonlinear facilitation factor
(the core's `facilitation_factor`) and the 1-D closure against the 2-D solution
(docs/validation-oxygen.md §7)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

pytest.importorskip("scipy")

import oxyline
from oxyline._core import facilitation_factor, linear_facilitation_factor
from validation.axisymmetric import (
    ConstantPO2,
    Grid,
    Tube,
    richardson,
    steady_march,
)
from validation.closures import HILL, load_case
from validation.hill import HillBlood, hill_uptake

ALPHA, D, D_HB = 1.40e-3, 1.2e-9, 5.5e-12
H = 150 * 1.34 / 22.414


def test_hill_march_without_haemoglobin_is_the_graetz_solution() -> None:
    """No binding capacity: the nonlinear marcher solves the dissolved-O2 Graetz problem;
    its extrapolated uptake Q α ΔP (1 − θ_m(x*)) matches the exact x-marching (discrete
    Graetz series, Richardson from 400/800 cells) at the coronary's x* = 2e-5."""
    r, length, q = 1.5e-3, 0.03456, 1.6e-6
    xs = math.pi * D * length / (4 * q)
    th = [steady_march(Tube(r, length), ConstantPO2(0.0), np.array([xs]), Grid(radial=n)).theta
          for n in (400, 800)]
    exact = q * ALPHA * (85 - 48) * (1 - float(richardson(th[0], th[1])[0]))
    uptake, est = hill_uptake(HillBlood(capacity=0.0), r, length, q, 85.0, 48.0, cells=80,
                              steps=100)
    # measured 3e-6; the extrapolation itself (the error estimate) is 2e-3
    assert uptake == pytest.approx(exact, rel=2e-5)
    assert est < 5e-3 * exact


def test_hill_factor_reduces_to_the_linear_closed_form() -> None:
    """S = P/(P + P50) with P50 ≫ P is linear: K = H/(α P50) and E_Hb must be
    (1 + K)^{1/3} (1 + K D_Hb/D)^{2/3}; the similarity ODE is solved numerically."""
    p50 = 1e8

    def hill_factor(*args: float) -> float:
        return facilitation_factor(*args, False)

    for k in (1.0, 20.0, 60.0):
        e = hill_factor(85.0, 48.0, ALPHA, D, D_HB, k * ALPHA * p50, p50, 1.0)
        # S deviates from P/P50 by P/P50 ~ 1e-6 relative
        assert e == pytest.approx(linear_facilitation_factor(k, D, D_HB), rel=1e-5)
    assert hill_factor(85.0, 48.0, ALPHA, D, D_HB, 0.0, 26.8, 2.7) == pytest.approx(1, abs=1e-8)


@pytest.mark.parametrize("example", ["curved", "straight"])
def test_facilitated_closure_matches_the_2d_solution_with_hill_binding(example: str) -> None:
    """Steady mean flow of a paper example through its rigid tube, `hemoglobin: hill`, Graetz
    closure: the default facilitated wall uptake is within 2 % of the 2-D solution with Hill
    binding in the fluid (measured −1.1 % curved, −0.8 % straight: the Graetz law's curvature
    correction is taken for dissolved O2), the dissolved-only closure is 2.4–2.8× too low and
    warns."""
    c = load_case(example)
    ref, est = hill_uptake(HillBlood(), c.radius, c.length, c.flow.mean, c.p_in, c.p_wall,
                           cells=80, steps=100)
    assert est < 5e-3 * ref

    def one_d(wall: dict) -> float:
        m = {"period": 1.0, "blood": {"density": c.density, "viscosity": c.viscosity},
             "vessels": [{"name": "tube", "from": "in", "to": "out", "length": c.length,
                          "radius": c.radius, "segments": c.segments}],
             "boundary_conditions": {"in": {"type": "flow", "value": c.flow.mean},
                                     "out": {"type": "resistance", "resistance": 1e8}},
             "oxygen": {"inlet": {"po2": c.p_in}, "hemoglobin": "hill", "hill": dict(HILL),
                        "solubility": c.alpha, "diffusivity": c.diffusivity,
                        "wall": {"model": "graetz", "po2": c.p_wall, **wall}},
             "simulation": {"cycles": 30}}
        res = oxyline.simulate(m, method="generalized-alpha", output_every=0.5)
        return float(res.wall_o2_flux[-1, 0])

    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.HemoglobinFacilitationWarning)
        facilitated = one_d({})  # the default
    assert facilitated == pytest.approx(ref, rel=0.02)
    with pytest.warns(oxyline.HemoglobinFacilitationWarning, match="dissolved O2 only"):
        dissolved = one_d({"hb_facilitation": False})
    assert 2.4 < ref / dissolved < 2.9


def test_pulsatile_hill_solver_without_haemoglobin_is_the_dissolved_solver() -> None:
    """`hill_periodic` with no haemoglobin (C = αP, Φ = αDP) against the independent dissolved
    solver (`AxisymmetricSolver`: exact radial exponential, GMRES periodic state) on the
    curved example's pulsatile flow, same grid: they differ only by the time discretisation
    of the radial step (backward Euler halves vs the exact exponential; measured 4.5e-4 on
    40×48×100, so 1e-2 bounds it on this coarse grid). Mass is conserved to round-off."""
    from validation.axisymmetric import AxisymmetricSolver, ConstantPO2, Grid
    from validation.hill import hill_periodic

    c = load_case("curved")
    grid = Grid(20, 24, steps_per_period=50)
    blood = HillBlood(solubility=c.alpha, diffusivity=c.diffusivity, capacity=0.0, d_hb=0.0)
    got = hill_periodic(blood, c.tube(), c.flow, c.p_in, c.p_wall, grid, tol=1e-7)
    ref = AxisymmetricSolver(c.tube(), c.flow, ConstantPO2(c.p_wall), c.p_in, grid
                             ).periodic(tol=1e-9)
    print(f"hill_periodic {got.uptake:.6e}, dissolved {ref.uptake:.6e}, "
          f"{got.uptake / ref.uptake - 1:+.2e}, {got.periods} periods")
    assert got.uptake == pytest.approx(ref.uptake, rel=1e-2)
    assert got.mass_residual < 1e-10
