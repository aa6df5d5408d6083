"""Exact sensitivities and calibration (``oxyline.sensitivities``, ``oxyline.calibrate``).

* The Jacobian of every kind of output, for every kind of parameter, against central
  differences of the same periodic runs (relative step 1e-4: truncation O(h²) ~1e-8 and
  rounding ~1e-16/h ~1e-12 of the derivative, so 1e-6 relative tells a wrong derivative).
* The tangent's own run against the run loop's generalized-α (the same scheme and step).
* Synthetic data from known parameters recovered, exactly without noise and inside the
  reported 95 % intervals with 2 % noise.
* Bad input named in the error.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import oxyline
from oxyline import CalibrationError, ModelError
from oxyline.calibrate import _base_value, native_model

pytest.importorskip("scipy")

MODEL = {
    "name": "y", "units": "SI", "period": 0.8,
    "vessels": [
        {"name": "parent", "from": "in", "to": "j", "segments": 3, "length": 0.1,
         "radius": 0.004, "wall_thickness": 0.0006, "youngs_modulus": 4e5},
        {"name": "d1", "from": "j", "to": "o1", "segments": 2, "length": 0.08,
         "radius_in": 0.003, "radius_out": 0.0025, "wall_thickness": 0.0005,
         "youngs_modulus": 6e5},
        {"name": "d2", "from": "j", "to": "o2", "segments": 2,
         "lumped": {"resistance": 3e7, "inductance": 1e5, "capacitance": 2e-10}},
    ],
    "boundary_conditions": {
        "in": {"type": "flow", "fourier": {"period": 0.8, "mean": 5e-6, "cos": [3e-6, -1e-6],
                                           "sin": [4e-6, 1e-6]}},
        "o1": {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-9,
               "distal_resistance": 1.2e9},
        "o2": {"type": "resistance", "resistance": 1.6e9},
    },
    "simulation": {"dt": 0.004, "method": "generalized-alpha"},
}

PARAMETERS = ["boundary_conditions.o1.proximal_resistance",
              "boundary_conditions.o1.capacitance", "boundary_conditions.o2.resistance",
              "vessels.parent.length", "vessels.parent.radius", "vessels.d1.youngs_modulus",
              "vessels.d2.lumped.resistance", "scale.resistance", "scale.inflow"]
OUTPUTS = ["parent.pressure_in.max", "parent.pressure_in.min", "parent.pressure_in.mean",
           "d1.pressure_out.pulse", "d2.flow_in.mean", "flow_split.d1.parent",
           "cardiac_output"]


def _base(path: str) -> float:
    return 1.0 if path.startswith("scale.") else _base_value(
        MODEL, path)


def test_output_jacobian_matches_central_differences() -> None:
    exact = oxyline.sensitivities(MODEL, PARAMETERS, OUTPUTS)
    assert exact.jacobian.shape == (len(OUTPUTS), len(PARAMETERS))
    h = 1e-4
    for k, path in enumerate(PARAMETERS):
        x0 = _base(path)
        up = oxyline.sensitivities(native_model(MODEL, [path], [x0 * (1 + h)]), [], OUTPUTS)
        down = oxyline.sensitivities(native_model(MODEL, [path], [x0 * (1 - h)]), [], OUTPUTS)
        # d/dx in native units = d/dx in SI here (an SI model)
        fd = (up.values - down.values) / (2 * h * x0)
        scale = np.abs(exact.jacobian * exact.parameter_values).max(axis=1)
        err = np.abs(exact.jacobian[:, k] - fd) * x0
        assert (err <= 1e-6 * scale + 1e-300).all(), (path, err / scale)


def test_the_tangent_run_is_the_run_loops_scheme() -> None:
    """The primal of the tangent run against ``simulate`` with the same step: both are
    generalized-α with ρ∞ = 0.5 on the same circuit. The run starts from the periodic state of
    the continuous circuit (8e-7 off the discrete scheme's); that offset decays with the
    Windkessel's time constant (R_d C = 7.2 s), so after 30 cycles of 0.8 s it is below 1e-8
    (measured 4e-9), and 1e-7 tells another scheme or step apart."""
    s = oxyline.sensitivities(MODEL, [], ["parent.pressure_in.series", "d1.flow_out.series"])
    res = oxyline.simulate(MODEL, cycles=30, dt=0.004, start="periodic", output_every=0.004)
    # the run's last cycle has t = 0 … T; the tangent records the step ends Δt … T
    p = res.vessel("parent").pressure_in[1:]
    q = res.vessel("d1").flow_out[1:]
    mine_p = s.values[s.rows["parent.pressure_in.series"]]
    mine_q = s.values[s.rows["d1.flow_out.series"]]
    assert np.abs(mine_p - p).max() <= 1e-7 * np.abs(p).max()
    assert np.abs(mine_q - q).max() <= 1e-7 * np.abs(q).max()


TRUE = {"boundary_conditions.o1.distal_resistance": 1.5e9,
        "boundary_conditions.o1.capacitance": 4e-9,
        "boundary_conditions.o2.resistance": 1.3e9}


def _synthetic(noise: float, seed: int = 1) -> dict[str, dict[str, object]]:
    truth = native_model(MODEL, list(TRUE), list(TRUE.values()))
    names = ["parent.pressure_in.max", "parent.pressure_in.min", "parent.pressure_in.mean",
             "flow_split.d1.parent", "d1.pressure_out.pulse"]
    s = oxyline.sensitivities(truth, [], names + ["d1.flow_out.series"])
    rng = np.random.default_rng(seed)
    targets: dict[str, dict[str, object]] = {}
    for name in names:
        v = float(s.values[s.rows[name]][0])
        targets[name] = {"value": v * (1 + noise * rng.standard_normal()),
                         "sigma": max(noise, 1e-3) * abs(v)}
    q = s.values[s.rows["d1.flow_out.series"]][::10]
    t = (np.arange(len(s.values[s.rows["d1.flow_out.series"]])) + 1)[::10] * 0.004
    sig = max(noise, 1e-3) * np.abs(q).max()
    targets["d1.flow_out.series"] = {"value": (q + noise * np.abs(q).max()
                                               * rng.standard_normal(q.size)).tolist(),
                                     "times": t.tolist(), "sigma": sig}
    return targets


def test_noise_free_synthetic_data_give_back_the_parameters() -> None:
    res = oxyline.calibrate(MODEL, _synthetic(0.0), list(TRUE), method="lm")
    assert res.success, res.report
    for p, v in TRUE.items():
        assert res.parameters[p] == pytest.approx(v, rel=1e-6), p
    assert res.report["rank"] == 3
    # the calibrated model loads and runs
    run = oxyline.simulate(res.model, cycles=1)
    assert np.isfinite(run.vessel("parent").pressure_in).all()


def test_noisy_synthetic_data_fall_inside_the_reported_intervals() -> None:
    bounds = {p: (v / 10, v * 10) for p, v in
              ((p, _base_value(MODEL, p)) for p in TRUE)}
    res = oxyline.calibrate(MODEL, _synthetic(0.02), list(TRUE), bounds=bounds, method="trf")
    assert res.success, res.report
    for p, v in TRUE.items():
        lo, hi = res.intervals[p]
        assert lo <= v <= hi, (p, lo, v, hi)
        assert hi / lo < 2.0  # 2 % noise on 25 values determines them to well within 2x


def test_bad_input_names_what_is_wrong() -> None:
    good = {"parent.pressure_in.mean": 1e4}
    with pytest.raises(CalibrationError, match="no vessel named 'aorta'"):
        oxyline.calibrate(MODEL, {"aorta.pressure_in.mean": 1.0}, list(TRUE))
    with pytest.raises(CalibrationError, match="unknown statistic 'median'"):
        oxyline.calibrate(MODEL, {"parent.pressure_in.median": 1.0}, list(TRUE))
    with pytest.raises(ModelError, match="parameter 'vessels.parent.colour'"):
        oxyline.calibrate(MODEL, good, ["vessels.parent.colour"])
    with pytest.raises(ModelError, match="parameter 'vessels.d1.radius'.*tapered"):
        oxyline.sensitivities(MODEL, ["vessels.d1.radius"], ["parent.pressure_in.mean"])
    with pytest.raises(CalibrationError, match="exclude the start"):
        oxyline.calibrate(MODEL, good, ["boundary_conditions.o2.resistance"],
                          bounds={"boundary_conditions.o2.resistance": (2e9, 3e9)},
                          method="trf")
    with pytest.raises(CalibrationError, match="non-finite value nan"):
        oxyline.calibrate(MODEL, {"parent.pressure_in.mean": float("nan")}, list(TRUE))
    with pytest.raises(CalibrationError, match="ftol: expected a number in \\(0, 1\\), got 0"):
        oxyline.calibrate(MODEL, good, list(TRUE), ftol=0)
    bad_series = {"d1.flow_out.series": {"value": [1.0, float("inf")], "times": [0.1, 0.2]}}
    with pytest.raises(CalibrationError, match="d1.flow_out.series.*non-finite"):
        oxyline.calibrate(MODEL, bad_series, list(TRUE))
    with pytest.raises(CalibrationError, match="'lm' takes no bounds"):
        oxyline.calibrate(MODEL, good, ["boundary_conditions.o2.resistance"],
                          bounds={"boundary_conditions.o2.resistance": (1e9, 3e9)})


def test_a_fit_that_runs_out_of_evaluations_says_so() -> None:
    mean = oxyline.sensitivities(MODEL, [], ["parent.pressure_in.mean"]).values[0]
    res = oxyline.calibrate(MODEL, {"parent.pressure_in.mean": 2 * mean},
                            ["boundary_conditions.o2.resistance"], max_evaluations=1)
    assert not res.success
    assert res.report["status"] == 0  # scipy: "the maximum number of evaluations is exceeded"


def test_a_failed_evaluation_returns_the_best_point_with_its_report(monkeypatch) -> None:
    """The core fails at the first trial point: the fit stops there and returns the best
    point so far (the start) with the error in its report, not an exception."""
    import sys

    module = sys.modules["oxyline.calibrate"]
    real, calls = module._evaluate, []

    def failing(*args, **kw):
        calls.append(1)
        if len(calls) > 1:  # the start is evaluated once, then every trial point fails
            raise oxyline.SolverError("diverged at the trial point")
        return real(*args, **kw)

    monkeypatch.setattr(module, "_evaluate", failing)
    res = oxyline.calibrate(MODEL, {"parent.pressure_in.mean": 1.0e4},
                            ["boundary_conditions.o2.resistance"])
    assert not res.success and res.report["status"] == -1
    assert "diverged at the trial point" in res.report["error"]
    assert res.parameters["boundary_conditions.o2.resistance"] == 1.6e9
    assert np.isfinite(res.residuals).all()


def test_cli_writes_a_calibrated_model(tmp_path) -> None:
    import yaml

    from oxyline.cli import main

    model = tmp_path / "y.yaml"
    model.write_text(yaml.safe_dump(copy.deepcopy(MODEL)))
    targets = {k: v for k, v in _synthetic(0.0).items() if not k.endswith("series")}
    problem = {"parameters": list(TRUE), "targets": targets, "method": "lm"}
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(problem))
    out = tmp_path / "calibrated.yaml"
    assert main(["calibrate", str(model), str(tmp_path / "t.yaml"), "-o", str(out),
                 "--quiet"]) == 0
    fitted = yaml.safe_load(out.read_text())
    assert fitted["boundary_conditions"]["o2"]["resistance"] == pytest.approx(1.3e9, rel=1e-6)
    assert main(["calibrate", str(model), str(tmp_path / "nope.yaml"), "-o", str(out)]) == 2


@pytest.mark.slow  # 3,600 model runs (~30 s idle); needs the bayes extra (emcee)
def test_the_posterior_agrees_with_the_gauss_newton_covariance() -> None:
    """For data that determine the parameters well (2 % noise, 25 values, 3 parameters) the
    posterior in log(parameter) is close to Gaussian: its mean near the fit and its spread the
    Gauss-Newton one. Tolerances: 8 walkers x 300 steps after a 150-step burn-in give ~100
    independent draws, so the sample mean is good to ~0.1 sd and the sample sd to ~10 %; 0.5
    sd and a factor 1.5 leave room for that and for the likelihood's curvature."""
    pytest.importorskip("emcee")
    res = oxyline.calibrate(MODEL, _synthetic(0.02), list(TRUE), method="bayes",
                            posterior={"walkers": 8, "steps": 450, "burn": 150})
    assert res.samples is not None and res.samples.shape == (8 * 300, 3)
    assert 0.1 < res.report["acceptance"] < 0.9
    logs = np.log(res.samples)
    fit = np.log([res.parameters[p] for p in TRUE])
    sd = np.sqrt(np.diag(res.covariance))
    assert (np.abs(logs.mean(axis=0) - fit) < 0.5 * sd).all(), (logs.mean(axis=0) - fit) / sd
    ratio = logs.std(axis=0) / sd
    assert ((ratio > 1 / 1.5) & (ratio < 1.5)).all(), ratio


def _tube() -> tuple[dict, float]:
    """Two uniform 0.6 m vessels in series, matched at the outlet (R = ρc/(πr²): no
    reflection), driven by a half-sine systolic inflow (10 harmonics); and the
    Moens–Korteweg speed of the thin, tethered wall, c = √(2Eh/(3ρr)) (ν = 0.5, physics.md
    §1.1)."""
    r, h, e, rho, period = 0.01, 0.001, 4e5, 1050.0, 1.0
    c = np.sqrt(2 * e * h / (3 * rho * r))
    t = np.linspace(0, period, 2000, endpoint=False)
    q = np.where(t < 0.3, np.sin(np.pi * t / 0.3), 0.0) * 1e-4
    k = np.arange(1, 11)[:, None]
    fourier = {"period": period, "mean": float(q.mean()),
               "cos": (2 * np.mean(q * np.cos(2 * np.pi * k * t), axis=1)).tolist(),
               "sin": (2 * np.mean(q * np.sin(2 * np.pi * k * t), axis=1)).tolist()}
    wall = {"segments": 60, "length": 0.6, "radius": r, "wall_thickness": h,
            "youngs_modulus": e}
    model = {"name": "tube", "units": "SI", "period": period,
             "vessels": [{"name": "a", "from": "in", "to": "m", **wall},
                         {"name": "b", "from": "m", "to": "out", **wall}],
             "boundary_conditions": {
                 "in": {"type": "flow", "fourier": fourier},
                 "out": {"type": "resistance", "resistance": rho * c / (np.pi * r * r)}},
             "simulation": {"dt": 0.001, "method": "generalized-alpha"}}
    return model, float(c)


def test_pulse_wave_velocity_is_moens_korteweg_and_its_derivatives_are_exact() -> None:
    model, c = _tube()
    params = ["vessels.a.length", "vessels.b.youngs_modulus"]
    s = oxyline.sensitivities(model, params, ["pwv.a.b"])
    # foot-to-foot on the sampled wave (1 ms steps, 0.24 s transit) and the line's
    # dispersion: within 1 % of the closed form
    assert s.values[0] == pytest.approx(c, rel=0.01)
    # closed form: PWV = L / (L_a/c_a + L_b/c_b), c ∝ √E: d PWV/d E_b = c (L_b/L) / (2 E)
    assert s.jacobian[0, 1] == pytest.approx(c * 0.5 / (2 * 4e5), rel=0.05)
    h = 1e-4
    for k, path in enumerate(params):
        x0 = _base_value(model, path)
        up, down = (oxyline.sensitivities(native_model(model, [path], [x0 * f]), [],
                                          ["pwv.a.b"]).values[0] for f in (1 + h, 1 - h))
        fd = (up - down) / (2 * h * x0)
        # the path length's own derivative (1/transit for vessels.a.length) is in both
        assert abs(s.jacobian[0, k] - fd) * x0 <= 1e-6 * c, (path, s.jacobian[0, k], fd)


def test_a_pulse_wave_velocity_needs_a_path_downstream() -> None:
    with pytest.raises(ModelError, match="not downstream"):
        oxyline.sensitivities(MODEL, [], ["pwv.d1.parent"])
    with pytest.raises(ModelError, match="no vessel named 'zz'"):
        oxyline.sensitivities(MODEL, [], ["pwv.parent.zz"])


def test_cardiac_output_is_the_prescribed_mean_inflow() -> None:
    # closed form: the flow condition's mean (5e-6 m³/s), proportional to scale.inflow and
    # independent of every resistance (a prescribed flow); the periodic cycle's mean of the
    # sampled Fourier waveform equals its mean to rounding (whole harmonics over the cycle)
    s = oxyline.sensitivities(MODEL, ["scale.inflow", "boundary_conditions.o2.resistance"],
                              ["cardiac_output"])
    assert s.values[0] == pytest.approx(5e-6, rel=1e-9)
    assert s.jacobian[0, 0] == pytest.approx(5e-6, rel=1e-9)
    assert abs(s.jacobian[0, 1]) * 1.6e9 <= 1e-9 * 5e-6


def _stenosed(coefficient: float = 1.2e13) -> dict:
    """``MODEL`` with a stenosis S Q|Q| in the lumped daughter: at its peak flow (~4e-6 m³/s)
    the nonlinear drop is ~1.6× the linear one R Q, so the fit has to see the quadratic."""
    model = copy.deepcopy(MODEL)
    model["vessels"][2]["lumped"]["stenosis_coefficient"] = coefficient
    return model


STENOSIS = "vessels.d2.lumped.stenosis_coefficient"


def test_stenosis_jacobian_matches_central_differences() -> None:
    """The stenosis coefficient, and linear kinds whose tangents now pass through the
    Newton matrices of the stenosed circuit, against central differences (relative step
    1e-4, as above)."""
    model = _stenosed()
    params = [STENOSIS, "vessels.d2.lumped.resistance", "boundary_conditions.o2.resistance",
              "vessels.parent.radius"]
    exact = oxyline.sensitivities(model, params, OUTPUTS)
    assert exact.parameter_values[0] == 1.2e13
    h = 1e-4
    # per output, the largest response to a 100 % change of a parameter; an output none of
    # them changes (cardiac output: a prescribed inflow) is held to 1e-11 of its value (the
    # difference quotient's rounding, 1e-16/h, is 1e-12 of it)
    scale = np.maximum(np.abs(exact.jacobian * exact.parameter_values).max(axis=1),
                       1e-5 * np.abs(exact.values))
    for k, path in enumerate(params):
        x0 = _base_value(model, path)
        up, down = (oxyline.sensitivities(native_model(model, [path], [x0 * f]), [],
                                          OUTPUTS).values for f in (1 + h, 1 - h))
        err = np.abs(exact.jacobian[:, k] - (up - down) / (2 * h * x0)) * x0
        assert (err <= 1e-6 * scale + 1e-300).all(), (path, err / scale)
    # a narrower daughter takes less of the flow and raises the inlet pressure
    rows = exact.rows
    assert exact.jacobian[rows["flow_split.d1.parent"], 0][0] > 0
    assert exact.jacobian[rows["parent.pressure_in.mean"], 0][0] > 0


def test_a_stenosis_coefficient_is_recovered_from_synthetic_data() -> None:
    """Targets of the stenosed model with S = 2.5e13 (and the daughter's outlet resistance
    1.4e9) fitted from S = 1.2e13 (1.6e9): noise-free data determine both exactly (the
    quadratic drop and the linear one differ in how they share the pulsatile flow)."""
    truth = _stenosed(2.5e13)
    truth["boundary_conditions"]["o2"]["resistance"] = 1.4e9
    outputs = ["parent.pressure_in.max", "parent.pressure_in.min", "parent.pressure_in.mean",
               "flow_split.d1.parent", "d2.flow_in.max", "d2.flow_in.min"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)} for o, v in
               zip(outputs, measured, strict=True)}
    params = [STENOSIS, "boundary_conditions.o2.resistance"]
    res = oxyline.calibrate(_stenosed(), targets, params, method="lm")
    assert res.success, res.report
    assert res.parameters[STENOSIS] == pytest.approx(2.5e13, rel=1e-6)
    assert res.parameters["boundary_conditions.o2.resistance"] == pytest.approx(1.4e9, rel=1e-6)
    assert res.model["vessels"][2]["lumped"]["stenosis_coefficient"] == \
        pytest.approx(2.5e13, rel=1e-6)


