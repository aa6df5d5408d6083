"""Identifiability and the gradient's choice in ``oxyline.calibrate``.

* Every terminal R and C, the inflow scale and the wall stiffness of the network (one factor,
  a group of paths) of the built-in aortic bifurcation, from synthetic data of known values:
  recovered to the optimiser's tolerance without noise, and inside the reported 95 %
  intervals with 2 % noise (the intervals assume exactly that sigma).
* The adjoint's fit (one backward sweep per target value) is the forward tangents' fit;
  ``gradient="auto"`` takes the adjoint when the parameters outnumber the target values.
* Groups: bad groups named in the error.
"""

from __future__ import annotations

import numpy as np
import pytest

import oxyline
from oxyline import CalibrationError
from oxyline.calibrate import _base_value, native_model

pytest.importorskip("scipy")

MODEL = "aortic-bifurcation"
OUTLETS = {"n3": "d1", "n4": "d2"}
PATHS = [f"boundary_conditions.{n}.{k}" for n in OUTLETS
         for k in ("distal_resistance", "capacitance")] + ["scale.inflow"]
STIFFNESS = {"stiffness": [f"vessels.{v}.youngs_modulus" for v in ("parent", "d1", "d2")]}
OUTPUTS = [f"{v}.flow_out.{s}" for v in OUTLETS.values() for s in ("mean", "pulse")] + \
    ["parent.pressure_in.max", "parent.pressure_in.min", "d1.pressure_out.pulse"]
#: the truth as factors on the model's values (the last: the stiffness group's)
FACTORS = np.array([1.3, 0.8, 0.75, 1.25, 1.1, 1.4])


def _truth() -> tuple[dict, dict[str, float]]:
    """The model at the true values and those values (a group by its factor)."""
    source = oxyline.load_model(MODEL).source
    stiff = STIFFNESS["stiffness"]
    paths = PATHS + stiff
    base = [1.0 if p.startswith("scale.") else _base_value(source, p) for p in paths]
    factors = np.concatenate([FACTORS[:-1], np.full(len(stiff), FACTORS[-1])])
    true = native_model(source, paths, np.array(base) * factors)
    return true, {**{p: b * f for p, b, f in zip(PATHS, base, FACTORS, strict=False)},
                  "stiffness": float(FACTORS[-1])}


def _targets(noise: float, seed: int = 7) -> dict[str, dict[str, float]]:
    true, _ = _truth()
    values = oxyline.sensitivities(true, [], OUTPUTS).values
    rng = np.random.default_rng(seed)
    sigma = 0.02 * np.abs(values)
    data = values + noise * sigma / 0.02 * rng.standard_normal(len(values))
    return {o: {"value": float(d), "sigma": float(s)}
            for o, d, s in zip(OUTPUTS, data, sigma, strict=True)}


def test_recovered_exactly_without_noise() -> None:
    """Noise-free data: the fit's residuals vanish and every parameter (and the stiffness
    factor) is its true value to 1e-6 (the fit stops at xtol 1e-10 in log space; 1e-6
    leaves room for the periodic tolerance's effect on the outputs)."""
    fit = oxyline.calibrate(MODEL, _targets(0.0), PATHS, groups=STIFFNESS, method="lm")
    _, truth = _truth()
    assert fit.success, fit.report
    assert fit.report["rank"] == len(truth)
    for p, v in truth.items():
        assert fit.parameters[p] == pytest.approx(v, rel=1e-6), p


def test_recovered_within_the_intervals_with_two_percent_noise() -> None:
    """2 % Gaussian noise, sigma 2 %: each true value inside its reported 95 % interval (for
    the seed used; a wrong covariance scale, a sign or a column mixed up puts values out), and
    the intervals are not vacuous (each narrower than a factor of 3)."""
    fit = oxyline.calibrate(MODEL, _targets(0.02), PATHS, groups=STIFFNESS, method="lm")
    _, truth = _truth()
    assert fit.success, fit.report
    for p, v in truth.items():
        lo, hi = fit.intervals[p]
        assert lo <= v <= hi, (p, lo, v, hi)
        assert hi / lo < 3.0, (p, lo, hi)


