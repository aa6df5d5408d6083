"""Exact sensitivities of a tapered vessel's end radii (``vessels.<name>.radius_in``,
``.radius_out``), of the geometry of vessels with a viscoelastic wall (openBF's, as imported
openBF models have them) or with Womersley friction cells, and of lumped RCL vessels'
values (svZeroDSolver's BloodVessel, as every imported svZeroDSolver model has them).

* Against central differences of the same periodic runs, the models moved by the calibration's
  own ``native_model`` (relative step 1e-4: the outputs are smooth in every parameter, so the
  truncation O(h²) ≈ 1e-8 and the rounding of the periodic fixed points (1e-12 relative over
  a step of 1e-4: 1e-8) stay well below the 1e-6 of each output's largest derivative that
  tells a wrong derivative).
* The adjoint against the forward tangents (1e-8, ``assert_adjoint_is_forward``).
* A taper's outlet radius and an RCL vessel's resistance recovered from synthetic data
  (noise-free: 1e-6).
"""

from __future__ import annotations

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


def _tapered() -> dict[str, Any]:
    """A uniform parent into a tapered daughter (3 π segments) and a uniform one, RCR
    outlets, a two-harmonic inflow; generalized-α at 200 steps a cycle."""
    wall = {"wall_thickness": 5e-4, "youngs_modulus": 5e5}
    rcr = {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-9,
           "distal_resistance": 1.2e9}
    return {
        "name": "taper", "units": "SI", "period": 0.8,
        "vessels": [
            {"name": "parent", "from": "in", "to": "j", "length": 0.1, "radius": 0.004,
             "segments": 3, **wall},
            {"name": "d1", "from": "j", "to": "o1", "length": 0.08, "radius_in": 0.003,
             "radius_out": 0.0022, "segments": 3, "arrangement": "pi", **wall},
            {"name": "d2", "from": "j", "to": "o2", "length": 0.07, "radius": 0.0025,
             "segments": 2, **wall},
        ],
        "boundary_conditions": {
            "in": {"type": "flow", "fourier": {"mean": 5e-6, "cos": [3e-6, -1e-6],
                                               "sin": [4e-6, 1e-6], "period": 0.8}},
            "o1": dict(rcr), "o2": dict(rcr, distal_resistance=1.6e9),
        },
        "simulation": {"dt": 0.004, "method": "generalized-alpha"},
    }


def _svzerod_rcl() -> tuple[dict[str, Any], str]:
    """svZeroDSolver's pulsatileFlow_R_RCR converted (an RCL BloodVessel into an RCR), its
    vessel given a capacitance and an inductance so that all three values act."""
    model = svz.to_oxyline_dict(str(data_path("svzerod", "cases", "pulsatileFlow_R_RCR.json")))
    vessel = model["vessels"][0]
    assert vessel["arrangement"] == "RCL"
    vessel["lumped"].update(capacitance=2e-5, inductance=5.0)
    return model, vessel["name"]



TAPER_PARAMS = ["vessels.d1.radius_in", "vessels.d1.radius_out", "vessels.parent.radius_out"]
TAPER_OUTPUTS = ["parent.pressure_in.max", "parent.pressure_in.min", "d1.flow_out.mean",
                 "d1.pressure_out.pulse", "flow_split.d1.parent"]


def test_taper_end_radii_match_central_differences() -> None:
    exact = assert_sensitivities_are_central_differences(_tapered(), TAPER_PARAMS, TAPER_OUTPUTS)
    # a narrower outlet end raises the daughter's resistance: less of the flow goes there
    split = exact.rows["flow_split.d1.parent"]
    assert exact.jacobian[split, 1] > 0


def test_taper_adjoint_is_the_forward_jacobian() -> None:
    model = _tapered()
    fwd = oxyline.sensitivities(model, TAPER_PARAMS, TAPER_OUTPUTS)
    adj = oxyline.sensitivities(model, TAPER_PARAMS, TAPER_OUTPUTS, mode="adjoint")
    assert_adjoint_is_forward(fwd, adj)


def test_rcl_vessel_values_match_central_differences() -> None:
    model, vessel = _svzerod_rcl()
    params = [f"vessels.{vessel}.lumped.{k}" for k in ("resistance", "capacitance",
                                                       "inductance")] + ["scale.resistance"]
    outputs = [f"{vessel}.pressure_in.max", f"{vessel}.pressure_in.min",
               f"{vessel}.pressure_out.mean", f"{vessel}.flow_out.pulse"]
    exact = assert_sensitivities_are_central_differences(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)


