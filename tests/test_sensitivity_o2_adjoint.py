"""The adjoint of oxygen outputs by oxygen parameters (``oxyline.sensitivities(...,
mode="adjoint")``): one backward sweep of the species transport per output row.

* Against the forward tangents (stepped forwards; the adjoint transposes each step) for
  every oxygen parameter kind × the outlet PO2 and saturation, SvO2, the wall uptake of a
  vessel, a region and the network: both iterate to a periodic change of 1e-12, so they
  agree to ~1e-11 of a row's scale; 1e-8 tells a wrong transpose.
* Against central differences of whole periodic runs for the mass-transfer k and P50
  (relative step 1e-4: truncation and rounding below 1e-7 of the derivative).
* Flow parameters (a radius, a length, a wall stiffness, a Windkessel's R and C, an
  outlet resistance, the inflow scale) beside oxygen ones: the flow's tangent forward, the
  species adjoint backward, against the forward tangents (1e-8 of a row's scale, as
  above) on the Y network with its RCR and on paper-bifurcated (with a mass-transfer wall
  and haemoglobin: with haemoglobin a Graetz wall's facilitation reads P50; its Graetz
  wall's own laws: test_sensitivity_o2_walls.py), and against central differences (relative step
  1e-4; 1e-6 of the quotient plus the outputs' rounding over h).
* ``calibrate(gradient="adjoint")`` with oxygen targets and flow parameters uses the
  adjoint (no forward tangent runs).
* A shear-dependent (Lévêque, instantaneous or relaxed) wall by oxygen and by flow
  parameters, forward and adjoint against central differences.
* What the oxygen adjoint does not follow is refused by name: a path that does not
  resolve; flow outputs beside oxygen parameters get zero rows.
"""

from __future__ import annotations

import copy
import importlib
from typing import Any

import numpy as np
import pytest
from test_sensitivity_o2 import (
    OUTPUTS,
    Y,
    central_differences,
    check_against_central_differences,
    consuming,
    per_vessel,
    values,
)

import oxyline
from oxyline import ModelError
from oxyline.calibrate import native_model

pytest.importorskip("scipy")


def check_adjoint_equals_forward(model: dict[str, Any], paths: list[str],
                                 outputs: list[str]) -> None:
    """Adjoint and forward tangents of the same outputs: d/d log θ, each row against its
    largest entry (both iterate to a periodic change of 1e-12: ~1e-11 of the row's scale;
    1e-8 tells a wrong transpose)."""
    fwd = oxyline.sensitivities(model, paths, outputs)
    adj = oxyline.sensitivities(model, paths, outputs, mode="adjoint")
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-10)
    np.testing.assert_allclose(adj.parameter_values, fwd.parameter_values, rtol=1e-14)
    a = adj.jacobian * adj.parameter_values
    f = fwd.jacobian * fwd.parameter_values
    scale = np.abs(f).max(axis=1, keepdims=True)
    assert np.all(scale > 0)
    assert np.all(np.abs(a - f) <= 1e-8 * scale), np.abs(a - f) / scale


@pytest.mark.parametrize(("model", "paths"), [
    (Y, ["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50"]),
    (consuming(), ["oxygen.wall.flux", "oxygen.hill.p50"]),
    (per_vessel(), ["oxygen.per_vessel.d1.wall.k", "oxygen.per_vessel.d1.wall.po2",
                    "oxygen.wall.k", "oxygen.wall.po2"]),
])
def test_adjoint_equals_forward(model: dict[str, Any], paths: list[str]) -> None:
    check_adjoint_equals_forward(model, paths, OUTPUTS)


@pytest.mark.parametrize("path", ["oxygen.wall.k", "oxygen.hill.p50"])
def test_adjoint_against_central_differences(path: str) -> None:
    outputs = ["d1.po2_out.mean", "SvO2.d1", "VO2", "parent.wall_uptake.mean"]
    s = oxyline.sensitivities(Y, [path], outputs, mode="adjoint")
    fd = central_differences(Y, path, outputs)
    exact = s.jacobian[:, 0] * s.parameter_values[0]
    assert np.all(np.abs(fd) > 1e-9 * np.abs(s.values)), fd
    np.testing.assert_allclose(exact, fd, rtol=1e-6)


def paper_bifurcated() -> dict[str, Any]:
    """paper-bifurcated with a mass-transfer wall (its Graetz wall's fully developed
    Sherwood number 3.66 over the CCA's diameter, far above, so that the wall takes a few
    per cent) and Hill's haemoglobin (for an SvO2)."""
    m = copy.deepcopy(oxyline.load_model("paper-bifurcated").source)
    m["oxygen"]["wall"] = {"model": "mass-transfer", "k": 2e-3, "po2": 55.5}
    m["oxygen"]["hemoglobin"] = "hill"
    m["oxygen"].pop("solubility", None)
    m["oxygen"]["hill"] = {"p50": 26.8, "n": 2.7}
    m["simulation"] = {"dt": 1.0 / 200, "method": "generalized-alpha"}
    return m


FLOW_Y = ["vessels.parent.radius", "vessels.d2.length", "vessels.d1.youngs_modulus",
          "boundary_conditions.o1.distal_resistance", "boundary_conditions.o1.capacitance",
          "boundary_conditions.o1.proximal_resistance", "scale.inflow", "oxygen.wall.k"]
FLOW_PB = ["vessels.CCA.radius", "vessels.ICA.length", "vessels.ECA.youngs_modulus",
           "boundary_conditions.ica_out.resistance", "scale.inflow", "oxygen.wall.k",
           "oxygen.hill.p50"]
