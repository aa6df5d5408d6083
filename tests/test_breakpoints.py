"""Breakpoints of the error-controlled step (docs/physics.md §10, "Breakpoints"): a linear
table's corners (its slope's jumps) end a step, checked against the closed-form periodic
response of an RC line under a piecewise-linear inflow."""

from __future__ import annotations

import numpy as np
import pytest

import oxyline

T = 1.0
R, R_OUT, C = 1e6, 1e8, 1.6e-9  # R into C || R_out: time constant R_out C = 0.16 s
#: a ramp up to a corner at 0.3 s, down to a second corner at 0.55 s, back to the start (a
#: third corner, on the cycle's end)
TIMES = [0.0, 0.3, 0.55, 1.0]
FLOWS = [2e-6, 9e-6, 3.4e-6, 2e-6]
CORNERS = (0.3, 0.55)


def model() -> dict:
    return {"name": "rc-corners", "arrangement": "L", "period": T,
            "vessels": [{"name": "v", "from": "in", "to": "out",
                         "lumped": {"resistance": R, "capacitance": C}}],
            "boundary_conditions": {
                "in": {"type": "flow", "time": TIMES, "flow": FLOWS},
                "out": {"type": "resistance", "resistance": R_OUT}}}


def exact(t: np.ndarray) -> dict[str, np.ndarray]:
    """The periodic response: C P' = Q(t) − P/R_out with Q linear on each piece, solved piece
    by piece (P = R_out (Q − τ Q') + (P_k − R_out (Q_k − τ Q'))·e^(−(t − t_k)/τ), τ = R_out C),
    its start P(0) the fixed point of one period."""
    tau = R_OUT * C
    pieces = list(zip(TIMES[:-1], TIMES[1:], FLOWS[:-1], FLOWS[1:], strict=True))

    def across(p0: float, t0: float, t1: float, q0: float, q1: float, at: np.ndarray
               ) -> np.ndarray:
        s = (q1 - q0) / (t1 - t0)
        q = q0 + s * (at - t0)
        return R_OUT * (q - tau * s) + (p0 - R_OUT * (q0 - tau * s)) * np.exp(-(at - t0) / tau)

    def period_map(p0: float) -> float:
        for t0, t1, q0, q1 in pieces:
            p0 = float(across(p0, t0, t1, q0, q1, np.array(t1)))
        return p0

    # P(T) = a P(0) + b: the map is affine
    b = period_map(0.0)
    a = period_map(1.0) - b
    p = b / (1.0 - a)
    tc = np.mod(t, T)
    pc, q = np.empty_like(tc), np.interp(tc, TIMES, FLOWS)
    for t0, t1, q0, q1 in pieces:
        sel = (tc >= t0) & (tc <= t1)
        pc[sel] = across(p, t0, t1, q0, q1, tc[sel])
        p = float(across(p, t0, t1, q0, q1, np.array(t1)))
    return {"flow_in": q, "pressure_out": pc, "pressure_in": pc + R * q}


def test_the_closed_form_is_periodic_and_solves_the_line() -> None:
    # the reference itself: P(0) = P(T), and C P' = Q − P/R_out by central differences
    t = np.linspace(0.01, 0.99, 50)
    e = exact(t)
    h = 1e-6
    dp = (exact(t + h)["pressure_out"] - exact(t - h)["pressure_out"]) / (2 * h)
    assert np.allclose(C * dp, e["flow_in"] - e["pressure_out"] / R_OUT, rtol=1e-5, atol=1e-12)
    ends = exact(np.array([0.0, T - 1e-12]))["pressure_out"]
    assert abs(ends[0] - ends[1]) < 1e-6 * ends[0]


@pytest.mark.parametrize("rtol", [1e-3, 1e-4, 1e-5])
def test_a_step_ends_on_each_corner_of_the_inflow_and_the_error_meets_rtol(rtol: float) -> None:
    res = oxyline.simulate(model(), rtol=rtol, cycles=3, start="periodic", output_every=1e-3,
                           method="generalized-alpha")
    # the last cycle's steps: one starts on each corner (none steps over it)
    starts = np.asarray(res.step_times)
    for corner in CORNERS:
        assert np.min(np.abs(starts - corner)) < 1e-9 * T, (rtol, corner)
    want = exact(res.time)
    v = res.vessel("v")
    for key, e in want.items():
        err = np.max(np.abs(getattr(v, key) - e)) / np.max(np.abs(e))
        assert err <= 2 * rtol, (rtol, key, err / rtol)
