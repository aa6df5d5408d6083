"""Coronary outlets (issue 14): svZeroDSolver's ``CORONARY`` and ``CORONARY_VAR_RES`` through the
drop-in, against the peer's stored references (generalized-alpha), fresh peer runs 20x finer
(RK4) and the analytical steady solution; the native ``coronary`` condition against a closed-form
periodic solution. The case classification lives in tests/test_svzerod.py (``HEART``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_svzerod import (
    COLS,
    HEART,
    RK4_REFINE,
    assert_same_layout,
    case,
    config,
    reference,
    scaled_errors,
    svzerod_run,
)

import oxyline
from oxyline import svzerod as svz

# the three supported coronary cases (their stored reference results are kept gzipped in
# tests/data/svzerod/cases/results)
CORONARY = HEART


@pytest.mark.parametrize("name", CORONARY)
def test_generalized_alpha_matches_reference(name: str) -> None:
    """svZeroDSolver's discretisation: the bed's equations with its eliminated flows restored
    are the same generalized-alpha equations, so only round-off and the references' 10
    decimals separate them (measured <= 1e-10); 1e-6 as for the other peer cases."""
    actual = svz.simulate(case(name))
    expected = reference(name)
    assert_same_layout(actual, expected)
    errors = scaled_errors(actual, expected)
    assert max(errors.values()) <= 1e-6, errors


@pytest.mark.parametrize("name", CORONARY)
def test_rk4_matches_svzerod(name: str) -> None:
    """RK4 (sub-stepped at half its stability limit, which for the varying resistance is the
    sampled instantaneous one with its margin) against the peer 20x finer: within 1e-4 of each
    column's range, as for the other peer cases."""
    cfg = config(name)
    expected = svzerod_run(cfg, RK4_REFINE)
    actual = svz.simulate(cfg, method="rk4")
    assert_same_layout(actual, expected)
    for c in COLS:
        a, e = actual[c].to_numpy(), expected[c].to_numpy()
        scale = np.ptp(e) if np.ptp(e) > 1e-9 * np.max(np.abs(e)) else np.max(np.abs(e))
        err = np.max(np.abs(a - e)) / max(scale, 1e-12)
        assert err <= 1e-4, (c, err)


@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
def test_steady_coronary_analytical_solution(method: str) -> None:
    """The case's description: P_out = Q (Ra1 + Ra2 + Rv1) + P_v = 1500, P_in = 2000, Q = 5
    (the capacitors are charged: the steady start is already the solution)."""
    df = svz.simulate(case("steadyFlow_R_coronary"), method=method)
    for col, value in (("flow_in", 5.0), ("flow_out", 5.0), ("pressure_in", 2000.0),
                       ("pressure_out", 1500.0)):
        np.testing.assert_allclose(df[col], value, rtol=1e-9)


def test_varying_resistance_differs_from_constant_and_is_periodic() -> None:
    """The contraction law acts: the varres result is not the constant-resistance one, and it
    is periodic after the first cycle (the law is evaluated on the time within the cycle)."""
    a = svz.simulate(case("pulsatileFlow_R_coronary_varres"))
    b = svz.simulate(case("pulsatileFlow_R_coronary"))
    assert np.max(np.abs(a["pressure_in"] - b["pressure_in"])) > 100.0
    p = a["pressure_in"].to_numpy()
    np.testing.assert_allclose(p[-201:], p[-401:-200], rtol=0, atol=1e-6 * np.max(p))


# ------------------------------------------------------------------------------------------
# the native `coronary` condition


def _native(pim: dict, method: str, cycles: int = 6) -> dict:
    """A rigid pressure-fed vessel (P0 at the inlet) into a coronary bed without arterial
    capacitance (SI)."""
    return {
        "units": "SI",
        "vessels": [{"name": "lad", "from": "in", "to": "out", "arrangement": "RCL",
                     "lumped": {"resistance": 1e8}}],
        "boundary_conditions": {
            "in": {"type": "pressure", "pressure": 1.2e4},
            "out": {"type": "coronary", "arterial_resistance": 2e9,
                    "arterial_capacitance": 0.0, "microvascular_resistance": 3e9,
                    "intramyocardial_capacitance": 2e-10, "venous_resistance": 1e9,
                    "intramyocardial_pressure": pim, "pressure": 500.0},
        },
        "simulation": {"cycles": cycles, "dt": 1e-3, "method": method},
    }


@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
def test_native_coronary_matches_closed_form_periodic_solution(method: str) -> None:
    """P_im(t) = A sin(wt). With C_a = 0 the bed is one capacitor C behind R1 = R + Ra + Ram
    from P0, and Rv to P_v; its transmural pressure u = P_c - P_im obeys
    C u' = (P0 - u - P_im)/R1 - (u + P_im - P_v)/Rv, so u = u0 - k A (k sin wt - w cos wt) /
    (k^2 + w^2) with k = (1/R1 + 1/Rv)/C, and the inflow is (P0 - u - P_im)/R1. After the
    start transient (time constant 1/k = 0.15 s, 6 cycles of 1 s: e^-40) the run's last cycle
    is that periodic solution to the integrators' discretisation error: second order for
    generalized-alpha (1 ms steps, w dt = 6e-3: ~1e-5 relative), fourth for RK4."""
    A, T = 2000.0, 1.0
    w = 2 * math.pi / T
    pim = {"fourier": {"period": T, "mean": 0.0, "sin": [A]}}
    res = oxyline.simulate(oxyline.load_model(_native(pim, method)))
    t = np.asarray(res.time)
    flow_in = np.asarray(res.vessel("lad").flow_in)
    R1, Rv, C, P0, Pv = 1e8 + 2e9 + 3e9, 1e9, 2e-10, 1.2e4, 500.0
    k = (1 / R1 + 1 / Rv) / C
    u0 = (P0 / R1 + Pv / Rv) / (k * C)
    tau = np.mod(t, T)
    u = u0 - k * A * (k * np.sin(w * tau) - w * np.cos(w * tau)) / (k * k + w * w)
    q = (P0 - u - A * np.sin(w * tau)) / R1
    tol = 1e-4 if method == "generalized-alpha" else 1e-7
    np.testing.assert_allclose(flow_in, q, rtol=0, atol=tol * np.ptp(q))


def test_native_coronary_bad_values_name_the_condition() -> None:
    m = _native({"value": 0.0}, "rk4")
    m["boundary_conditions"]["out"]["venous_resistance"] = -1.0
    with pytest.raises(oxyline.ModelError, match="boundary condition 'out'.*venous_resistance"):
        oxyline.simulate(oxyline.load_model(m))
    m = _native({"value": 0.0}, "rk4")
    m["boundary_conditions"]["out"]["microvascular_resistance_max"] = 5e9
    with pytest.raises(oxyline.ModelError, match="contraction_time"):
        oxyline.simulate(oxyline.load_model(m))