def test_adjoint_fit_is_the_forward_fit() -> None:
    """The same fit by the adjoint and by the tangents: the Jacobians agree to the periodic
    tolerance, so the iterates (and the end points) agree to far below the data's scale."""
    targets = _targets(0.02)
    fwd = oxyline.calibrate(MODEL, targets, PATHS, groups=STIFFNESS, method="lm",
                            gradient="forward")
    adj = oxyline.calibrate(MODEL, targets, PATHS, groups=STIFFNESS, method="lm",
                            gradient="adjoint")
    assert (fwd.report["gradient"], adj.report["gradient"]) == ("forward", "adjoint")
    for p, v in fwd.parameters.items():
        assert adj.parameters[p] == pytest.approx(v, rel=1e-6), p
    np.testing.assert_allclose(adj.covariance, fwd.covariance, rtol=1e-5,
                               atol=1e-8 * np.abs(fwd.covariance).max())


def test_auto_takes_the_adjoint_when_parameters_outnumber_targets() -> None:
    """Eight paths (four conditions, the inflow scale, three in the group) against seven
    target values: the adjoint; five paths (no group) against seven: the tangents."""
    t = _targets(0.0)
    fit = oxyline.calibrate(MODEL, t, PATHS, groups=STIFFNESS, method="lm", max_evaluations=2)
    assert fit.report["gradient"] == "adjoint"
    fit = oxyline.calibrate(MODEL, t, PATHS, method="lm", max_evaluations=2)
    assert fit.report["gradient"] == "forward"


@pytest.mark.parametrize("groups, match", [
    ({"g": "vessels.d1.youngs_modulus"}, "non-empty list"),
    ({"g": [PATHS[0]]}, PATHS[0]),
    ({"g": ["vessels.d1.youngs_modulus"], "h": ["vessels.d1.youngs_modulus"]},
     "vessels.d1.youngs_modulus"),
    ({"g": ["vessels.nowhere.youngs_modulus"]}, "nowhere"),
    (["vessels.d1.youngs_modulus"], "mapping"),
])
def test_bad_groups_are_named(groups: object, match: str) -> None:
    with pytest.raises(CalibrationError, match=match):
        oxyline.calibrate(MODEL, _targets(0.0), PATHS, groups=groups)


def test_bad_gradient_is_named() -> None:
    with pytest.raises(CalibrationError, match="gradient"):
        oxyline.calibrate(MODEL, _targets(0.0), PATHS, gradient="reverse")


def test_the_adjoint_reads_the_one_primal_cycle() -> None:
    """The adjoint (``sensitivities(..., mode="adjoint")``, the core building each output's
    weights on its one primal cycle) reduces the same periodic cycle as the forward tangents:
    a cycle mean is the mean of the forward run's series over its steps (the step end times
    Δt … T, each weighted 1/n), to the periodic tolerance (1e-12; 1e-9 allows its spread over
    the cycle), and its gradient by the inflow scale is the tangents' (one backward sweep
    against one tangent run: the same derivative to that tolerance). The inflow scale moves a
    linear network's pressure about its own level (p(s) = s p(1) with no outlet pressure), so
    the mean's derivative by it is the mean itself: an independent check of both."""
    model = oxyline.load_model(MODEL)
    series = oxyline.sensitivities(model, [], ["parent.pressure_in.series"])
    mean = ["parent.pressure_in.mean"]
    fwd = oxyline.sensitivities(model, ["scale.inflow"], mean)
    adj = oxyline.sensitivities(model, ["scale.inflow"], mean, mode="adjoint")
    assert adj.values[0] == pytest.approx(series.values.mean(), rel=1e-9)
    assert adj.jacobian[0, 0] == pytest.approx(fwd.jacobian[0, 0], rel=1e-9)
    assert adj.jacobian[0, 0] == pytest.approx(adj.values[0], rel=1e-9)


def test_a_problem_file_reads_groups_and_gradient(tmp_path) -> None:
    from oxyline.calibrate import read_problem

    f = tmp_path / "problem.yaml"
    f.write_text("parameters: [scale.inflow]\n"
                 "groups: {stiffness: [vessels.d1.youngs_modulus, vessels.d2.youngs_modulus]}\n"
                 "gradient: adjoint\ntargets: {cardiac_output: 1.0e-4}\n")
    p = read_problem(str(f))
    assert p["groups"] == {"stiffness": ["vessels.d1.youngs_modulus",
                                         "vessels.d2.youngs_modulus"]}
    assert p["gradient"] == "adjoint"
    f.write_text("parameters: [scale.inflow]\ntargets: {cardiac_output: 1.0e-4}\nweights: 1\n")
    with pytest.raises(CalibrationError, match="weights"):
        read_problem(str(f))
