"""Exact sensitivities of oxygen outputs by oxygen and flow parameters
(``oxyline.sensitivities``).

* The outlet PO2 and saturation, the flow-weighted outflow saturation (SvO2) and the wall
  uptake of a vessel, a region and the whole network (VO2), by the wall's mass-transfer
  coefficient and PO2, Hill's P50 and a prescribed consumption flux, against central
  differences of the same periodic runs (relative step 1e-4: the truncation, O(h²), and
  the rounding of the binding's inversion, 1e-10 mmHg over h, stay below 1e-7 of the
  derivative, so 1e-6 relative tells a wrong derivative).
* The same outputs by a radius, a length, a Windkessel resistance and the inflow scale
  (through the flow's tangent), against central differences likewise.
* A P50 and a consumption flux recovered from synthetic SvO2 / VO2 targets, a Windkessel
  resistance from synthetic SvO2 / PO2 targets.
* Paths and outputs the oxygen tangent does not cover are ModelErrors naming them.
"""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import ModelError
from oxyline.calibrate import _base_value, native_model

pytest.importorskip("scipy")

T = 0.8  # s
#: an inflow without backflow into an elastic parent and two daughters (SI); oxygen with
#: Hill's law and a mass-transfer wall. Its k (and the consumption flux below) are far above
#: an artery's, so that the wall takes a few per cent of the oxygen delivered and the
#: outputs move well above the difference quotients' rounding (1e-12 of a PO2 over h)
Y: dict[str, Any] = {
    "name": "y-o2", "units": "SI", "period": T,
    "vessels": [
        {"name": "parent", "from": "in", "to": "j", "length": 0.1, "radius": 0.004,
         "wall_thickness": 6e-4, "youngs_modulus": 4e5, "segments": 3},
        {"name": "d1", "from": "j", "to": "o1", "length": 0.08, "radius": 0.003,
         "wall_thickness": 5e-4, "youngs_modulus": 6e5, "segments": 4},
        {"name": "d2", "from": "j", "to": "o2", "length": 0.05, "radius": 0.002,
         "wall_thickness": 4e-4, "youngs_modulus": 6e5, "segments": 2},
    ],
    "boundary_conditions": {
        "in": {"type": "flow", "fourier": {"period": T, "mean": 3e-6, "cos": [1e-6, -0.4e-6],
                                           "sin": [1.2e-6, 0.3e-6]}},
        "o1": {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-10,
               "distal_resistance": 1.2e9},
        "o2": {"type": "resistance", "resistance": 1.6e9},
    },
    "simulation": {"dt": T / 160, "method": "generalized-alpha"},
    "oxygen": {"inlet": {"po2": 85.0}, "hemoglobin": "hill",
               "hill": {"p50": 26.8, "n": 2.7},
               "wall": {"model": "mass-transfer", "k": 5e-3, "po2": 40.0}},
}
OUTPUTS = ["d1.po2_out.mean", "d1.saturation_out.min", "SvO2.d1", "VO2", "VO2.parent.d1",
           "parent.wall_uptake.max"]


def consuming() -> dict[str, Any]:
    """:data:`Y` with a prescribed consumption flux (mol m⁻² s⁻¹) instead of the wall law."""
    m = copy.deepcopy(Y)
    m["oxygen"]["wall"] = {"model": "flux", "flux": 1.5e-4}
    return m


def per_vessel() -> dict[str, Any]:
    """:data:`Y` with a wall of d1's own (the section's wall stays on the others)."""
    m = copy.deepcopy(Y)
    m["oxygen"]["per_vessel"] = {"d1": {"wall": {"model": "mass-transfer", "k": 3e-3,
                                                 "po2": 30.0}}}
    return m


def values(model: dict[str, Any], outputs: list[str]) -> np.ndarray:
    return oxyline.sensitivities(model, [], outputs).values


def central_differences(model: dict[str, Any], path: str, outputs: list[str],
                        h: float = 1e-4) -> np.ndarray:
    """d outputs / d log θ by central differences of whole periodic runs (relative step h):
    unit-free, whatever units the model writes θ in."""
    x0 = _base_value(model, path)
    up = values(native_model(model, [path], [x0 * (1 + h)]), outputs)
    down = values(native_model(model, [path], [x0 * (1 - h)]), outputs)
    return (up - down) / (2 * h)


