"""Coronary oxygen: `paper-curved-coronary`, the paper's coronary vessel fed
by aortic pressure and draining into a coronary bed under intramyocardial pressure
(docs/physics.md §1.7, docs/oxygen.md "Coronary oxygen"). Checked against the closed-form
periodic solution of the linear circuit and the O2 mass balance, not against the code's own
numbers."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

import oxyline
from oxyline import catalogue
from oxyline.plot_oxygen import without_intramyocardial_pressure

SYSTOLE = 0.35  # s, the systolic window of the example's P_lv(t) (its file's comments)


def _harmonic(f: dict, k: int) -> complex:
    """Complex amplitude X_k of a `fourier` waveform x(t) = Re Σ X_k e^{ikωt}."""
    if k == 0:
        return f["mean"]
    c = f["cos"][k - 1] if k - 1 < len(f["cos"]) else 0.0
    s = f["sin"][k - 1] if k - 1 < len(f["sin"]) else 0.0
    return c - 1j * s


def periodic_inflow(src: dict, t: np.ndarray, with_pim: bool = True) -> np.ndarray:
    """Closed-form periodic inflow of the example, harmonic by harmonic (phasors): the coronary
    bed (docs/physics.md §1.7: C_im between its node and the source P_im, R_v to P_v = 0) is
    reduced to a Thévenin source E and impedance Z, then the vessel's inverted-L segments
    (§1.1 R, L, C; §1.2 capacitor at each segment's proximal node, the first one on the
    pressure-fed inlet) are added from the outlet back to the inlet: Q = (P_ao - E)/Z."""
    v, bc = src["vessels"][0], src["boundary_conditions"]
    out, n = bc["outlet"], v["segments"]
    mu, rho, dx, r = src["blood"]["viscosity"], src["blood"]["density"], v["length"] / n, v["radius"]
    R, L = 8 * mu * dx / (math.pi * r**4), rho * dx / (math.pi * r**2)
    C = 2 * math.pi * r**3 * (1 - v["poisson_ratio"]**2) * dx / (v["youngs_modulus"]
                                                               * v["wall_thickness"])
    fa, fi = bc["inlet"]["fourier"], out["intramyocardial_pressure"]["fourier"]
    w0 = 2 * math.pi / fa["period"]
    q = np.zeros_like(t)
    for k in range(max(len(fa["cos"]), len(fi["cos"])) + 1):
        jw = 1j * k * w0
        pim = _harmonic(fi, k) if with_pim else 0.0
        y = jw * out["intramyocardial_capacitance"] + 1 / out["venous_resistance"]
        z, e = 1 / y + out["microvascular_resistance"], jw * out["intramyocardial_capacitance"] * pim / y
        d = 1 + jw * out["arterial_capacitance"] * (z)
        z, e = z / d + out["arterial_resistance"], e / d
        for i in range(n):
            z = z + R + jw * L
            if i < n - 1:
                d = 1 + jw * C * z
                z, e = z / d, e / d
        qk = (_harmonic(fa, k) - e) / z
        q += (qk * np.exp(jw * t)).real
    return q


@pytest.fixture(scope="module")
def runs() -> dict:
    m = catalogue.load("paper-curved-coronary")
    rigid = oxyline.load_model(without_intramyocardial_pressure(m))
    return {"src": m.source,
            "rk4": oxyline.simulate(m, method="rk4", transport=False),
            "rk4_rigid": oxyline.simulate(rigid, method="rk4", transport=False),
            "o2": oxyline.simulate(m), "o2_rigid": oxyline.simulate(rigid)}


def test_inflow_is_the_closed_form_periodic_solution(runs: dict) -> None:
    """RK4 (Δt = 1/3 ms, fourth order) after 8 cycles (slowest time constant R_v C_im
    = 0.12 s): the closed form to 1e-6 of the flow swing (measured 7.5e-8); generalized-α
    (1 ms, second order) to 2e-4 (measured 4e-5)."""
    for key, on in (("rk4", True), ("rk4_rigid", False), ("o2", True), ("o2_rigid", False)):
        res = runs[key]
        t, q = np.asarray(res.time), np.asarray(res.vessel("coronary").flow_in)
        qa = periodic_inflow(runs["src"], t, on)
        tol = 1e-6 if key.startswith("rk4") else 2e-4
        assert np.max(np.abs(q - qa)) <= tol * np.ptp(qa), key


def test_systolic_impediment_is_the_intramyocardial_pressure_driven_amount(runs: dict) -> None:
    """P_im lowers the systolic inflow; by linearity the deficit is the response to P_im alone
    (closed form), and the cycle mean is unchanged (the capacitors carry no mean current:
    Q̄ = P̄_ao / (R_vessel + R_a + R_am + R_v))."""
    t = np.asarray(runs["rk4"].time)
    sys = np.mod(t, 1.0) < SYSTOLE
    q = np.asarray(runs["rk4"].vessel("coronary").flow_in)
    q0 = np.asarray(runs["rk4_rigid"].vessel("coronary").flow_in)
    deficit = q0[sys].mean() - q[sys].mean()
    closed = (periodic_inflow(runs["src"], t[sys], False)
              - periodic_inflow(runs["src"], t[sys], True)).mean()
    assert deficit > 0.05 * q0[sys].mean()  # a visible impediment (measured 7 %)
    assert deficit == pytest.approx(closed, rel=1e-5)
    src = runs["src"]
    out, v = src["boundary_conditions"]["outlet"], src["vessels"][0]
    r_total = (8 * src["blood"]["viscosity"] * v["length"] / (math.pi * v["radius"]**4)
               + out["arterial_resistance"] + out["microvascular_resistance"]
               + out["venous_resistance"])
    q_mean = src["boundary_conditions"]["inlet"]["fourier"]["mean"] / r_total
    for qq in (q, q0):  # trapezoidal cycle mean of the last cycle (spectrally exact here)
        assert np.trapezoid(qq, t) / (t[-1] - t[0]) == pytest.approx(q_mean, rel=1e-7)


def test_cycle_mean_wall_uptake_is_the_o2_mass_balance(runs: dict) -> None:
    """At periodic steady state the stored O2 returns to its value, so the cycle-integrated
    wall uptake equals the convective inflow minus outflow, both integrated from the recorded
    fluxes (trapezoid on the 1 ms output of smooth periodic signals: measured 4e-10 of the
    uptake; tolerance 1e-6)."""
    for key in ("o2", "o2_rigid"):
        res = runs[key]
        t = np.asarray(res.time)
        j_in, j_out = res.o2_flux_in[:, 0], res.o2_flux_out[:, 0]
        uptake = np.trapezoid(res.wall_o2_flux[:, 0], t)
        assert uptake > 0
        assert np.trapezoid(j_in - j_out, t) == pytest.approx(uptake, rel=1e-6)


def test_impediment_figure_shows_both_cases(runs: dict) -> None:
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from oxyline import plot_oxygen

    fig = plot_oxygen.coronary_impediment(runs["o2"], runs["o2_rigid"], systole=SYSTOLE)
    a1, a2 = fig.axes[:2]
    assert len(a1.get_lines()) >= 2 and len(a2.get_lines()) >= 2
    assert np.allclose(a2.get_lines()[0].get_ydata(), runs["o2"].wall_o2_flux[:, 0] * 1e9)
    plt.close(fig)


def test_rigid_variant_drops_only_the_intramyocardial_pressure() -> None:
    m = catalogue.load("paper-curved-coronary")
    s = without_intramyocardial_pressure(m)
    ref = copy.deepcopy(m.source)
    ref["boundary_conditions"]["outlet"]["intramyocardial_pressure"] = 0.0
    assert s == ref
