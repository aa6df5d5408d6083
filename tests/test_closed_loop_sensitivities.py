"""The closed loop's O2 outputs at the periodic state and their exact derivatives (the core's
step tangent and the implicit function theorem on the periodic fixed point) against central
differences of whole periodic runs, bad input named, and a calibration that recovers known
parameters from synthetic data."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import oxyline
from oxyline import closed_loop
from oxyline.errors import ModelError

#: every parameter kind the tangent covers, and the outputs read by the run's own summary
PARAMETERS = ["organs.brain.vo2", "organs.muscle.vo2", "km", "lungs.diffusing_capacity",
              "lungs.alveolar_po2", "blood.p50", "blood.hemoglobin", "cardiac_output"]
OUTPUTS = ["SvO2", "SaO2", "PaO2", "PvO2", "VO2.brain", "VO2.muscle", "VO2",
           "cardiac_output"]
#: a periodic tolerance far below the differences' truncation error (h² ~ 1e-8)
TOL = 1e-14
H = 1e-4


def _set() -> dict:
    """closed-loop-o2 on its prescribed flow table (the table is proportional to the cardiac
    output, so that is a parameter too); 100 steps a cycle keep the runs short."""
    p = closed_loop.load("closed-loop-o2")
    p.update(flows="table", dt=0.008)
    return p


def _summary_outputs(p: dict) -> np.ndarray:
    """The outputs of a whole periodic run, read from its summary (mmHg and mL/min: the
    comparison below is of logarithmic derivatives, free of units)."""
    s = closed_loop.simulate_o2(p, tol=TOL).summary()
    return np.array([s["SvO2"], s["SaO2"], s["PaO2"], s["PvO2"], s["VO2_organs"]["brain"],
                     s["VO2_organs"]["muscle"], s["VO2"], s["cardiac_output"]])


def _scaled(p: dict, path: str, factor: float) -> dict:
    q = copy.deepcopy(p)
    *head, last = path.split(".")
    node = q
    for k in head:
        node = node[k]
    node[last] *= factor
    return q


def test_derivatives_of_every_parameter_kind_match_central_differences_of_periodic_runs():
    p = _set()
    s = oxyline.sensitivities(p, PARAMETERS, OUTPUTS, tol=TOL)
    base = _summary_outputs(p)
    # the values: the summary's (SI here, mmHg and mL/min there)
    assert s.values[0] == pytest.approx(base[0], rel=1e-12)
    assert s.values[1] == pytest.approx(base[1], rel=1e-12)
    # d log(output) / d log(parameter): exact tangent against central differences
    exact = s.jacobian * s.parameter_values[None, :] / s.values[:, None]
    fd = np.empty_like(exact)
    for j, path in enumerate(PARAMETERS):
        up = _summary_outputs(_scaled(p, path, np.exp(H)))
        down = _summary_outputs(_scaled(p, path, np.exp(-H)))
        fd[:, j] = (up - down) / (2 * H) / base
    # the differences' truncation error is ~h² = 1e-8 of the curvature, the runs' periodic
    # noise 1e-14/h; each row is compared on the scale of its largest entry (a parameter
    # that hardly moves an output has a derivative of round-off size)
    scale = np.abs(fd).max(axis=1, keepdims=True)
    np.testing.assert_allclose(exact / scale, fd / scale, rtol=0, atol=1e-6)
    # and they are not trivially zero: SvO2 falls with the muscle's VO2, rises with the flow
    assert exact[0, 1] < -0.01 and exact[0, 7] > 0.1


def test_sensitivities_with_the_heart_runs_flows_cover_the_oxygen_parameters():
    # the heart's flows do not depend on the O2 parameters: the same tangent on its table
    p = closed_loop.load("closed-loop-o2")
    for path, out in (("organs.muscle.vo2", "SvO2"), ("blood.p50", "SaO2")):
        s = oxyline.sensitivities(p, [path], [out], tol=TOL)
        up = closed_loop.simulate_o2(_scaled(p, path, np.exp(H)), tol=TOL).summary()[out]
        down = closed_loop.simulate_o2(_scaled(p, path, np.exp(-H)), tol=TOL).summary()[out]
        fd = (up - down) / (2 * H)
        # the differences' truncation error ~h², the runs' periodic noise ~1e-14/h
        assert s.jacobian[0, 0] * s.parameter_values[0] == pytest.approx(fd, rel=1e-6)


@pytest.mark.parametrize(("parameters", "outputs", "named"), [
    (["organs.liver.vo2"], ["SvO2"], "liver"),
    (["pools.veins"], ["SvO2"], "pools.veins"),
    (["km"], ["VO2.liver"], "VO2.liver"),
    (["km"], ["SvO3"], "SvO3"),
])
def test_an_unknown_parameter_or_output_is_a_model_error_naming_it(parameters, outputs,
                                                                    named):
    with pytest.raises(ModelError, match=named.replace(".", r"\.")):
        oxyline.sensitivities(_set(), parameters, outputs)


def test_flow_parameters_of_a_heart_run_and_the_arterial_tree_are_refused_by_name():
    with pytest.raises(ModelError, match="cardiac_output"):
        oxyline.sensitivities("closed-loop-o2", ["cardiac_output"], ["SvO2"])
    with pytest.raises(ModelError, match="arterial tree"):
        oxyline.sensitivities("closed-loop-o2-tree", ["km"], ["SvO2"])


def test_calibration_recovers_the_muscle_vo2_diffusing_capacity_and_cardiac_output():
    # synthetic data: a whole periodic run of known parameters, read from its summary
    truth = _set()
    truth["organs"]["muscle"]["vo2"] = 80.0
    truth["lungs"]["diffusing_capacity"] = 6.0   # diffusion-limited: SaO2 below 0.95
    truth["cardiac_output"] = 5.6
    s = closed_loop.simulate_o2(truth, tol=TOL).summary()
    targets = {"SvO2": s["SvO2"], "SaO2": s["SaO2"],
               "cardiac_output": s["cardiac_output"] * 1e-3 / 60.0}  # m³/s
    params = ["organs.muscle.vo2", "lungs.diffusing_capacity", "cardiac_output"]
    # from the resting set, whose lungs equilibrate (d log SaO2/d log D_L ≈ 2e-4 there: an
    # unbounded first step would go far), within bounds
    bounds = {"organs.muscle.vo2": (10.0, 200.0), "lungs.diffusing_capacity": (3.0, 40.0),
              "cardiac_output": (2.0, 10.0)}
    fit = oxyline.calibrate(_set(), targets, params, tol=TOL, method="trf", bounds=bounds)
    assert fit.success, fit.report
    # an exact fit of three values by three parameters: recovered to the runs' tolerance
    for path, want in zip(params, [80.0, 6.0, 5.6], strict=True):
        assert fit.parameters[path] == pytest.approx(want, rel=1e-6)
    # the calibrated set runs and meets the targets
    again = closed_loop.simulate_o2(fit.model, tol=TOL).summary()
    assert again["SvO2"] == pytest.approx(s["SvO2"], rel=1e-8)
    lo, hi = fit.intervals["lungs.diffusing_capacity"]
    assert lo < 6.0 < hi


def test_calibration_bad_targets_and_parameters_are_named():
    with pytest.raises(oxyline.CalibrationError, match="SvO3"):
        oxyline.calibrate(_set(), {"SvO3": 0.7}, ["km"])
    with pytest.raises(oxyline.CalibrationError, match="organs.liver.vo2"):
        oxyline.calibrate(_set(), {"SvO2": 0.7}, ["organs.liver.vo2"])


def test_calibration_with_noisy_data_brackets_the_truth_in_its_intervals():
    # 0.5 % noise on each target (its sigma): the linearised 95 % intervals of the
    # Gauss–Newton covariance hold the true values (a fixed draw)
    truth = _set()
    truth["organs"]["muscle"]["vo2"] = 80.0
    truth["lungs"]["diffusing_capacity"] = 6.0
    truth["cardiac_output"] = 5.6
    s = closed_loop.simulate_o2(truth, tol=TOL).summary()
    exact = {"SvO2": s["SvO2"], "SaO2": s["SaO2"],
             "cardiac_output": s["cardiac_output"] * 1e-3 / 60.0}
    rng = np.random.default_rng(1)
    targets = {o: {"value": v * (1 + 0.005 * rng.standard_normal()), "sigma": 0.005 * v}
               for o, v in exact.items()}
    bounds = {"organs.muscle.vo2": (10.0, 200.0), "lungs.diffusing_capacity": (3.0, 40.0),
              "cardiac_output": (2.0, 10.0)}
    fit = oxyline.calibrate(_set(), targets, list(bounds), method="trf", bounds=bounds,
                            tol=1e-13)
    assert fit.success, fit.report
    for path, want in zip(bounds, [80.0, 6.0, 5.6], strict=True):
        lo, hi = fit.intervals[path]
        assert lo < want < hi, (path, lo, hi)
        assert fit.parameters[path] != pytest.approx(want, rel=1e-3)  # the noise moved it
