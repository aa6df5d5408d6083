"""Oxygen sensitivities and svZeroDSolver-form stenoses (``stenosis_form: svzerod``: the
capacitor row of an RCL vessel with C and a stenosis written by the chain rule on its inlet
pressure, docs/svzerod.md, "C + stenosis").

That form exists only where the vessel has both a stenosis and a capacitance, and the
species transport refuses a lumped capacitance (it has no lumen volume to conserve the
oxygen in): an oxygen model with an svZeroDSolver-form stenosis is refused at load, naming
the vessel, and so are its sensitivities. The stenosed RCL vessel an oxygen model can have
(C = 0: its R + S|Q| and L carry the oxygen without volume, whatever its form) is
differentiated through the flow's tangent:

* the oxygen outputs by its S, R and L and by an oxygen parameter against central
  differences of whole periodic runs (relative step 1e-4; the outputs carry ~1e-12 of their
  value in rounding, so the quotient is judged to 1e-6 of itself plus that rounding over h,
  as tests/test_sensitivity_o2.py);
* the adjoint against the forward tangents (1e-8 of each output's largest derivative).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import ModelError
from tests.test_sensitivity_o2 import Y, central_differences

pytest.importorskip("scipy")

#: the stenosed vessel's lumped values (SI): S |Q| at d1's peak flow (~3e-6 m³/s) about R,
#: so the nonlinear term acts as much as the linear one; L = ρ l/(π r²) of a 3 cm narrowing
#: of 1 mm radius, so that L moves the oxygen outputs well above their rounding
STENOSIS = {"resistance": 1e8, "inductance": 1e7, "stenosis_coefficient": 3e13,
            "stenosis_form": "svzerod"}
OUTPUTS = ["d1.po2_out.mean", "d1.saturation_out.min", "SvO2.d1", "VO2", "VO2.parent.d1",
           "s.flow_out.max"]
PATHS = [f"vessels.s.lumped.{k}" for k in ("stenosis_coefficient", "resistance",
                                          "inductance")]


def stenosed(capacitance: float = 0.0) -> dict[str, Any]:
    """:data:`Y` with a stenosed RCL vessel between the junction and d1."""
    m = copy.deepcopy(Y)
    d1 = next(v for v in m["vessels"] if v["name"] == "d1")
    d1["from"] = "k"
    lumped = dict(STENOSIS, capacitance=capacitance)
    m["vessels"].insert(1, {"name": "s", "from": "j", "to": "k", "arrangement": "RCL",
                            "lumped": lumped})
    return m


def test_an_svzerod_form_stenosis_with_oxygen_is_refused_naming_the_vessel() -> None:
    """C = 2e-11 m³/Pa makes the form apply; the transport has no volume for it."""
    model = stenosed(capacitance=2e-11)
    with pytest.raises(ModelError, match="vessel 's'.*no lumen volume"):
        oxyline.load_model(model)
    with pytest.raises(ModelError, match="vessel 's'.*no lumen volume"):
        oxyline.sensitivities(model, PATHS[:1], OUTPUTS[:1])
    # without oxygen the same vessel is the svZeroDSolver form's and is differentiated
    flow_only = copy.deepcopy(model)
    flow_only.pop("oxygen")
    s = oxyline.sensitivities(flow_only, PATHS[:1], ["s.flow_out.max"])
    assert np.isfinite(s.jacobian).all()


@pytest.mark.parametrize("path", [*PATHS, "oxygen.wall.k"])
def test_oxygen_outputs_through_a_stenosis_against_central_differences(path: str) -> None:
    model = stenosed()
    s = oxyline.sensitivities(model, [path], OUTPUTS)
    fd = central_differences(model, path, OUTPUTS)
    exact = s.jacobian[:, 0] * s.parameter_values[0]
    rounding = 1e-12 * np.abs(s.values) / 1e-4
    # the check reaches the oxygen outputs: at least two move 1e3 x their rounding
    oxygen = np.abs(fd[:-1]) > 1e3 * rounding[:-1]
    assert oxygen.sum() >= 2, (path, fd)
    err = np.abs(exact - fd)
    assert np.all(err <= 1e-6 * np.abs(fd) + rounding), (path, err / np.abs(fd))


def test_oxygen_adjoint_through_a_stenosis_is_the_forward_jacobian() -> None:
    model = stenosed()
    paths = [*PATHS, "oxygen.wall.k", "oxygen.hill.p50"]
    outputs = OUTPUTS[:-1]
    f = oxyline.sensitivities(model, paths, outputs).jacobian
    a = oxyline.sensitivities(model, paths, outputs, mode="adjoint").jacobian
    scale = np.abs(f).max(axis=1, keepdims=True)
    assert np.all(scale > 0)
    assert np.all(np.abs(a - f) <= 1e-8 * scale), np.abs(a - f) / scale
