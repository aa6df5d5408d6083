"""Pulse-pressure amplification and the augmentation index as outputs
(``amplification.<central>.<peripheral>``, ``augmentation_index.<vessel>``): their Jacobians
against central differences of whole periodic runs, the adjoint's against the forward
tangent's, a closed form of each on a reflecting tube, and bad input named.

The model: an aorta-like tube into a narrower, stiffer one closed by a resistance three times
its characteristic impedance; the wave reflected there returns to the inlet ~0.17 s after the
foot, before the inflow's peak, so the inlet pressure has a shoulder on its upstroke (an
augmentation index > 0), and the pulse grows towards the narrower end (amplification > 1).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import oxyline
from oxyline import CalibrationError, ModelError
from oxyline.calibrate import _base_value, native_model

pytest.importorskip("scipy")

RHO = 1060.0
PERIOD = 0.8


def _inflow() -> dict:
    """A half-sine ejection over 0.3 s (10 harmonics), 1e-4 m³/s at its peak."""
    t = np.linspace(0, PERIOD, 2000, endpoint=False)
    q = np.where(t < 0.3, np.sin(np.pi * t / 0.3), 0.0) * 1e-4
    k = np.arange(1, 11)[:, None]
    return {"period": PERIOD, "mean": float(q.mean()),
            "cos": (2 * np.mean(q * np.cos(2 * np.pi * k * t), axis=1)).tolist(),
            "sin": (2 * np.mean(q * np.sin(2 * np.pi * k * t), axis=1)).tolist()}


def _model() -> dict:
    wall = {"wall_thickness": 0.0008, "youngs_modulus": 4e5}
    r_b, h_b, e_b = 0.004, 0.0006, 8e5
    c_b = np.sqrt(2 * e_b * h_b / (3 * RHO * r_b))
    return {
        "name": "tube", "units": "SI", "period": PERIOD,
        "vessels": [
            {"name": "a", "from": "in", "to": "m", "segments": 30, "length": 0.3,
             "radius": 0.006, **wall},
            {"name": "b", "from": "m", "to": "out", "segments": 20, "length": 0.2,
             "radius": r_b, "wall_thickness": h_b, "youngs_modulus": e_b}],
        "boundary_conditions": {
            "in": {"type": "flow", "fourier": _inflow()},
            "out": {"type": "resistance",
                    "resistance": float(3 * RHO * c_b / (np.pi * r_b * r_b))}},
        "simulation": {"dt": 0.001, "method": "generalized-alpha"},
    }


MODEL = _model()
PARAMETERS = ["vessels.a.length", "vessels.a.youngs_modulus", "vessels.b.radius",
              "boundary_conditions.out.resistance", "scale.inflow"]
OUTPUTS = ["augmentation_index.a", "amplification.a.b"]


def _base(path: str) -> float:
    return 1.0 if path.startswith("scale.") else _base_value(MODEL, path)


def test_the_wave_shape_outputs_are_those_of_the_run() -> None:
    """Closed forms on the run's own pressures: the amplification is the ratio of the two
    pulses; the augmentation index (P_sys − P_i)/PP with the shoulder where the inlet's
    pressure slope has its first local minimum after the foot (NumPy's differences)."""
    s = oxyline.sensitivities(MODEL, [], OUTPUTS + ["a.pressure_in.pulse",
                                                    "b.pressure_out.pulse"])
    aix, amp, pp_a, pp_b = s.values
    assert amp == pytest.approx(pp_b / pp_a, rel=1e-12)
    assert amp > 1.05
    res = oxyline.simulate(MODEL, cycles=40)
    p = np.asarray(res.vessel("a").pressure_in)[-800:]
    lo = int(np.argmin(p))
    p = np.roll(p, -lo)                     # the cycle from its minimum
    hi = int(np.argmax(p))
    slope = np.diff(p[:hi + 1])
    k = next(i for i in range(1, len(slope) - 1)
             if slope[i] < slope[i - 1] and slope[i] <= slope[i + 1])
    # the shoulder is between samples k and k + 1; the index from its two sample pressures
    # brackets the core's (interpolated between them)
    bounds = sorted((p[hi] - p[j]) / (p[hi] - p[0]) for j in (k, k + 1))
    assert 0.0 < aix
    assert bounds[0] - 1e-9 <= aix <= bounds[1] + 1e-9, (aix, bounds)


def test_the_wave_shape_jacobian_matches_central_differences() -> None:
    # relative step 3e-5: truncation O(h²) (3.5e-7 of the largest response at a step of 1e-4,
    # 3e-8 at 3e-5: the shape outputs curve more than the statistics), rounding ~1e-16/h
    # ~3e-12; the samples of the peak, minimum and shoulder stay the same under it, so 1e-6
    # of the output's largest response tells a wrong derivative
    exact = oxyline.sensitivities(MODEL, PARAMETERS, OUTPUTS)
    h = 3e-5
    scale = np.abs(exact.jacobian * exact.parameter_values).max(axis=1)
    for k, path in enumerate(PARAMETERS):
        x0 = _base(path)
        up, down = (oxyline.sensitivities(native_model(MODEL, [path], [x0 * f]), [], OUTPUTS)
                    for f in (1 + h, 1 - h))
        fd = (up.values - down.values) / (2 * h * x0)
        err = np.abs(exact.jacobian[:, k] - fd) * x0
        assert (err <= 1e-6 * scale).all(), (path, err / scale)
    # a wave scaled by the inflow keeps its shape (a linear line): both derivatives ~0
    inflow = PARAMETERS.index("scale.inflow")
    assert (np.abs(exact.jacobian[:, inflow]) <= 1e-6 * scale).all()


def test_the_adjoint_wave_shape_jacobian_is_the_forward_one() -> None:
    """As for the other outputs (tests/test_calibrate.py): the two differ by their fixed
    points' tolerance (1e-12) and rounding."""
    fwd = oxyline.sensitivities(MODEL, PARAMETERS, OUTPUTS)
    adj = oxyline.sensitivities(MODEL, PARAMETERS, OUTPUTS, mode="adjoint")
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-12)
    scale = np.abs(fwd.jacobian * fwd.parameter_values).max(axis=1)
    err = np.abs(adj.jacobian - fwd.jacobian) * np.abs(fwd.parameter_values)
    assert (err <= 1e-8 * scale[:, None]).all(), err / scale[:, None]


def test_bad_wave_shape_outputs_name_the_output() -> None:
    with pytest.raises(ModelError, match="amplification.a.zz.*no vessel named 'zz'"):
        oxyline.sensitivities(MODEL, [], ["amplification.a.zz"])
    with pytest.raises(ModelError, match="expected augmentation_index.<vessel>"):
        oxyline.sensitivities(MODEL, [], ["augmentation_index.a.b"])
    with pytest.raises(CalibrationError, match="expected amplification.<central"):
        oxyline.calibrate(MODEL, {"amplification.a": 1.2}, ["scale.inflow"])
    # a reflection-free tube: the inlet pressure is the inflow's half sine, whose slope has
    # no local minimum before its peak
    free = copy.deepcopy(MODEL)
    r, h, e = 0.006, 0.0008, 4e5
    c = np.sqrt(2 * e * h / (3 * RHO * r))
    free["vessels"] = free["vessels"][:1]
    free["vessels"][0]["to"] = "out"
    free["boundary_conditions"]["out"]["resistance"] = float(RHO * c / (np.pi * r * r))
    with pytest.raises(ModelError, match="augmentation_index.a.*no inflection"):
        oxyline.sensitivities(free, [], ["augmentation_index.a"])