def test_taper_and_rcl_values_are_recovered_from_synthetic_data() -> None:
    """The daughter's outlet radius 0.9× and the svZeroDSolver vessel's resistance 1.4× the
    model's, fitted from the model's values (noise-free: exact)."""
    model = _tapered()
    path = "vessels.d1.radius_out"
    truth = native_model(model, [path], [0.9 * 0.0022])
    outputs = ["flow_split.d1.parent", "parent.pressure_in.max"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    res = oxyline.calibrate(model, targets, [path], method="lm")
    assert res.success, res.report
    assert res.parameters[path] == pytest.approx(0.9 * 0.0022, rel=1e-6)
    d1 = next(v for v in res.model["vessels"] if v["name"] == "d1")
    assert (d1["radius_in"], d1["radius_out"]) == pytest.approx((0.003, 0.9 * 0.0022),
                                                                rel=1e-6)

    model, vessel = _svzerod_rcl()
    path = f"vessels.{vessel}.lumped.resistance"
    r0 = _base_value(model, path)
    truth = native_model(model, [path], [1.4 * r0])
    outputs = [f"{vessel}.pressure_in.mean"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {outputs[0]: {"value": measured[0], "sigma": 0.01 * abs(measured[0])}}
    res = oxyline.calibrate(model, targets, [path], method="lm")
    assert res.success, res.report
    assert res.parameters[path] == pytest.approx(1.4 * r0, rel=1e-6)


def test_geometry_the_tangent_leaves_out_is_refused_naming_it() -> None:
    """A tapered vessel's one radius (its end radii are the parameters)."""
    with pytest.raises(ModelError, match="parameter 'vessels.d1.radius'.*radius_in"):
        oxyline.sensitivities(_tapered(), ["vessels.d1.radius"], ["d1.flow_out.mean"])


@pytest.mark.parametrize("friction", ["poiseuille", "womersley"])
def test_thick_wall_radii_match_central_differences(friction: str) -> None:
    """The thick (Lamé) wall model: its compliance is no power law of the radius, so a
    radius and the end radii take each segment's quadrature's own slopes (with and without
    Womersley friction cells); against central differences and the adjoint."""
    model = _tapered()
    model["wall_model"] = "thick"
    model["wall_friction"] = friction
    params = ["vessels.parent.radius", "vessels.d1.radius_in", "vessels.d1.radius_out",
              "vessels.d2.radius"]
    exact = assert_sensitivities_are_central_differences(model, params, TAPER_OUTPUTS)
    adj = oxyline.sensitivities(model, params, TAPER_OUTPUTS, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)


def _womersley() -> dict[str, Any]:
    """``_tapered`` with Womersley friction cells on every vessel (the model's
    ``wall_friction``): three R‖L cells in series with each segment's flow, their values
    following the segment's Poiseuille R₀ and flat-profile L₀ (at these radii no cell's pole
    is folded into the series inertance; the core's tests cover folded cells)."""
    model = _tapered()
    model["wall_friction"] = "womersley"
    return model


WOMERSLEY_PARAMS = ["vessels.parent.radius", "vessels.parent.length",
                    "vessels.d1.radius_in", "vessels.d1.radius_out",
                    "vessels.d1.youngs_modulus", "vessels.d2.radius", "vessels.d2.length"]


def test_womersley_geometry_matches_central_differences() -> None:
    """The radius, end radii, length and stiffness of vessels with Womersley friction
    cells against central differences of whole periodic runs; the adjoint against the
    forward tangents."""
    model = _womersley()
    exact = assert_sensitivities_are_central_differences(model, WOMERSLEY_PARAMS,
                                                         TAPER_OUTPUTS)
    adj = oxyline.sensitivities(model, WOMERSLEY_PARAMS, TAPER_OUTPUTS, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)


def test_lumped_womersley_values_match_central_differences() -> None:
    """A lumped daughter in two segments under the model's ``wall_friction: womersley``
    carries cells that follow its R and L (each segment's R/2 and L/2): its R and L and
    ``scale.resistance``, against central differences and the adjoint."""
    model = _womersley()
    model["vessels"][2] = {"name": "d2", "from": "j", "to": "o2", "segments": 2,
                           "lumped": {"resistance": 3e7, "inductance": 5e6,
                                      "capacitance": 2e-10}}
    params = ["vessels.d2.lumped.resistance", "vessels.d2.lumped.inductance",
              "scale.resistance"]
    outputs = ["parent.pressure_in.max", "d2.flow_in.pulse", "d2.pressure_out.min",
               "flow_split.d1.parent"]
    exact = assert_sensitivities_are_central_differences(model, params, outputs)
    adj = oxyline.sensitivities(model, params, outputs, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)


def test_womersley_radius_is_recovered_from_synthetic_data() -> None:
    """The Womersley daughter's outlet radius 0.9× the model's, fitted from the model's
    values (noise-free: exact)."""
    model = _womersley()
    path = "vessels.d1.radius_out"
    truth = native_model(model, [path], [0.9 * 0.0022])
    outputs = ["flow_split.d1.parent", "parent.pressure_in.max"]
    measured = oxyline.sensitivities(truth, [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)}
               for o, v in zip(outputs, measured, strict=True)}
    res = oxyline.calibrate(model, targets, [path], method="lm")
    assert res.success, res.report
    assert res.parameters[path] == pytest.approx(0.9 * 0.0022, rel=1e-6)


VISCOELASTIC_PARAMS = ["vessels.parent.radius", "vessels.parent.youngs_modulus",
                       "vessels.d1.radius_out", "vessels.d1.length", "vessels.d2.radius",
                       "vessels.d2.youngs_modulus"]


def _viscoelastic() -> dict[str, Any]:
    """``_tapered`` with Kelvin-Voigt walls on the parent (η/E = 2 ms, π arrangement) and the
    tapered daughter (6 ms, π), the other daughter elastic: the junction's wall mixes the
    parent's and d1's relaxation times and holds d2's capacitance share too."""
    model = _tapered()
    model["vessels"][0]["wall_viscosity"] = 1e3
    model["vessels"][0]["arrangement"] = "pi"
    model["vessels"][1]["wall_viscosity"] = 3e3
    return model


def test_viscoelastic_geometry_matches_central_differences() -> None:
    """The radius, taper end, length and stiffness of vessels with a viscoelastic wall (a
    capacitance at the wall's elastic pressure behind R_v = τ/C, both moving with the
    parameter) and of an elastic vessel at their junction, against central differences; the
    adjoint against the forward tangents."""
    model = _viscoelastic()
    exact = assert_sensitivities_are_central_differences(model, VISCOELASTIC_PARAMS,
                                                         TAPER_OUTPUTS)
    adj = oxyline.sensitivities(model, VISCOELASTIC_PARAMS, TAPER_OUTPUTS, mode="adjoint")
    assert_adjoint_is_forward(exact, adj)


def test_viscoelastic_openbf_model_geometry_matches_central_differences() -> None:
    """openBF's bifurcation (Boileau 2015) read with openBF's viscoelastic wall on every
    vessel (a tapered parent): its end radii and stiffness and a daughter's length and
    stiffness, against central differences."""
    from oxyline.io.openbf import to_native_dict

    model = to_native_dict(data_path("openbf", "models", "boileau2015", "ibif", "ibif.yaml"),
                           viscoelastic=True)
    assert all(v["wall_viscosity"] > 0 for v in model["vessels"])
    params = ["vessels.parent.radius_in", "vessels.parent.radius_out",
              "vessels.parent.youngs_modulus", "vessels.d1.length", "vessels.d1.youngs_modulus"]
    outputs = ["parent.pressure_in.max", "parent.pressure_in.min", "d1.flow_out.pulse",
               "d1.pressure_out.pulse"]
    assert_sensitivities_are_central_differences(model, params, outputs)


def test_scales_on_viscoelastic_walls_and_womersley_vessels() -> None:
    """``scale.compliance`` divides a viscoelastic wall's E by the factor (its capacitance,
    held at the wall's elastic pressure, and its relaxation time η/E move alike; R_v = τ/C
    stays); neither scale touches the friction cells of a vessel given by its geometry."""
    model = _tapered()
    for v, eta in zip(model["vessels"], (1e3, 3e3, 2e3), strict=True):
        v["wall_viscosity"] = eta
    outputs = ["parent.pressure_in.max", "parent.pressure_in.min", "d1.flow_out.pulse"]
    assert_sensitivities_are_central_differences(model, ["scale.compliance",
                                                         "scale.resistance"], outputs)
    model = _tapered()
    model["wall_friction"] = "womersley"
    assert_sensitivities_are_central_differences(model, ["scale.compliance",
                                                         "scale.resistance"], outputs)
