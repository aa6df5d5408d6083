"""Exact sensitivities of svZeroDSolver's closed-loop heart block (``heart_pulmonary``).

The block's on/off valves reset a closed valve's flow to zero at every Newton correction, so
a converged step's flow there is zero whatever the parameters: its tangent row is zero
(``sensitivity/tangent.rs``), and the adjoint zeroes the same rows. The block's own
∂c/∂θ is checked against differences of its residual in the core
(``element::heart::tests::parameter_derivatives_are_the_residuals_central_differences``).

* The block between two venous pressures (svZeroDSolver's ``closedLoopHeart_singleVessel``
  opened: the heart fills from a vena-cava pressure, the RCR drains into the veins): the
  adjoint against the forward tangents (1e-8) for the cardiac output, the mean aortic
  pressure and the left ventricle's peak pressure, every block key.
* Central differences of whole runs are no check there: the block's mitral valve slides
  between the E and A waves (ΔP ≈ 0 and Q ≈ 0, its status at a step decided below Newton's
  tolerance), so a relative change of 1e-6 of a parameter flips a status and moves the
  cardiac output by more than 1e-4 a few cycles later (``test_the_block_slides``).
* A closed loop (the block without boundary conditions, the case itself): its conserved
  blood volume (a neutral mode of the cycle map) is held at the start values' by the volume
  row of the bordered periodic problem; the adjoint against the forward tangents (1e-8) for
  every block key. Its coronary beds stay refused by name.
* A smooth closed loop (a chamber between tanh valves, its blood returning through a
  Windkessel-like systemic bed, no boundary condition): the forward tangents against central
  differences of whole periodic runs (1e-6 of each output's scale), the adjoint against the
  forward tangents (1e-8), and a capacitance's tangent adds exactly the start values' volume
  its change holds (the conservation law: the outputs move as in runs from the same start).
* Paths that name nothing differentiable are ModelErrors naming them.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import ModelError
from oxyline.calibrate import _base_value, native_model
from tests.conftest import assert_adjoint_is_forward, data_path

pytest.importorskip("scipy")

svz = pytest.importorskip("oxyline.svzerod")

#: cycles of each run: the block's discrete cycle does not settle (it slides, see above), so
#: every run stops after this count
CYCLES = 60


def _closed(name: str = "closedLoopHeart_singleVessel") -> dict[str, Any]:
    return svz.to_oxyline_dict(str(data_path("svzerod", "cases", f"{name}.json")))


@functools.cache
def _case() -> tuple[dict[str, Any], str, str]:
    """The case opened between a vena-cava pressure (8, the case's numbers) and the veins (0),
    its heart block's vessel and the aorta's vessel."""
    model = _closed()
    heart = next(v for v in model["vessels"] if "heart_pulmonary" in v)
    drain = next(v for v in model["vessels"] if v["to"] == heart["from"])
    drain["to"], heart["from"] = "veins", "vena_cava"
    model["boundary_conditions"] = {"veins": {"type": "pressure", "value": 0.0},
                                    "vena_cava": {"type": "pressure", "value": 8.0}}
    return model, heart["name"], model["vessels"][0]["name"]


def _outputs() -> list[str]:
    _, heart, aorta = _case()
    return [f"{heart}:aortic.flow_in.mean", f"{aorta}.pressure_in.mean",
            f"{heart}:aortic.pressure_in.max"]


#: every key the block differentiates
KEYS = ["aortic_capacitance", "pulmonary_capacitance", "left_ventricle_elastance", "right_ventricle_elastance", "left_ventricle_rest_volume",
        "right_ventricle_rest_volume", "left_atrium_elastance", "right_atrium_elastance",
        "left_atrium_passive_pressure", "right_atrium_passive_pressure",
        "left_atrium_passive_volume_coefficient", "right_atrium_passive_volume_coefficient",
        "left_atrium_rest_volume", "right_atrium_rest_volume", "atrial_systole_fraction",
        "p_wave_divisor", "tricuspid_resistance", "pulmonary_valve_resistance",
        "mitral_resistance", "aortic_valve_resistance", "tricuspid_inductance",
        "pulmonary_valve_inductance", "mitral_inductance", "aortic_valve_inductance",
        "pulmonary_resistance"]


def _paths(keys: list[str]) -> list[str]:
    _, heart, _ = _case()
    return [f"vessels.{heart}.heart_pulmonary.{k}" for k in keys]


def test_closed_loop_heart_adjoint_is_the_forward_jacobian() -> None:
    model, _, _ = _case()
    fwd = oxyline.sensitivities(model, _paths(KEYS), _outputs(), max_cycles=CYCLES)
    adj = oxyline.sensitivities(model, _paths(KEYS), _outputs(), mode="adjoint",
                                max_cycles=CYCLES)
    assert_adjoint_is_forward(fwd, adj)
    # every key moves some output but the right atrium's law: the vena-cava condition holds
    # the atrium's pressure (through the block's resistance-free venous wire), so its
    # volume takes up any change of the law and nothing downstream sees it
    for k, key in enumerate(KEYS):
        moved = np.abs(fwd.jacobian[:, k]).max()
        assert (moved == 0) == key.startswith("right_atrium"), (key, moved)


def test_the_block_slides() -> None:
    """A 1e-6 change of the left ventricle's elastance changes the mitral valve's status at
    some step and the cardiac output after the run by far more than 1e-6 (the reason the
    block is checked by its residual's differences and the adjoint, not by differences of
    whole runs)."""
    model, _, _ = _case()
    path = _paths(["left_ventricle_elastance"])[0]
    x0 = _base_value(model, path)
    base, moved = (oxyline.sensitivities(native_model(model, [path], [x]), [], _outputs()[:1],
                                         max_cycles=CYCLES).values[0]
                   for x in (x0, x0 * (1 + 1e-6)))
    assert abs(moved / base - 1) > 1e-4


@pytest.mark.parametrize(("key", "words"), [
    ("period", ["heart_pulmonary.period", "no differentiable value 'period'"]),
    ("initial_left_ventricle_volume", ["no differentiable value"]),
    ("mitral_width", ["no differentiable value 'mitral_width'"]),
])
def test_bad_block_paths_name_themselves(key: str, words: list[str]) -> None:
    model, _, _ = _case()
    with pytest.raises(ModelError) as err:
        oxyline.sensitivities(model, _paths([key]), _outputs()[:1])
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_closed_loop_adjoint_is_the_forward_jacobian() -> None:
    """The closed loop itself: forward (volume row held) and adjoint (bordered) agree."""
    model = _closed()
    heart = next(v["name"] for v in model["vessels"] if "heart_pulmonary" in v)
    outputs = [f"{heart}:aortic.flow_in.mean", f"{model['vessels'][0]['name']}.pressure_in.mean",
               f"{heart}:aortic.pressure_in.max"]
    paths = [f"vessels.{heart}.heart_pulmonary.{k}" for k in KEYS]
    fwd = oxyline.sensitivities(model, paths, outputs, max_cycles=CYCLES)
    adj = oxyline.sensitivities(model, paths, outputs, mode="adjoint", max_cycles=CYCLES)
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-12)
    scale = np.abs(fwd.jacobian * fwd.parameter_values).max(axis=1)
    err = np.abs(adj.jacobian - fwd.jacobian) * np.abs(fwd.parameter_values)
    assert (err <= 1e-8 * scale[:, None]).all(), err / scale[:, None]
    # in the closed loop the right atrium's law moves the outputs (no vena-cava condition
    # holds its pressure any more): every key moves some output
    assert (np.abs(fwd.jacobian).max(axis=0) > 0).all(), fwd.jacobian


def test_closed_loop_coronary_beds_are_refused_by_name() -> None:
    model = _closed("closedLoopHeart_withCoronaries")
    vessel = model["vessels"][0]["name"]
    with pytest.raises(ModelError, match="closed-loop coronary bed"):
        oxyline.sensitivities(model, [], [f"{vessel}.pressure_in.mean"])


T = 0.8  # s
VALVE = {"law": "tanh", "min_resistance": 3e6, "max_resistance": 1e10, "steepness": 5e-3}

#: a closed loop without valve-status ambiguity (SI): a left ventricle between tanh valves
#: ejecting into an aorta and a systemic bed whose outlet is the mitral valve's inlet; the
#: blood is the ventricle's start volume, no boundary condition
SMOOTH_LOOP: dict[str, Any] = {
    "name": "smooth-loop", "units": "SI", "period": T,
    "vessels": [
        {"name": "mitral", "from": "ven", "to": "mv_out", "valve": dict(VALVE)},
        {"name": "lv", "from": "mv_out", "to": "lv_out", "chamber": {
            "law": "elastance-inductor", "max_elastance": 3.0e8, "min_elastance": 1.3e7,
            "rest_volume_diastole": 2e-5, "rest_volume_systole": 1e-5, "period": T,
            "inductance": 1e4, "initial_volume": 1.0e-4,
            "activation": {"kind": "half-cosine", "t_active": 0.1, "t_twitch": 0.35}}},
        {"name": "aortic", "from": "lv_out", "to": "ao", "valve": dict(VALVE)},
        {"name": "aorta", "from": "ao", "to": "art",
         "lumped": {"resistance": 5e6, "inductance": 1e5, "capacitance": 1.2e-8}},
        {"name": "systemic", "from": "art", "to": "ven",
         "lumped": {"resistance": 1.4e8, "capacitance": 5e-8}},
    ],
    "boundary_conditions": {},
    "simulation": {"dt": 0.004, "method": "generalized-alpha"},
}

LOOP_PARAMETERS = ["vessels.lv.chamber.max_elastance", "vessels.lv.chamber.min_elastance",
                   "vessels.aortic.valve.min_resistance", "vessels.aorta.lumped.capacitance",
                   "vessels.systemic.lumped.resistance", "vessels.systemic.lumped.capacitance"]
LOOP_OUTPUTS = ["lv.pressure_in.max", "aortic.flow_in.mean", "aorta.pressure_out.mean",
                "mitral.flow_in.max", "systemic.pressure_out.mean"]


def test_smooth_closed_loop_matches_central_differences() -> None:
    """Central differences of whole periodic runs from the same start values (relative step
    1e-4: truncation and rounding well below 1e-6 of each output's scale)."""
    exact = oxyline.sensitivities(SMOOTH_LOOP, LOOP_PARAMETERS, LOOP_OUTPUTS)
    assert exact.periodic_change <= 1e-11
    scale = np.abs(exact.jacobian * exact.parameter_values).max(axis=1)
    assert (scale > 0).all()
    for k, path in enumerate(LOOP_PARAMETERS):
        x0 = _base_value(SMOOTH_LOOP, path)
        h = 1e-4
        up, down = (oxyline.sensitivities(native_model(SMOOTH_LOOP, [path], [x0 * f]), [],
                                          LOOP_OUTPUTS).values for f in (1 + h, 1 - h))
        err = np.abs(exact.jacobian[:, k] - (up - down) / (2 * h * x0)) * x0
        assert (err <= 1e-6 * scale).all(), (path, err / scale)


def test_smooth_closed_loop_adjoint_is_the_forward_jacobian() -> None:
    fwd = oxyline.sensitivities(SMOOTH_LOOP, LOOP_PARAMETERS, LOOP_OUTPUTS)
    adj = oxyline.sensitivities(SMOOTH_LOOP, LOOP_PARAMETERS, LOOP_OUTPUTS, mode="adjoint")
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-12)
    scale = np.abs(fwd.jacobian * fwd.parameter_values).max(axis=1)
    err = np.abs(adj.jacobian - fwd.jacobian) * np.abs(fwd.parameter_values)
    assert (err <= 1e-8 * scale[:, None]).all(), err / scale[:, None]
