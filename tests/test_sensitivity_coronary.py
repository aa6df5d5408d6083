"""Exact sensitivities of coronary outlets (``oxyline.sensitivities``, svZeroDSolver's
``CORONARY``): R_a, R_am, R_v, C_a, C_im and the intramyocardial pressure's factor.

* Against central differences of the same periodic runs (relative step 1e-4: the outputs are
  smooth in every parameter, so the truncation O(h²) ≈ 1e-8 and the rounding of the periodic
  fixed points (1e-12 relative over a step of 1e-4: 1e-8) stay well below the 1e-6 of the
  largest derivative of each output that tells a wrong derivative).
* The adjoint against the forward tangents (1e-8).
* The microvascular resistance and the intramyocardial pressure's factor recovered from
  synthetic data (noise-free: 1e-6).
* Through a varying microvascular resistance (``CORONARY_VAR_RES``): the bed's values, the
  varying resistance's own R_min and R_max included, against central differences and the
  adjoint; a law with a zero end is refused naming the parameter. The law's contraction
  and relaxation times likewise; its cycle period is refused by name.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

import oxyline
from oxyline import ModelError
from oxyline import svzerod as svz
from oxyline.calibrate import native_model
from tests.conftest import (
    assert_adjoint_is_forward,
    assert_sensitivities_are_central_differences,
    data_path,
)

pytest.importorskip("scipy")

KEYS = ["arterial_resistance", "microvascular_resistance", "venous_resistance",
        "arterial_capacitance", "intramyocardial_capacitance"]


def _svzerod_case(name: str) -> tuple[dict[str, Any], str, str]:
    """svZeroDSolver's case converted: the model, its coronary node and its vessel."""
    model = svz.to_oxyline_dict(str(data_path("svzerod", "cases", name)))
    node = next(n for n, bc in model["boundary_conditions"].items()
                if bc.get("type") == "coronary")
    return model, node, model["vessels"][0]["name"]


def _curved_coronary() -> dict[str, Any]:
    """The packaged paper-curved-coronary example (svZeroDSolver's LCA bed under a Fourier
    intramyocardial pressure) without its oxygen set-up, on generalized-α."""
    path = Path(oxyline.__file__).parent / "examples" / "paper-curved-coronary.yaml"
    model = yaml.safe_load(path.read_text())
    model.pop("oxygen")
    model["simulation"] = {"dt": 2e-3, "method": "generalized-alpha"}
    return model



def test_svzerod_coronary_jacobian_matches_central_differences() -> None:
    model, node, vessel = _svzerod_case("pulsatileFlow_R_coronary.json")
    params = [f"boundary_conditions.{node}.{k}" for k in KEYS] + ["scale.resistance",
                                                                   "scale.compliance"]
    outputs = [f"{vessel}.pressure_in.max", f"{vessel}.pressure_in.min",
               f"{vessel}.pressure_out.mean", f"{vessel}.pressure_out.pulse"]
    exact = assert_sensitivities_are_central_differences(model, params, outputs)
    # the mean pressure is the inflow's mean through R_a + R_am + R_v: each adds to it
    mean = exact.rows[f"{vessel}.pressure_out.mean"]
    assert (exact.jacobian[mean, :3] > 0).all()


def test_intramyocardial_pressure_factor_matches_central_differences() -> None:
    model = _curved_coronary()
    params = ["boundary_conditions.outlet.intramyocardial_pressure.scale",
              "boundary_conditions.outlet.microvascular_resistance",
              "boundary_conditions.outlet.intramyocardial_capacitance"]
    outputs = ["coronary.flow_out.max", "coronary.flow_out.min", "coronary.flow_in.mean",
               "coronary.pressure_out.pulse"]
    exact = assert_sensitivities_are_central_differences(model, params, outputs)
    # squeezing harder lowers the systolic outflow of the bed's inlet vessel
    assert exact.jacobian[exact.rows["coronary.flow_out.min"], 0][0] < 0


