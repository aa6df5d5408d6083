"""Kelvin–Voigt walls (``wall_viscosity``) against closed forms.

A wall σ = E ε + η dε/dt puts a resistance R_v = τ/C, τ = η/E, in series with each segment's
compliance C, so the shunt admittance of a segment is iωC/(1 + iωτ). Truths computed here:

* one segment (inverted-L: C at the inlet node, then R + iωL to a zero pressure): the input
  impedance 1/(iωC/(1 + iωτ) + 1/(R + iωL)), exactly;
* a uniform viscoelastic line closed by a resistance: the transmission-line input impedance with
  the per-length admittance iωC'/(1 + iωτ), approached at second order by π segments;
* the periodic state of both integrators under an oscillating inflow against Z(ω);
* oxygen transport: a uniform inlet PO2 stays uniform in a pulsating viscoelastic vessel (the
  lumen volume follows the wall, not the lumen pressure) and the O2 balance closes to 1e-12.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from conftest import first_harmonic

import oxyline

RHO, MU = 1050.0, 3.5e-3
R, H, E, LENGTH = 3e-3, 5e-4, 4e5, 0.1


def vessel(segments: int, eta: float, **extra: object) -> dict:
    return {"name": "v", "from": "in", "to": "out", "length": LENGTH, "radius": R,
            "wall_thickness": H, "youngs_modulus": E, "wall_viscosity": eta,
            "segments": segments, **extra}


def model(segments: int, eta: float, outlet: dict, arrangement: str = "inverted-L",
          friction: str = "poiseuille") -> dict:
    return {"name": "ve", "period": 1.0, "arrangement": arrangement, "wall_friction": friction,
            "vessels": [vessel(segments, eta)],
            "boundary_conditions": {"in": {"type": "flow", "value": 1e-6}, "out": outlet}}


def per_length() -> tuple[float, float, float]:
    """R', L', C' of docs/physics.md §1.1 (ν = 0.5)."""
    return (8 * MU / (math.pi * R**4), RHO / (math.pi * R**2),
            2 * math.pi * R**3 * 0.75 / (E * H))


@pytest.mark.parametrize("eta", [0.0, 2e3, 2e4])
def test_one_segment_is_the_closed_form(eta: float) -> None:
    f = np.array([0.5, 2.0, 5.0, 10.0, 20.0])
    z = oxyline.impedance(model(1, eta, {"type": "pressure", "value": 0.0}), "in", f)
    rp, lp, cp = per_length()
    tau = eta / E
    w = 2 * math.pi * f
    exact = 1.0 / (1j * w * cp * LENGTH / (1 + 1j * w * tau)
                   + 1.0 / ((rp + 1j * w * lp) * LENGTH))
    # one sparse solve of four unknowns against a closed form: rounding only
    np.testing.assert_allclose(z, exact, rtol=1e-10)


def line(omega: float, tau: float, z_load: float) -> complex:
    rp, lp, cp = per_length()
    z = rp + 1j * omega * lp
    y = 1j * omega * cp / (1 + 1j * omega * tau)
    gamma, zc = cmath.sqrt(z * y), cmath.sqrt(z / y)
    t = cmath.tanh(gamma * LENGTH)
    return zc * (z_load + zc * t) / (zc + z_load * t)


def test_viscoelastic_line_converges_to_its_closed_form() -> None:
    eta, r_out = 1e4, 1e8
    f = np.array([1.0, 5.0, 10.0, 20.0])
    exact = np.array([line(2 * math.pi * fi, eta / E, r_out) for fi in f])
    errors = []
    for n in (16, 32):
        m = model(n, eta, {"type": "resistance", "resistance": r_out}, arrangement="pi")
        z = oxyline.impedance(m, "in", f)
        errors.append(np.max(np.abs(z / exact - 1.0)))
    # π segments are second order (docs/physics.md §6 F3): halving dx quarters the error
    assert errors[1] < 2e-3, errors
    assert 3.5 < errors[0] / errors[1] < 4.5, errors
    elastic = np.array([line(2 * math.pi * fi, 0.0, r_out) for fi in f])
    assert np.max(np.abs(elastic / exact - 1.0)) > 10 * errors[1]  # the wall viscosity shows