def test_stenosis_parameters_a_model_lacks_are_named() -> None:
    with pytest.raises(ModelError, match=r"parameter 'vessels\.d1\.lumped\.stenosis_coefficient'"
                                         r".*no differentiable value"):
        oxyline.sensitivities(MODEL, ["vessels.d1.lumped.stenosis_coefficient"],
                              ["parent.pressure_in.mean"])
    with pytest.raises(ModelError, match=r"parameter 'vessels\.d9\.lumped\.stenosis_coefficient'"
                                         r".*no vessel named 'd9'"):
        oxyline.sensitivities(MODEL, ["vessels.d9.lumped.stenosis_coefficient"],
                              ["parent.pressure_in.mean"])
    # a lumped vessel without a stenosis: S = 0 cannot be fitted in log space
    with pytest.raises(CalibrationError, match=f"parameter '{STENOSIS}': the start must be "
                                               "positive"):
        oxyline.calibrate(MODEL, {"parent.pressure_in.mean": 1e4}, [STENOSIS])


def test_the_stenosed_tangent_run_is_the_run_loops_newton_scheme() -> None:
    """The primal of a stenosed model's tangent run against ``simulate`` with the same step:
    both take generalized-α's Newton steps (converged to 1e-12 of the state's scale). The
    run's periodic start is that of the mean flow, which misses the stenosis's mean drop
    S⟨Q|Q|⟩ − S Q̄²; that offset decays over the cycles (measured 1e-4, 5e-7 and 2e-11 of the
    pressure after 30, 60 and 120 cycles), so after 120 cycles 1e-9 tells another scheme,
    step or stenosis law apart."""
    model = _stenosed()
    s = oxyline.sensitivities(model, [], ["parent.pressure_in.series", "d2.flow_in.series"])
    res = oxyline.simulate(model, cycles=120, dt=0.004, start="periodic", output_every=0.004)
    p = res.vessel("parent").pressure_in[1:]
    q = res.vessel("d2").flow_in[1:]
    assert np.abs(s.values[s.rows["parent.pressure_in.series"]] - p).max() \
        <= 1e-9 * np.abs(p).max()
    assert np.abs(s.values[s.rows["d2.flow_in.series"]] - q).max() <= 1e-9 * np.abs(q).max()


@pytest.mark.parametrize("stenosed", [False, True])
def test_the_adjoint_jacobian_is_the_forward_one(stenosed: bool) -> None:
    """``mode="adjoint"`` (one backward sweep per output, transposed solves) against the
    forward tangents (checked against central differences above) on every output kind: the
    two differ only by their fixed points' tolerance (1e-12) and rounding, so 1e-8 of each
    output's largest response to a 100 % change tells a wrong transpose or weight apart."""
    model = _stenosed() if stenosed else MODEL
    params = PARAMETERS + ([STENOSIS] if stenosed else [])
    outputs = OUTPUTS + ["d1.flow_out.max"]
    fwd = oxyline.sensitivities(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-12)
    np.testing.assert_array_equal(adj.parameter_values, fwd.parameter_values)
    scale = np.maximum(np.abs(fwd.jacobian * fwd.parameter_values).max(axis=1),
                       1e-5 * np.abs(fwd.values))
    err = np.abs(adj.jacobian - fwd.jacobian) * np.abs(fwd.parameter_values)
    assert (err <= 1e-8 * scale[:, None]).all(), err / scale[:, None]
    assert adj.tangent_cycles < 2000  # the adjoint reached its periodic state