def test_coronary_adjoint_is_the_forward_jacobian() -> None:
    model = _curved_coronary()
    params = [f"boundary_conditions.outlet.{k}" for k in KEYS] + [
        "boundary_conditions.outlet.intramyocardial_pressure.scale"]
    outputs = ["coronary.flow_out.max", "coronary.pressure_out.mean"]
    fwd = oxyline.sensitivities(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    assert_adjoint_is_forward(fwd, adj)


def test_coronary_parameters_are_recovered_from_synthetic_data() -> None:
    """Flows and pressures of the bed with R_am 1.3× and the intramyocardial pressure 0.8×
    the model's, fitted from the model's values (noise-free: exact)."""
    model = _curved_coronary()
    params = ["boundary_conditions.outlet.microvascular_resistance",
              "boundary_conditions.outlet.intramyocardial_pressure.scale"]
    r_am = float(model["boundary_conditions"]["outlet"]["microvascular_resistance"])
    truth = native_model(model, params, [1.3 * r_am, 0.8])
    outputs = ["coronary.flow_out.max", "coronary.flow_out.min", "coronary.flow_in.mean"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    res = oxyline.calibrate(model, targets, params, method="lm")
    assert res.success, res.report
    assert res.parameters[params[0]] == pytest.approx(1.3 * r_am, rel=1e-6)
    assert res.parameters[params[1]] == pytest.approx(0.8, rel=1e-6)
    bc = res.model["boundary_conditions"]["outlet"]
    assert bc["microvascular_resistance"] == pytest.approx(1.3 * r_am, rel=1e-6)
    pim = model["boundary_conditions"]["outlet"]["intramyocardial_pressure"]["fourier"]
    assert bc["intramyocardial_pressure"]["fourier"]["mean"] == pytest.approx(
        0.8 * pim["mean"], rel=1e-6)


def test_through_a_varying_microvascular_resistance() -> None:
    """svZeroDSolver's pulsatileFlow_R_coronary_varres: the bed's microvascular resistance
    follows the contraction law R(t) (R_min 50 to R_max 200), which joins each step's matrix
    of the tangent and the adjoint; R_min and R_max move R(t) by the law's slopes at each
    step. The bed's values and the vessel's, against central differences and the adjoint; a
    law with a zero end (whose square roots have no derivative there) is refused."""
    model, node, vessel = _svzerod_case("pulsatileFlow_R_coronary_varres.json")
    params = [f"boundary_conditions.{node}.{k}" for k in KEYS]
    params += [f"boundary_conditions.{node}.microvascular_resistance_max",
               f"vessels.{vessel}.lumped.resistance"]
    outputs = [f"{vessel}.pressure_in.max", f"{vessel}.pressure_in.min",
               f"{vessel}.pressure_out.mean", f"{vessel}.pressure_out.pulse"]
    exact = assert_sensitivities_are_central_differences(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)
    model["boundary_conditions"][node]["microvascular_resistance"] = 0.0
    path = f"boundary_conditions.{node}.microvascular_resistance_max"
    with pytest.raises(ModelError, match=f"parameter '{path}'.*varying microvascular resistance"):
        oxyline.sensitivities(model, [path], [f"{vessel}.pressure_in.mean"])


def test_through_the_contraction_laws_times() -> None:
    """The same case's contraction and relaxation times (T_vc, T_vr): R(t) moves by the law's
    slope by each time at every step (zero at the phase ends, so the periodic outputs are
    smooth in them), against central differences and the adjoint; the law's cycle_period
    (which must repeat with the model's cycle) is refused naming it."""
    model, node, vessel = _svzerod_case("pulsatileFlow_R_coronary_varres.json")
    params = [f"boundary_conditions.{node}.{k}" for k in ("contraction_time",
                                                           "relaxation_time")]
    outputs = [f"{vessel}.pressure_in.max", f"{vessel}.pressure_in.min",
               f"{vessel}.pressure_out.mean", f"{vessel}.pressure_out.pulse"]
    exact = assert_sensitivities_are_central_differences(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)
    model["boundary_conditions"][node]["cycle_period"] = model["period"]
    path = f"boundary_conditions.{node}.cycle_period"
    with pytest.raises(ModelError, match=f"parameter '{path}'.*cycle_period is not"):
        oxyline.sensitivities(model, [path], [f"{vessel}.pressure_in.mean"])


@pytest.mark.parametrize(("key", "words"), [
    ("pressure", ["no differentiable value 'pressure'"]),
    ("capacitance", ["no differentiable value 'capacitance'"]),
])
def test_bad_coronary_paths_name_themselves(key: str, words: list[str]) -> None:
    model = copy.deepcopy(_curved_coronary())
    path = f"boundary_conditions.outlet.{key}"
    with pytest.raises(ModelError) as err:
        oxyline.sensitivities(model, [path], ["coronary.flow_in.mean"])
    for w in [path, *words]:
        assert w in str(err.value), (w, str(err.value))