@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
@pytest.mark.parametrize("friction", ["poiseuille", "womersley"])
def test_periodic_state_agrees_with_the_impedance(method: str, friction: str) -> None:
    """Q = Q0 + Q1 sin(ωt) into a viscoelastic vessel: the inlet pressure's first harmonic is
    Z(ω)·(−i Q1) and its mean Z(0)·Q0."""
    period, q0, q1 = 0.2, 2e-6, 1e-6
    data = model(4, 1e4, {"type": "resistance", "resistance": 1e8}, arrangement="pi",
                 friction=friction)
    data["period"] = period
    data["boundary_conditions"]["in"] = {
        "type": "flow", "fourier": {"period": period, "mean": q0, "cos": [], "sin": [q1]}}
    m = oxyline.load_model(data)
    steps = 1000
    res = oxyline.simulate(m, cycles=12, dt=period / steps, method=method,
                           output_every=period / steps)
    p, harmonic = first_harmonic(res.vessel("v"), "pressure_in", period, steps)
    zw, z0 = oxyline.impedance(m, "in", [1.0 / period, 0.0])
    # second order in dt at 1000 steps per period (~1e-5), after 11 periods of decay of the
    # start (the vessel-outlet RC time 1e8 · C ≈ 0.03 s)
    assert abs(harmonic / (-1j * q1 * zw) - 1.0) < 1e-3, harmonic / (-1j * q1 * zw)
    assert abs(p.mean() / (q0 * z0.real) - 1.0) < 1e-6


@pytest.mark.parametrize(("friction", "eta"),
                         [("poiseuille", 2e4), ("womersley", 2e4), ("womersley", 0.0)])
def test_oxygen_stays_uniform_and_balanced_in_a_pulsating_viscoelastic_vessel(
        friction: str, eta: float) -> None:
    """With the new unknowns (a 3 mm vessel keeps all three friction cells per segment, the
    viscous wall its elastic pressure), the transport's volumes and face flows still close
    the O2 balance and keep a uniform inlet PO2 uniform."""
    data = model(6, eta, {"type": "resistance", "resistance": 1e8}, friction=friction)
    data["boundary_conditions"]["in"] = {
        "type": "flow", "fourier": {"period": 1.0, "mean": 2e-6, "cos": [], "sin": [3e-6]}}
    data["oxygen"] = {"inlet": {"po2": 85.0}, "hemoglobin": "hill"}
    res = oxyline.simulate(data, cycles=2, method="generalized-alpha", dt=1e-3,
                           output_every=0.05)
    # the lumen volume follows the wall's elastic pressure: with the lumen pressure instead,
    # c = amount/volume would drift from 85 mmHg as the wall lags the pressure
    assert np.abs(res.segment_po2 - 85.0).max() < 1e-9
    mb = res.o2_mass_balance
    assert np.abs(mb["residual"]).max() <= 1e-12 * np.abs(mb["inflow"]).max()


def test_bad_wall_viscosity_names_the_vessel_key_and_value() -> None:
    data = model(1, -5.0, {"type": "pressure", "value": 0.0})
    with pytest.raises(oxyline.ModelError, match="vessel 'v'.*wall_viscosity.*-5"):
        oxyline.load_model(data)
    data["vessels"][0] = {"name": "v", "from": "in", "to": "out", "length": LENGTH,
                          "radius": R, "wall_viscosity": 1e3}
    with pytest.raises(oxyline.ModelError, match="vessel 'v'.*wall_viscosity needs a wall"):
        oxyline.load_model(data)
    data["vessels"][0] = vessel(1, float("nan"))
    with pytest.raises(oxyline.ModelError, match="vessel 'v'.*wall_viscosity"):
        oxyline.load_model(data)


def test_downstream_impedance_at_a_viscoelastic_junction() -> None:
    """π segments put half of each vessel's wall at the junction; the downstream view keeps
    only the daughters' halves, each still behind its own R_v: Z = 1/Σ_d (Y_d + 1/Z_d),
    Y_d = iω(C_d/2)/(1 + iωτ), Z_d = R_d + iωL_d + 1/(Y_d + 1/R_out)."""
    eta, r_out = 1e4, 2e8
    tau = eta / E
    rp, lp, cp = per_length()
    lengths = {"p": 0.05, "a": 0.1, "b": 0.07}
    ends = {"p": ("in", "j"), "a": ("j", "oa"), "b": ("j", "ob")}
    # one π section per vessel, stated: the closed form below is that single section's (the
    # default, `auto`, would cut each vessel into a ladder approaching the line instead)
    vessels = [{"name": n, "from": ends[n][0], "to": ends[n][1], "length": ln, "radius": R,
                "wall_thickness": H, "youngs_modulus": E, "wall_viscosity": eta, "segments": 1}
               for n, ln in lengths.items()]
    m = {"name": "junction", "period": 1.0, "arrangement": "pi", "vessels": vessels,
         "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                 "oa": {"type": "resistance", "resistance": r_out},
                                 "ob": {"type": "resistance", "resistance": r_out}}}
    f = np.array([1.0, 5.0, 20.0])
    z = oxyline.impedance(m, "j", f)
    w = 2 * math.pi * f
    y = 0j
    for n in ("a", "b"):
        ln = lengths[n]
        half = 1j * w * cp * ln / 2 / (1 + 1j * w * tau)
        zd = (rp + 1j * w * lp) * ln + 1.0 / (half + 1.0 / r_out)
        y = y + half + 1.0 / zd
    # a sparse solve of ~12 unknowns against the closed form: rounding only
    np.testing.assert_allclose(z, 1.0 / y, rtol=1e-9)
