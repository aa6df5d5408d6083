"""Exact sensitivities through svZeroDSolver-form stenoses (``stenosis_form: svzerod``: the
capacitor row of a BloodVessel with C and a stenosis written by the chain rule on its inlet
pressure, as svZeroDSolver's generalized-α does; docs/svzerod.md, "C + stenosis").

* Against central differences of whole periodic runs, the models moved by the calibration's
  own ``native_model`` (``assert_sensitivities_are_central_differences``: relative step 1e-4,
  1e-6 of each output's largest response to a 100 % change; the differences' truncation and
  rounding sit near 1e-8 there).
* The adjoint against the forward tangents (1e-8, ``assert_adjoint_is_forward``).
* The stenosis coefficient recovered from synthetic data (noise-free: 1e-6).
* Where the form switches (a zero coefficient next to a capacitor), the derivative is refused
  naming the parameter.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

import oxyline
from oxyline import ModelError
from oxyline import svzerod as svz
from oxyline.calibrate import _base_value, native_model
from tests.conftest import (
    assert_adjoint_is_forward,
    assert_sensitivities_are_central_differences,
    data_path,
)

pytest.importorskip("scipy")


def _stenosed(coefficient: float = 20.0) -> tuple[dict[str, Any], str]:
    """svZeroDSolver's pulsatileFlow_R_RCR (a BloodVessel into an RCR, inflow up to 4.7 cm³/s)
    with the vessel given C, L and a stenosis (cgs): S Q² at peak flow ≈ its R Q, so the
    nonlinear term acts as much as the linear one. The reader writes the svZeroDSolver form."""
    path = data_path("svzerod", "cases", "pulsatileFlow_R_RCR.json")
    config = json.loads(path.read_text())
    values = config["vessels"][0]["zero_d_element_values"]
    values.update(C=2e-5, L=5.0, stenosis_coefficient=coefficient)
    model = svz.to_oxyline_dict(config)
    vessel = model["vessels"][0]
    assert vessel["lumped"]["stenosis_form"] == "svzerod"
    return model, vessel["name"]


def _params(vessel: str) -> list[str]:
    keys = ("stenosis_coefficient", "resistance", "capacitance", "inductance")
    return [f"vessels.{vessel}.lumped.{k}" for k in keys] + [
        "scale.resistance", "scale.compliance", "boundary_conditions.OUT.distal_resistance"]


def _outputs(vessel: str) -> list[str]:
    return [f"{vessel}.pressure_in.max", f"{vessel}.pressure_in.min",
            f"{vessel}.pressure_out.pulse", f"{vessel}.flow_out.max"]


def test_svzerod_form_stenosis_matches_central_differences() -> None:
    model, vessel = _stenosed()
    exact = assert_sensitivities_are_central_differences(model, _params(vessel),
                                                         _outputs(vessel))
    # a tighter stenosis raises the inlet's systolic pressure
    assert exact.jacobian[exact.rows[f"{vessel}.pressure_in.max"], 0] > 0


def test_svzerod_form_adjoint_is_the_forward_jacobian() -> None:
    model, vessel = _stenosed()
    params, outputs = _params(vessel), _outputs(vessel)
    fwd = oxyline.sensitivities(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    assert_adjoint_is_forward(fwd, adj)


def test_svzerod_form_stenosis_coefficient_is_recovered_from_synthetic_data() -> None:
    """The coefficient 1.5× the model's, fitted from the model's inlet pressure (noise-free)."""
    model, vessel = _stenosed()
    path = f"vessels.{vessel}.lumped.stenosis_coefficient"
    s0 = _base_value(model, path)
    truth = native_model(model, [path], [1.5 * s0])
    outputs = [f"{vessel}.pressure_in.max", f"{vessel}.pressure_in.min"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    res = oxyline.calibrate(model, targets, [path], method="lm")
    assert res.success, res.report
    assert res.parameters[path] == pytest.approx(1.5 * s0, rel=1e-6)
    lumped = res.model["vessels"][0]["lumped"]
    assert lumped["stenosis_form"] == "svzerod"


def test_svzerod_form_at_zero_coefficient_is_refused_naming_it() -> None:
    model, vessel = _stenosed()
    model["vessels"][0]["lumped"]["stenosis_coefficient"] = 0.0
    path = f"vessels.{vessel}.lumped.stenosis_coefficient"
    with pytest.raises(ModelError, match=f"parameter '{path}'.*svzerod"):
        oxyline.sensitivities(model, [path], [f"{vessel}.pressure_in.max"])