def check_against_central_differences(model: dict[str, Any], path: str, outputs: list[str],
                                      mode: str = "forward") -> None:
    """The outputs carry ~1e-12 of their value in rounding, so the quotient is judged to
    1e-6 of itself plus that rounding over h (h = 1e-4), where at least two outputs move
    well above it."""
    s = oxyline.sensitivities(model, [path], outputs, mode=mode)
    fd = central_differences(model, path, outputs, h=1e-4)
    exact = s.jacobian[:, 0] * s.parameter_values[0]
    rounding = 1e-12 * np.abs(s.values) / 1e-4
    assert (np.abs(fd) > 1e4 * rounding).sum() >= 2, (path, fd)
    err = np.abs(exact - fd)
    assert np.all(err <= 1e-6 * np.abs(fd) + rounding), (path, err / np.abs(fd))


@pytest.mark.parametrize(("model", "path"), [
    (Y, "oxygen.wall.k"), (Y, "oxygen.wall.po2"), (Y, "oxygen.hill.p50"),
    (consuming(), "oxygen.wall.flux"), (per_vessel(), "oxygen.wall.k"),
    (per_vessel(), "oxygen.per_vessel.d1.wall.k"), (per_vessel(), "oxygen.per_vessel.d1.wall.po2"),
])
def test_oxygen_outputs_against_central_differences(model: dict[str, Any], path: str
                                                    ) -> None:
    s = oxyline.sensitivities(model, [path], OUTPUTS)
    fd = central_differences(model, path, OUTPUTS)
    exact = s.jacobian[:, 0] * s.parameter_values[0]
    moved = np.abs(fd) > 1e-12 * np.abs(s.values)
    assert moved.sum() >= 4, (path, fd)
    np.testing.assert_allclose(exact[moved], fd[moved], rtol=1e-6,
                               atol=1e-9 * np.abs(fd).max())


@pytest.mark.parametrize("path", ["vessels.parent.radius", "vessels.d2.length",
                                  "boundary_conditions.o1.distal_resistance", "scale.inflow"])
def test_oxygen_outputs_by_flow_parameters_against_central_differences(path: str) -> None:
    """A flow parameter reaches the oxygen through the face flows and transport volumes of
    every step (and a radius or length through the lumen volumes and wall areas). The
    outputs carry ~1e-12 of their value in rounding, so the quotient is judged to 1e-6 of
    itself plus that rounding over h (a far vessel's wall by a length moves by less)."""
    check_against_central_differences(Y, path, OUTPUTS)


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", ["oxygen.wall.k", "oxygen.wall.po2", "vessels.parent.radius"])
def test_mass_transfer_wall_behind_a_permeability_against_central_differences(
    path: str, mode: str
) -> None:
    """A wall permeability in series equal to k: g = 1/(1/(k A) + 1/(P A)) moves by half of
    k's relative change (the blood side's share 1 − g/(P A)), by the wall area in full."""
    m = copy.deepcopy(Y)
    m["oxygen"]["wall"]["permeability"] = 5e-3
    check_against_central_differences(m, path, OUTPUTS, mode=mode)


def tapered(friction: str = "poiseuille") -> dict[str, Any]:
    """:data:`Y` with d1 tapered 3 → 2.5 mm (its radius given by its two ends), the
    model's ``wall_friction`` ``friction``."""
    m = copy.deepcopy(Y)
    d1 = m["vessels"][1]
    del d1["radius"]
    d1.update(radius_in=0.003, radius_out=0.0025)
    m["wall_friction"] = friction
    return m


@pytest.mark.parametrize(("model", "path", "mode"), [
    (tapered(), "vessels.d1.radius_in", "forward"),
    (tapered(), "vessels.d1.radius_out", "adjoint"),
    (tapered("womersley"), "vessels.d1.radius_out", "forward"),
    (tapered("womersley"), "vessels.parent.radius", "adjoint"),
    (tapered("womersley"), "vessels.d2.length", "forward"),
])
def test_taper_end_radii_and_womersley_geometry_against_central_differences(
        model: dict[str, Any], path: str, mode: str) -> None:
    """A taper's end radius moves each segment's lumen volume and wall area by its own
    share; Womersley friction cells follow each segment's R and L, and the oxygen the
    flows they shape. Forward and adjoint against central differences, judged as above."""
    check_against_central_differences(model, path, OUTPUTS, mode=mode)


