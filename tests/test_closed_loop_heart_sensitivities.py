"""The closed loop's O2 outputs by the parameters of its heart model (the heart's half of the
loop: the heart run's exact flow tangent at its periodic state, read into the O2 loop's flow
table and balanced) against five-point differences of whole periodic runs (heart run and O2
run), the heart run to its periodic state, bad heart paths named, and a calibration of the
left ventricle's elastance to a cardiac output.

The native two-ventricle heart is the one checked against differences: its tanh valves are
smooth and its branch flows have no on/off gating, so no valve changes state under the
difference step (svZeroDSolver's block slides its mitral valve between states under a
relative change of 1e-6, tests/test_sensitivity_heart_loop.py)."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest

import oxyline
from oxyline import closed_loop
from oxyline.errors import ModelError, PeriodicityWarning

#: the heart's elastances and valve coefficients and a pulmonary resistance
PARAMETERS = ["vessels.lv.chamber.max_elastance", "vessels.rv.chamber.passive_elastance",
              "vessels.aortic_valve.valve.min_resistance", "vessels.lungs.lumped.resistance"]
OUTPUTS = ["SvO2", "SaO2", "PvO2", "VO2", "cardiac_output"]
#: the O2 run's periodic tolerance (the heart run's own is 1e-10)
TOL = 1e-13
#: a logarithmic step: the five-point rule's truncation error at h = 1e-2 is still 7e-5 of
#: PvO2's derivative by the elastance (its higher derivatives are large), at 1e-3 below
#: 1e-9; the heart run's periodic remainder (1e-10) over h is ~1e-7 at most
H = 1e-3


def _set() -> dict:
    """closed-loop-o2 driven by the native two-ventricle heart (125 O2 steps a cycle of 0.8 s,
    each 8 of the heart run's 1 ms steps)."""
    p = closed_loop.load("closed-loop-o2")
    p.update(heart="two-ventricle", flows="heart", dt=0.008)
    return p


def _with(p: dict, path: str, value: float) -> dict:
    q = copy.deepcopy(p)
    q.setdefault("heart_values", {})[path] = value
    return q


def _outputs(p: dict) -> np.ndarray:
    """The outputs of a whole periodic run (heart, then O2) of `p`."""
    return np.asarray(closed_loop.o2_sensitivities(p, [], OUTPUTS, tol=TOL)["values"])


def test_heart_parameters_match_five_point_differences_of_whole_periodic_runs():
    p = _set()
    s = closed_loop.o2_sensitivities(p, PARAMETERS, OUTPUTS, tol=TOL)
    assert s["heart_periodic"] and s["heart_cycles"] >= 30
    base = np.asarray(s["values"])
    np.testing.assert_allclose(base, _outputs(p), rtol=1e-12)
    x0 = np.asarray(s["parameter_values"])
    # d output / d log parameter, exact and by differences along the log of each value
    exact = np.asarray(s["jacobian"]) * x0[None, :]
    fd = np.empty_like(exact)
    for j, path in enumerate(PARAMETERS):
        f = {k: _outputs(_with(p, path, x0[j] * np.exp(k * H))) for k in (-2, -1, 1, 2)}
        fd[:, j] = (f[-2] - 8 * f[-1] + 8 * f[1] - f[2]) / (12 * H)
    # each output's row on the scale of its largest derivative (a parameter that hardly
    # moves an output has a derivative of the runs' noise size)
    scale = np.abs(fd).max(axis=1, keepdims=True)
    np.testing.assert_allclose(exact / scale, fd / scale, rtol=0, atol=1e-6)
    # not trivially zero: a stronger left ventricle ejects more, and SvO2 rises with it
    assert exact[4, 0] > 0.01 * base[4] and exact[0, 0] > 0


def test_the_heart_run_reaches_its_periodic_state_or_says_so():
    r = closed_loop.simulate_o2(_set(), tol=TOL)
    assert r.heart.periodic and r.heart.cycles >= 30 and r.heart.periodic_error < 1e-10
    short = {**_set(), "heart_max_cycles": 30}
    with pytest.warns(PeriodicityWarning, match="heart run stopped at its most cycles"):
        r = closed_loop.simulate_o2(short, tol=TOL)
    assert not r.heart.periodic and r.heart.cycles == 30 and r.heart.periodic_error > 1e-10
    with pytest.raises(ModelError, match="heart_max_cycles must be a whole number from 30"):
        closed_loop.simulate_o2({**_set(), "heart_max_cycles": 5})


def test_heart_values_are_written_into_the_heart_model():
    p = _with(_set(), "vessels.lv.chamber.max_elastance", 3.0e8)
    lv = next(v for v in closed_loop.heart_model(p)["vessels"] if v["name"] == "lv")
    assert lv["chamber"]["max_elastance"] == 3.0e8


@pytest.mark.parametrize(("path", "words"), [
    ("vessels.lv.chamber.max_elastanse", ["max_elastanse", "nearest", "max_elastance"]),
    ("vessels.vl.chamber.max_elastance", ["'vl'", "lv"]),
    ("boundary_conditions.inlet.flow", ["inlet"]),
])
def test_a_heart_parameter_that_does_not_resolve_names_the_path(path, words):
    with pytest.raises(ModelError) as e:
        closed_loop.o2_sensitivities(_set(), [path], ["SvO2"])
    for w in words:
        assert w in str(e.value), str(e.value)
    # and the same path as a value of the set
    with pytest.raises(ModelError, match=path.replace(".", r"\.")):
        closed_loop.simulate_o2(_with(_set(), path, 1.0))


def test_a_heart_parameter_needs_the_heart_runs_flows():
    p = {**_set(), "flows": "table"}
    with pytest.raises(ModelError, match=r"vessels\.lv\.chamber\.max_elastance.*flows='heart'"):
        closed_loop.o2_sensitivities(p, ["vessels.lv.chamber.max_elastance"], ["SvO2"])


def test_calibration_recovers_the_left_ventricles_elastance_from_a_cardiac_output():
    truth = _with(_set(), "vessels.lv.chamber.max_elastance", 2.8e8)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PeriodicityWarning)
        target = closed_loop.o2_sensitivities(truth, [], ["cardiac_output"], tol=TOL)
    co = float(target["values"][0])
    path = "vessels.lv.chamber.max_elastance"
    fit = oxyline.calibrate(_set(), {"cardiac_output": co}, [path], tol=TOL,
                            bounds={path: (1e8, 1e9)}, method="trf")
    assert fit.success, fit.report
    assert fit.parameters[path] == pytest.approx(2.8e8, rel=1e-6)
    assert fit.start[path] == pytest.approx(3.3e8)     # the built heart's value
    assert fit.model["heart_values"][path] == pytest.approx(2.8e8, rel=1e-6)
    again = closed_loop.o2_sensitivities(fit.model, [], ["cardiac_output"], tol=TOL)
    assert again["values"][0] == pytest.approx(co, rel=1e-8)
