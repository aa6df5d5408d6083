"""Exact sensitivities of heart chambers and valves (``oxyline.sensitivities``).

* Chamber elastances, rest volumes and activation timing, and valve coefficients, against
  central differences of the same periodic runs (relative step 1e-4, 1e-5 for the timing,
  whose activation is C¹ but not C² in it: truncation and rounding well below 1e-6 of the
  derivative, so 1e-6 relative tells a wrong derivative).
* The adjoint against the forward tangents (1e-8: only the fixed points' tolerance and
  rounding separate them).
* A chamber's maximal elastance and a valve's open resistance recovered from synthetic data.
* Paths that name nothing differentiable are ModelErrors naming the path (the closed-loop
  heart block: tests/test_sensitivity_heart_loop.py).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import ModelError
from oxyline.calibrate import _base_value, native_model
from tests.conftest import assert_adjoint_is_forward

pytest.importorskip("scipy")

T = 0.8  # s
VALVE = {"law": "tanh", "min_resistance": 3e6, "max_resistance": 1e10, "steepness": 5e-3}

#: a left heart between a venous pressure and a Windkessel (SI): tanh valves switching over
#: ~1/k = 200 Pa, an elastance-inductor chamber with a half-cosine activation
HEART: dict[str, Any] = {
    "name": "left-heart", "units": "SI", "period": T,
    "vessels": [
        {"name": "mitral", "from": "ven", "to": "mv_out", "valve": dict(VALVE)},
        {"name": "lv", "from": "mv_out", "to": "lv_out", "chamber": {
            "law": "elastance-inductor", "max_elastance": 3.0e8, "min_elastance": 1.3e7,
            "rest_volume_diastole": 2e-5, "rest_volume_systole": 1e-5, "period": T,
            "inductance": 1e5, "initial_volume": 1.2e-4,
            "activation": {"kind": "half-cosine", "t_active": 0.1, "t_twitch": 0.35}}},
        {"name": "aortic", "from": "lv_out", "to": "ao", "valve": dict(VALVE)},
        {"name": "aorta", "from": "ao", "to": "out",
         "lumped": {"resistance": 5e6, "inductance": 1e5, "capacitance": 3e-9}},
    ],
    "boundary_conditions": {
        "ven": {"type": "pressure", "value": 1200.0},
        "out": {"type": "rcr", "proximal_resistance": 1e7, "capacitance": 1.2e-8,
                "distal_resistance": 1.3e8},
    },
    "simulation": {"dt": 0.004, "method": "generalized-alpha"},
}

PARAMETERS = ["vessels.lv.chamber.max_elastance", "vessels.lv.chamber.min_elastance",
              "vessels.lv.chamber.rest_volume_diastole",
              "vessels.lv.chamber.activation.t_active",
              "vessels.lv.chamber.activation.t_twitch",
              "vessels.aortic.valve.min_resistance", "vessels.aortic.valve.max_resistance",
              "vessels.aortic.valve.steepness", "vessels.mitral.valve.min_resistance"]
OUTPUTS = ["lv.pressure_in.max", "lv.pressure_in.min", "aortic.flow_in.mean",
           "aorta.pressure_out.mean", "aorta.pressure_out.pulse", "mitral.flow_in.max"]


def test_heart_jacobian_matches_central_differences() -> None:
    exact = oxyline.sensitivities(HEART, PARAMETERS, OUTPUTS)
    assert exact.periodic_change <= 1e-11
    scale = np.abs(exact.jacobian * exact.parameter_values).max(axis=1)
    assert (scale > 0).all()
    for k, path in enumerate(PARAMETERS):
        x0 = _base_value(HEART, path)
        assert exact.parameter_values[k] == x0
        h = 1e-5 if ".activation." in path else 1e-4
        up, down = (oxyline.sensitivities(native_model(HEART, [path], [x0 * f]), [],
                                          OUTPUTS).values for f in (1 + h, 1 - h))
        err = np.abs(exact.jacobian[:, k] - (up - down) / (2 * h * x0)) * x0
        assert (err <= 1e-6 * scale).all(), (path, err / scale)
    rows = exact.rows
    # a stiffer contracting ventricle ejects more and raises the systolic pressure
    e_max = PARAMETERS.index("vessels.lv.chamber.max_elastance")
    assert exact.jacobian[rows["aortic.flow_in.mean"], e_max][0] > 0
    assert exact.jacobian[rows["lv.pressure_in.max"], e_max][0] > 0


def test_heart_adjoint_is_the_forward_jacobian() -> None:
    params = PARAMETERS + ["boundary_conditions.out.distal_resistance"]
    fwd = oxyline.sensitivities(HEART, params, OUTPUTS)
    adj = oxyline.sensitivities(HEART, params, OUTPUTS, mode="adjoint")
    assert_adjoint_is_forward(fwd, adj)


def test_heart_parameters_are_recovered_from_synthetic_data() -> None:
    """Pressures and flows of the heart with E_max = 2.6e8 and the aortic valve's open
    resistance 4.5e6, fitted from the model's 3.0e8 and 3e6 (noise-free: exact)."""
    truth = copy.deepcopy(HEART)
    truth["vessels"][1]["chamber"]["max_elastance"] = 2.6e8
    truth["vessels"][2]["valve"]["min_resistance"] = 4.5e6
    outputs = ["lv.pressure_in.max", "aorta.pressure_out.max", "aorta.pressure_out.min",
               "aortic.flow_in.mean"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    params = ["vessels.lv.chamber.max_elastance", "vessels.aortic.valve.min_resistance"]
    res = oxyline.calibrate(HEART, targets, params, method="lm")
    assert res.success, res.report
    assert res.parameters[params[0]] == pytest.approx(2.6e8, rel=1e-6)
    assert res.parameters[params[1]] == pytest.approx(4.5e6, rel=1e-6)
    assert res.model["vessels"][1]["chamber"]["max_elastance"] == pytest.approx(2.6e8, rel=1e-6)


@pytest.mark.parametrize(("path", "words"), [
    ("vessels.lv.chamber.passive_elastance", ["vessels.lv.chamber.passive_elastance",
                                              "no differentiable value 'passive_elastance'"]),
    ("vessels.lv.chamber.activation.t_shift", ["activation.t_shift"]),
    ("vessels.aorta.valve.min_resistance", ["vessels.aorta.valve.min_resistance",
                                            "'aorta' is not a valve"]),
    ("vessels.mitral.valve.width", ["vessels.mitral.valve.width", "'width'"]),
    ("vessels.rv.chamber.max_elastance", ["vessels.rv.chamber.max_elastance",
                                          "no vessel named 'rv'"]),
])
def test_bad_heart_paths_name_themselves(path: str, words: list[str]) -> None:
    with pytest.raises(ModelError) as err:
        oxyline.sensitivities(HEART, [path], ["lv.pressure_in.max"])
    for w in words:
        assert w in str(err.value), (w, str(err.value))