def test_windkessel_resistance_recovered_from_po2_and_svo2() -> None:
    path = "boundary_conditions.o1.distal_resistance"
    truth = native_model(Y, [path], [1.5e9])
    outputs = ["SvO2.d1", "d1.po2_out.mean"]
    target = values(truth, outputs)
    fit = oxyline.calibrate(Y, dict(zip(outputs, target, strict=True)), [path], method="lm")
    assert fit.success
    assert fit.parameters[path] == pytest.approx(1.5e9, rel=1e-6)


def test_consumption_balances_inflow_minus_outflow() -> None:
    """At the periodic state the stored oxygen repeats: d VO2 = d(inflow − outflow) of O2."""
    from oxyline import _core
    from oxyline.model import build_model

    raw = _core.tangent_sensitivities(
        json.dumps(build_model(Y).canonical), ["oxygen.wall.k", "oxygen.hill.p50"],
        [("", "consumption"), ("", "inflow"), ("", "outflow")], T, 160, 0.5, 2000, 1e-13)
    d = raw["derivatives"].mean(axis=1)  # (parameter, signal)
    # the stored oxygen's derivative repeats to the periodic tolerance (1e-13 of the field)
    np.testing.assert_allclose(d[:, 0], d[:, 1] - d[:, 2], rtol=1e-8)
    assert np.abs(d[:, 0]).min() > 0


def test_p50_and_consumption_recovered_from_svo2_and_vo2() -> None:
    truth = native_model(consuming(), ["oxygen.hill.p50", "oxygen.wall.flux"], [29.5, 1.7e-4])
    target = values(truth, ["SvO2.d1", "VO2"])
    fit = oxyline.calibrate(consuming(), {"SvO2.d1": target[0], "VO2": target[1]},
                            ["oxygen.hill.p50", "oxygen.wall.flux"], method="lm")
    assert fit.success
    assert fit.parameters["oxygen.hill.p50"] == pytest.approx(29.5, rel=1e-6)
    assert fit.parameters["oxygen.wall.flux"] == pytest.approx(1.7e-4, rel=1e-6)


@pytest.mark.parametrize(("parameters", "outputs", "named"), [
    (["oxygen.wall.kk"], ["VO2"], "oxygen.wall.kk"),
    (["oxygen.wall.flux"], ["VO2"], "oxygen.wall.flux"),
    (["vessels.parent.colour"], ["SvO2.d1"], "vessels.parent.colour"),
    (["oxygen.wall.k"], ["SvO2.nope"], "nope"),
    (["oxygen.wall.k"], ["d1.po2_out.median"], "median"),
    (["oxygen.per_vessel.d2.wall.k"], ["VO2"], "oxygen.per_vessel.d2.wall.k"),
])
def test_bad_oxygen_paths_and_outputs_are_model_errors(parameters: list[str],
                                                       outputs: list[str], named: str) -> None:
    with pytest.raises(ModelError, match=named.replace(".", r"\.")):
        oxyline.sensitivities(Y, parameters, outputs)


def test_oxygen_needs_an_oxygen_model() -> None:
    flow_only = {k: v for k, v in Y.items() if k != "oxygen"}
    with pytest.raises(ModelError, match="no oxygen section"):
        oxyline.sensitivities(flow_only, [], ["VO2"])
    with pytest.raises(ModelError, match="no oxygen section"):
        oxyline.sensitivities(flow_only, ["vessels.parent.radius"], ["VO2"], mode="adjoint")


def test_oxygen_parameters_leave_flow_outputs_alone() -> None:
    s = oxyline.sensitivities(Y, ["oxygen.wall.k", "scale.resistance"],
                              ["parent.pressure_in.mean"])
    assert s.jacobian[0, 0] == 0.0
    assert s.jacobian[0, 1] > 0.0


def test_the_differentiated_cycle_is_the_runs() -> None:
    """The values the tangents differentiate are those of ``simulate``'s generalized-α run
    at its periodic state (its recorder, PO2 in mmHg, read at every step of the last cycle)."""
    s = oxyline.sensitivities(Y, [], ["d1.po2_out.mean", "d1.po2_out.max"])
    res = oxyline.simulate(Y, cycles=40, progress=False, output_every=T / 160)
    po2 = res.po2_out[-160:, list(res.vessels).index("d1")] * 133.322368  # mmHg → Pa
    # measured: the mean within 7e-9, the maximum within 1.7e-7 (40 cycles of the run, its
    # own start and step control, against the tangent's cycle periodic to 1e-12)
    np.testing.assert_allclose(s.values, [po2.mean(), po2.max()], rtol=1e-6)