OUTPUTS_PB = ["ICA.po2_out.mean", "SvO2.ECA", "VO2", "VO2.CCA", "ECA.saturation_out.min",
              "CCA.pressure_in.mean"]


@pytest.mark.parametrize(("model", "paths", "outputs"), [
    (Y, FLOW_Y, [*OUTPUTS, "parent.pressure_in.mean"]),
    (paper_bifurcated(), FLOW_PB, OUTPUTS_PB),
], ids=["y-rcr", "paper-bifurcated"])
def test_adjoint_equals_forward_by_flow_parameters(model: dict[str, Any], paths: list[str],
                                                   outputs: list[str]) -> None:
    check_adjoint_equals_forward(model, paths, outputs)


@pytest.mark.parametrize("path", ["vessels.parent.radius", "boundary_conditions.o1.distal_resistance",
                                  "scale.inflow"])
def test_adjoint_by_flow_parameters_against_central_differences(path: str) -> None:
    """The outputs carry ~1e-12 of their value in rounding, so the quotient is judged to
    1e-6 of itself plus that rounding over h (as the forward tangent's test does)."""
    outputs = ["d1.po2_out.mean", "SvO2.d1", "VO2", "parent.wall_uptake.mean"]
    check_against_central_differences(Y, path, outputs, mode="adjoint")


def test_calibrate_by_adjoint_with_oxygen_targets_and_flow_parameters(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A Windkessel resistance and the inflow scale from synthetic SvO2 / PO2 / VO2
    targets, every Jacobian by the adjoint: the forward tangents' entry is made to fail."""
    cal = importlib.import_module("oxyline.calibrate")  # (the package's name is the function)
    paths = ["boundary_conditions.o1.distal_resistance", "scale.inflow"]
    truth = native_model(Y, paths, [1.5e9, 1.1])
    outputs = ["SvO2.d1", "d1.po2_out.mean", "VO2"]
    target = values(truth, outputs)

    def no_forward(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the forward tangents were asked for")
    monkeypatch.setattr(cal, "_evaluate", no_forward)
    fit = oxyline.calibrate(Y, dict(zip(outputs, target, strict=True)), paths, method="lm",
                            gradient="adjoint")
    assert fit.success
    assert fit.parameters[paths[0]] == pytest.approx(1.5e9, rel=1e-6)
    assert fit.parameters[paths[1]] == pytest.approx(1.1, rel=1e-6)


def test_unresolved_flow_paths_are_refused_by_name() -> None:
    with pytest.raises(ModelError, match="nope"):
        oxyline.sensitivities(Y, ["oxygen.wall.k", "vessels.nope.radius"], ["VO2"],
                              mode="adjoint")


def test_flow_outputs_beside_oxygen_get_zero_rows() -> None:
    outputs = ["parent.pressure_in.mean", "SvO2.d1"]
    adj = oxyline.sensitivities(Y, ["oxygen.wall.k"], outputs, mode="adjoint")
    fwd = oxyline.sensitivities(Y, ["oxygen.wall.k"], outputs)
    assert adj.jacobian[0, 0] == 0.0
    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-10)
    np.testing.assert_allclose(adj.jacobian[1], fwd.jacobian[1], rtol=1e-8)


def sheared(shear: str) -> dict[str, Any]:
    """:data:`Y` with a Lévêque wall of the shear ``shear`` on d2 (the section's
    mass-transfer wall on the others)."""
    leveque = {"wall": {"model": "leveque", "po2": 40.0, "shear": shear}}
    return {**Y, "oxygen": {**Y["oxygen"], "per_vessel": {"d2": leveque}}}


SHEARED_OUTPUTS = ["d2.po2_out.mean", "d2.saturation_out.min", "VO2", "SvO2.d1",
                   "d1.po2_out.mean"]


@pytest.mark.parametrize(("shear", "path", "mode"), [
    ("instantaneous", "oxygen.wall.k", "forward"),
    ("instantaneous", "oxygen.per_vessel.d2.wall.po2", "adjoint"),
    ("relaxed", "oxygen.per_vessel.d2.wall.po2", "forward"),
    ("relaxed", "oxygen.hill.p50", "adjoint"),
])
def test_shear_dependent_wall_by_oxygen_parameters(shear: str, path: str, mode: str) -> None:
    """A Lévêque wall whose conductance follows the shear step by step (instantaneous, or
    relaxed through its own state): an oxygen parameter scales each step's conductance, so
    forward and adjoint follow it; against central differences, judged as above."""
    check_against_central_differences(sheared(shear), path, SHEARED_OUTPUTS, mode=mode)


@pytest.mark.parametrize(("shear", "path", "mode"), [
    ("instantaneous", "vessels.d2.radius", "forward"),
    ("instantaneous", "scale.inflow", "adjoint"),
    ("relaxed", "vessels.d2.length", "adjoint"),
    ("relaxed", "boundary_conditions.o1.distal_resistance", "forward"),
])
def test_shear_dependent_wall_by_flow_parameters(shear: str, path: str, mode: str) -> None:
    """A flow parameter moves the shear such a wall reads each step (the relaxed one
    through its own state, whose relaxation time the mean flow and the geometry set) and a
    radius or length the wall law's coefficients: forward and adjoint against central
    differences of whole periodic runs, judged as above."""
    check_against_central_differences(sheared(shear), path, SHEARED_OUTPUTS, mode=mode)
