"""Prescribed wall flux varying in space and time, and the forward-flow-mean Graetz closure
(the reversal closure; docs/physics.md §3.1 C1, §3.6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import tube as tube_model

import oxyline

R, LENGTH, N = 3e-3, 0.1, 10
AREA = 2 * math.pi * R * LENGTH / N  # lumen wall area of one segment


def tube(species: list[dict] | None = None, oxygen: dict | None = None, *, n: int = N,
         flow: float | dict = 2e-6, cycles: int = 40, length: float = LENGTH,
         radius: float = R) -> dict:
    return tube_model(n, species, oxygen, radius=radius, length=length, flow=flow,
                      cycles=cycles)


def test_space_varying_flux_in_steady_plug_flow_matches_the_analytic_profile() -> None:
    """Steady plug flow Q through a rigid tube with a wall flux f(x) = f0 (1 + 2x/L):
    c(x) = c_in − (2πr/Q) ∫_0^x f = c_in − (2πr f0/Q)(x + x²/L). Per segment the flux is f at
    the segment mid-point (its exact mean for a linear f); the inverted-L cell of segment j
    holds the blood that has passed its whole wall, so its concentration is c((j + 1) L/N)
    exactly at steady state (upwind cell balance Q c_{j−1} − Q c_j = f_j A_j)."""
    q, f0, c_in = 2e-6, 2e-4, 1.0
    xm = (np.arange(N) + 0.5) * LENGTH / N
    fluxes = list(f0 * (1 + 2 * xm / LENGTH))
    sp = [{"name": "s", "inlet": {"concentration": c_in}, "initial": c_in,
           "wall": {"model": "flux", "flux": fluxes}}]
    res = oxyline.simulate(tube(sp, flow=q), method="generalized-alpha", output_every=0.5)
    x_end = (np.arange(N) + 1) * LENGTH / N
    exact = c_in - 2 * math.pi * R * f0 / q * (x_end + x_end**2 / LENGTH)
    # 28 transit times after the start the transient is below round-off
    np.testing.assert_allclose(res.segment_s_concentration[-1], exact, rtol=1e-11)
    assert exact[-1] < 0.7 * c_in  # a visible, strongly non-uniform depletion
    np.testing.assert_allclose(res.species["s"].segment("wall_flux")[-1],
                               np.asarray(fluxes) * AREA, rtol=1e-12)


@pytest.mark.parametrize("method", ["rk4", "generalized-alpha"])
def test_time_and_space_varying_flux_keeps_the_mass_balance_exact(method: str) -> None:
    """A Python callable f(t) per segment, sampled on the time grid: the integrated wall flux
    equals inflow − outflow − storage change to 1e-9 of the throughput, and equals the
    prescribed ∫ Σ f_j A_j dt (independent: the sine integrates to zero over whole periods)."""
    f0 = 1e-6
    weights = np.linspace(0.5, 1.5, N)

    def flux(t: float) -> np.ndarray:
        return f0 * weights * (1.0 + 0.8 * math.sin(2 * math.pi * t))

    sp = [{"name": "s", "inlet": {"concentration": 1.0}, "initial": 1.0,
           "wall": {"model": "flux", "flux": flux}}]
    flow = {"fourier": {"period": 1.0, "mean": 2e-6, "sin": [3e-6]}}  # reversing
    # a fixed step (the grid the callable is sampled on; the default run's error control
    # would integrate the table's kinks to its rtol only)
    fixed = {"dt": 0.01} if method == "generalized-alpha" else {}
    res = oxyline.simulate(tube(sp, flow=flow, cycles=4), method=method, output_cycles="all",
                           output_every=0.01, **fixed)
    mb = res.species["s"].mass_balance
    throughput = max(abs(mb["inflow"]).max(), abs(mb["outflow"]).max())
    assert np.abs(mb["residual"]).max() <= 1e-9 * throughput
    # ∫_0^4 Σ f_j A_j dt = 4 f0 Σ w_j A (the sampled sine is piecewise linear on a grid
    # aligned with the period: its integral over whole periods is zero up to the
    # integrator's quadrature of the table's kinks, O(dt²) per kink)
    expected = 4.0 * f0 * weights.sum() * AREA
    assert mb["wall_uptake"][-1] == pytest.approx(expected, rel=1e-6)
    # the recorded wall flux follows f(t): linear interpolation of 200 samples per period
    # is within (2π/200)²/8 ≈ 1.2e-4 of the sine's amplitude
    t = res.time
    prescribed = f0 * weights.sum() * AREA * (1.0 + 0.8 * np.sin(2 * math.pi * t))
    assert np.abs(res.species["s"].wall_flux[:, 0] - prescribed).max() < (
        2e-4 * f0 * weights.sum() * AREA)


def test_flux_table_repeats_and_is_uniform_with_one_value_per_row() -> None:
    sp = [{"name": "s", "inlet": {"concentration": 1.0}, "initial": 1.0,
           "wall": {"model": "flux", "flux": {"time": [0.0, 0.5, 1.0],
                                              "flux": [1e-6, 3e-6, 1e-6]}}}]
    res = oxyline.simulate(tube(sp, cycles=3), method="generalized-alpha", output_every=0.25,
                           output_cycles="all")
    w = res.species["s"].wall_flux[:, 0] / (N * AREA)
    expected = {0.0: 1e-6, 0.25: 2e-6, 0.5: 3e-6, 0.75: 2e-6}
    for t, v in zip(res.time, w, strict=True):
        assert v == pytest.approx(expected[round(t % 1.0, 9)], rel=1e-12)


def test_bad_flux_input_names_the_vessel() -> None:
    sp = [{"name": "s", "inlet": {"concentration": 1.0},
           "wall": {"model": "flux", "flux": [1e-6, 2e-6, 3e-6]}}]
    with pytest.raises(oxyline.ModelError, match="vessel 'tube'.*3 values.*10 segments"):
        oxyline.simulate(tube(sp, cycles=1))
    sp[0]["wall"]["flux"] = {"time": [0.0, 0.0], "flux": [1e-6, 1e-6]}
    with pytest.raises(oxyline.ModelError, match="strictly increasing"):
        oxyline.load_model(tube(sp, cycles=1))
    sp[0]["wall"]["flux"] = [1e-6, float("nan")]
    with pytest.raises(oxyline.ModelError, match="flux"):
        oxyline.load_model(tube(sp, cycles=1))


def _graetz_theta(x_star: float) -> float:
    """Mixed-cup θ_m(x*) from the 2-D reference's exact x-marching (an independent Graetz
    solution), Richardson-extrapolated from 400/800 radial cells (error < 1e-7)."""
    from validation.axisymmetric import ConstantPO2, Grid, Tube, richardson, steady_march

    tube_ = Tube(radius=R, length=LENGTH)
    runs = [steady_march(tube_, ConstantPO2(0.0), np.array([x_star]), Grid(radial=n))
            for n in (400, 800)]
    return float(richardson(runs[0].theta, runs[1].theta)[0])


@pytest.mark.parametrize("flow_kind", ["forward-mean", "cycle-mean"])
def test_graetz_closure_reads_the_forward_flow_mean(flow_kind: str) -> None:
    """A rigid tube carries Q(t) = m + a sin(2πt) (a > m: reversal) everywhere. The Graetz
    closure with `flow: forward-mean` uses ⟨max(Q, 0)⟩ = (⟨|Q|⟩ + m)/2, with ⟨|Q|⟩ =
    (2/π)(sqrt(a² − m²) + m asin(m/a)); `cycle-mean` uses ⟨|Q|⟩. The segment conductances
    telescope: Σ G_j = Q̄ (−ln θ_m(x*_L)), x*_L = πDL/(4Q̄). With a tiny enhancement the PO2
    stays at the inlet value (to ~1e-6), so the wall uptake is ε Σ G_j α (P_in − P_w)."""
    m_, a, d, eps, alpha = 2e-6, 5e-6, 1.2e-9, 1e-3, 1.4e-3
    mean_abs = 2 / math.pi * (math.sqrt(a * a - m_ * m_) + m_ * math.asin(m_ / a))
    q_bar = (mean_abs + m_) / 2 if flow_kind == "forward-mean" else mean_abs
    oxygen = {"inlet": {"po2": 85.0}, "diffusivity": d, "solubility": alpha,
              "wall": {"model": "graetz", "po2": 60.0, "enhancement": eps, "flow": flow_kind}}
    flow = {"fourier": {"period": 1.0, "mean": m_, "sin": [a]}}
    res = oxyline.simulate(tube(oxygen=oxygen, flow=flow, cycles=2),
                           method="generalized-alpha", dt=2e-4, output_every=0.1)
    g_sum = q_bar * -math.log(_graetz_theta(math.pi * d * LENGTH / (4 * q_bar)))
    expected = eps * g_sum * alpha * (85.0 - 60.0)
    # tolerance: mean flow by the rectangle rule at dt = 2e-4 (~1e-6), θ_m to 1e-7, the
    # PO2 drop below the inlet value (~1e-6 relative)
    np.testing.assert_allclose(res.wall_o2_flux[:, 0], expected, rtol=2e-5)
