"""Exact sensitivities of the other activation laws and of spherical chambers
(``oxyline.sensitivities``).

* The piecewise-cosine, two-Hill and wrapping-cosine activations' timing and shape
  parameters (``vessels.<v>.chamber.activation.<key>``) on the left heart of
  ``test_sensitivity_heart``, and every constant of svZeroDSolver's ``ChamberSphere``
  (``vessels.<v>.chamber_sphere.<key>``) on its chamber_sphere case, against central
  differences of the same periodic runs: relative step 1e-5 for the activations (C¹ laws:
  truncation and the rounding of the periodic fixed points stay below 1e-7 of the
  derivative); for the sphere 1e-4 (1e-5 for its switch times) and half of it, combined by
  Richardson extrapolation (its sharp tanh switches leave plain differences' h² truncation
  near 1e-6); 1e-6 relative to each output's largest derivative tells a wrong derivative.
* The adjoint against the forward tangents (1e-8).
* A two-Hill time constant and a sphere's maximal active stress recovered from synthetic
  data (noise-free: 1e-6).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import ModelError
from oxyline import svzerod as svz
from oxyline.calibrate import _base_value, native_model
from tests.conftest import assert_adjoint_is_forward, data_path
from tests.test_sensitivity_heart import HEART, OUTPUTS

pytest.importorskip("scipy")

#: the activations' parameters on the left heart's 0.8 s cycle (svZeroDSolver's two-Hill
#: exponents m1 = 1.32, m2 = 27.4; each law contracts the ventricle once a cycle)
ACTIVATIONS: dict[str, dict[str, Any]] = {
    "piecewise-cosine": {"contract_start": 0.1, "relax_start": 0.25,
                         "contract_duration": 0.15, "relax_duration": 0.3},
    "two-hill": {"t_shift": 0.1, "tau_1": 0.15, "tau_2": 0.35, "m1": 1.32, "m2": 27.4},
    "wrapping-cosine": {"systole_fraction": 0.45, "p_wave_divisor": 2.5},
}


def _heart(kind: str) -> dict[str, Any]:
    model = copy.deepcopy(HEART)
    model["vessels"][1]["chamber"]["activation"] = {"kind": kind, **ACTIVATIONS[kind]}
    return model


def _sphere() -> tuple[dict[str, Any], str]:
    model = svz.to_oxyline_dict(str(data_path("svzerod", "cases", "chamber_sphere.json")))
    name = next(v["name"] for v in model["vessels"] if "chamber_sphere" in v)
    return model, name


def _central(model: dict[str, Any], path: str, outputs: list[str], h: float) -> Any:
    """d(outputs)/d(log parameter) by central differences of relative step h."""
    x0 = _base_value(model, path)  # in the model's units (the Jacobian's are SI)
    up, down = (oxyline.sensitivities(native_model(model, [path], [x0 * f]), [],
                                      outputs).values for f in (1 + h, 1 - h))
    return (up - down) / (2 * h)


def _check_central(model: dict[str, Any], params: list[str], outputs: list[str],
                   step: Any, richardson: bool = False) -> Any:
    """The Jacobian against central differences (with ``richardson``: steps h and h/2
    combined as (4 D(h/2) − D(h))/3, which cancels the h² truncation)."""
    exact = oxyline.sensitivities(model, params, outputs)
    assert exact.periodic_change <= 1e-11
    scale = np.abs(exact.jacobian * exact.parameter_values).max(axis=1)
    assert (scale > 0).all()
    for k, path in enumerate(params):
        h = step(path)
        fd = _central(model, path, outputs, h)
        if richardson:
            fd = (4 * _central(model, path, outputs, h / 2) - fd) / 3
        err = np.abs(exact.jacobian[:, k] * exact.parameter_values[k] - fd)
        assert (err <= 1e-6 * scale).all(), (path, err / scale)
        assert np.abs(exact.jacobian[:, k]).max() > 0, path
    return exact


@pytest.mark.parametrize("kind", list(ACTIVATIONS))
def test_activation_jacobian_matches_central_differences(kind: str) -> None:
    params = [f"vessels.lv.chamber.activation.{k}" for k in ACTIVATIONS[kind]]
    _check_central(_heart(kind), params, OUTPUTS, lambda _: 1e-5)


SPHERE_KEYS = ["density", "wall_thickness", "reference_radius", "w1", "w2", "viscosity",
               "max_active_stress", "max_activation_rate", "min_activation_rate",
               "systole_start", "diastole_start", "activation_steepness"]


def test_sphere_jacobian_matches_central_differences() -> None:
    model, name = _sphere()
    params = [f"vessels.{name}.chamber_sphere.{k}" for k in SPHERE_KEYS]
    outputs = [f"{name}.pressure_in.max", f"{name}.pressure_in.min",
               f"{name}.flow_out.max", f"{name}.flow_in.mean"]
    # the switches' times move a tanh of width γ = 5 ms and the radius enters as R⁻¹²: plain
    # differences converge as h² (measured over steps 1e-3 … 1e-6) but reach 1e-6 of the
    # row's scale only near the rounding floor, so h and h/2 are extrapolated (Richardson)
    exact = _check_central(model, params, outputs,
                           lambda p: 1e-5 if p.endswith("_start") else 1e-4, richardson=True)
    # a stronger contraction raises the systolic chamber pressure
    row = exact.rows[f"{name}.pressure_in.max"]
    assert exact.jacobian[row, SPHERE_KEYS.index("max_active_stress")][0] > 0


def test_laws_adjoint_is_the_forward_jacobian() -> None:
    sphere, name = _sphere()
    cases = [(_heart(k), [f"vessels.lv.chamber.activation.{p}" for p in ACTIVATIONS[k]],
              OUTPUTS[:2]) for k in ACTIVATIONS]
    cases.append((sphere, [f"vessels.{name}.chamber_sphere.{k}" for k in SPHERE_KEYS],
                  [f"{name}.pressure_in.max", f"{name}.flow_in.mean"]))
    for model, params, outputs in cases:
        fwd = oxyline.sensitivities(model, params, outputs)
        adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
        assert_adjoint_is_forward(fwd, adj, params[0])


def test_two_hill_time_constant_is_recovered_from_synthetic_data() -> None:
    model = _heart("two-hill")
    path = "vessels.lv.chamber.activation.tau_1"
    x0 = _base_value(model, path)
    truth = native_model(model, [path], [1.15 * x0])
    outputs = ["lv.pressure_in.max", "aorta.pressure_out.max", "aortic.flow_in.mean"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    res = oxyline.calibrate(model, targets, [path], method="lm")
    assert res.success, res.report
    assert res.parameters[path] == pytest.approx(1.15 * x0, rel=1e-6)


def test_sphere_active_stress_is_recovered_from_synthetic_data() -> None:
    model, name = _sphere()
    path = f"vessels.{name}.chamber_sphere.max_active_stress"
    x0 = _base_value(model, path)
    truth = native_model(model, [path], [0.9 * x0])
    outputs = [f"{name}.pressure_in.max", f"{name}.flow_out.max"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    res = oxyline.calibrate(model, targets, [path], method="lm")
    assert res.success, res.report
    assert res.parameters[path] == pytest.approx(0.9 * x0, rel=1e-6)
    assert res.model["vessels"][[v["name"] for v in res.model["vessels"]].index(name)][
        "chamber_sphere"]["max_active_stress"] == pytest.approx(0.9 * x0, rel=1e-6)


@pytest.mark.parametrize(("path", "words"), [
    ("vessels.lv.chamber.activation.t_active", ["activation.t_active"]),
    ("vessels.lv.chamber_sphere.w1", ["'lv' is not a chamber_sphere"]),
])
def test_bad_law_paths_name_themselves(path: str, words: list[str]) -> None:
    with pytest.raises(ModelError) as err:
        oxyline.sensitivities(_heart("two-hill"), [path], ["lv.pressure_in.max"])
    for w in [path, *words]:
        assert w in str(err.value), (w, str(err.value))


def test_sphere_period_is_not_a_parameter() -> None:
    model, name = _sphere()
    path = f"vessels.{name}.chamber_sphere.period"
    with pytest.raises(ModelError, match="no differentiable value 'period'"):
        oxyline.sensitivities(model, [path], [f"{name}.pressure_in.max"])
