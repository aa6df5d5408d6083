"""The adjoint of oxygen outputs by oxygen parameters (``oxyline.sensitivities(...,
mode="adjoint")``): one backward sweep of the species transport per output row.

* Against the forward tangents (stepped forwards; the adjoint transposes each step) for
  every oxygen parameter kind × the outlet PO2 and saturation, SvO2, the wall uptake of a
  vessel, a region and the network: both iterate to a periodic change of 1e-12, so they
  agree to ~1e-11 of a row's scale; 1e-8 tells a wrong transpose.
* Against central differences of whole periodic runs for the mass-transfer k and P50
  (relative step 1e-4: truncation and rounding below 1e-7 of the derivative).
* What the oxygen adjoint does not follow is refused by name: flow parameters beside
  oxygen (forward tangents), a shear-dependent (Lévêque) wall; flow outputs beside oxygen
  parameters get zero rows.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from test_sensitivity_o2 import OUTPUTS, Y, consuming, per_vessel, values

import oxyline
from oxyline import CalibrationError, ModelError
from oxyline.calibrate import _base_value, native_model

pytest.importorskip("scipy")


@pytest.mark.parametrize(("model", "paths"), [
    (Y, ["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50"]),
    (consuming(), ["oxygen.wall.flux", "oxygen.hill.p50"]),
    (per_vessel(), ["oxygen.per_vessel.d1.wall.k", "oxygen.per_vessel.d1.wall.po2",
                    "oxygen.wall.k", "oxygen.wall.po2"]),
])
def test_adjoint_equals_forward(model: dict[str, Any], paths: list[str]) -> None:
    fwd = oxyline.sensitivities(model, paths, OUTPUTS)
    adj = oxyline.sensitivities(model, paths, OUTPUTS, mode="adjoint")
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-10)
    # d/d log θ, each row against its largest entry
    a = adj.jacobian * adj.parameter_values
    f = fwd.jacobian * fwd.parameter_values
    scale = np.abs(f).max(axis=1, keepdims=True)
    assert np.all(scale > 0)
    assert np.all(np.abs(a - f) <= 1e-8 * scale), np.abs(a - f) / scale


@pytest.mark.parametrize("path", ["oxygen.wall.k", "oxygen.hill.p50"])
def test_adjoint_against_central_differences(path: str) -> None:
    outputs = ["d1.po2_out.mean", "SvO2.d1", "VO2", "parent.wall_uptake.mean"]
    s = oxyline.sensitivities(Y, [path], outputs, mode="adjoint")
    x0, h = _base_value(Y, path), 1e-4
    up = values(native_model(Y, [path], [x0 * (1 + h)]), outputs)
    down = values(native_model(Y, [path], [x0 * (1 - h)]), outputs)
    fd = (up - down) / (2 * h)
    exact = s.jacobian[:, 0] * s.parameter_values[0]
    assert np.all(np.abs(fd) > 1e-9 * np.abs(s.values)), fd
    np.testing.assert_allclose(exact, fd, rtol=1e-6)


def test_flow_parameters_are_refused_by_name() -> None:
    with pytest.raises(CalibrationError, match=r"scale\.inflow"):
        oxyline.sensitivities(Y, ["oxygen.wall.k", "scale.inflow"], ["VO2"], mode="adjoint")


def test_flow_outputs_beside_oxygen_get_zero_rows() -> None:
    outputs = ["parent.pressure_in.mean", "SvO2.d1"]
    adj = oxyline.sensitivities(Y, ["oxygen.wall.k"], outputs, mode="adjoint")
    fwd = oxyline.sensitivities(Y, ["oxygen.wall.k"], outputs)
    assert adj.jacobian[0, 0] == 0.0
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-10)
    np.testing.assert_allclose(adj.jacobian[1], fwd.jacobian[1], rtol=1e-8)


def test_a_shear_dependent_wall_is_refused_by_name() -> None:
    leveque = {"wall": {"model": "leveque", "po2": 40.0, "shear": "instantaneous"}}
    m = {**Y, "oxygen": {**Y["oxygen"], "per_vessel": {"d2": leveque}}}
    with pytest.raises(ModelError, match="shear-dependent"):
        oxyline.sensitivities(m, ["oxygen.wall.k"], ["SvO2.d1"], mode="adjoint")
