"""Oxygen sensitivities with boundary-layer walls whose law reads the cycle-mean flow
(``oxyline.sensitivities``): a Graetz wall of the forward-flow mean and a cycle-mean
Lévêque wall. Their conductance moves with every flow parameter (through each segment's
mean flow over the periodic cycle) and with a vessel's length (the layer's development),
not with the wall area alone.

* paper-bifurcated (the paper's carotid bifurcation, dissolved oxygen, its Graetz wall
  with the forward-flow mean): the CCA's and ECA's radii, the ICA's length, the inflow
  scale and the wall's enhancement, against central differences of whole periodic runs (relative
  step 1e-4; 1e-6 of the quotient plus the outputs' rounding over h), forward and adjoint;
  the adjoint against the forward tangents to 1e-8 of each row's scale.
* A Graetz wall facilitated by haemoglobin on the Y network by a radius, a length and the
  inflow scale (adjoint), against central differences likewise.
* paper-bifurcated as shipped: its Graetz wall's inlet renewal (the default law), whose
  factor reads the inlet flow's harmonics, by the same parameters and the ICA's outlet
  resistance, forward and adjoint, against central differences likewise; the adjoint
  against the forward tangents.
* A facilitated Graetz wall behind a permeability in series (the Y network): its PO2, P50
  and the inflow scale against central differences likewise, forward and adjoint (without
  one: test_sensitivity_o2_facilitation.py).
"""

from __future__ import annotations

import copy
from typing import Any

import pytest
from test_sensitivity_o2 import Y, check_against_central_differences
from test_sensitivity_o2_adjoint import check_adjoint_equals_forward

import oxyline

pytest.importorskip("scipy")


def paper_bifurcated() -> dict[str, Any]:
    """paper-bifurcated as shipped, its Graetz wall reading the forward-flow mean (= the
    cycle-mean |Q| here: no reversal) and its enhancement written out (1, the default) so
    that it can be a parameter."""
    m = copy.deepcopy(oxyline.load_model("paper-bifurcated").source)
    m["oxygen"]["wall"] = {**m["oxygen"]["wall"], "flow": "forward-mean", "enhancement": 1.0}
    return m


PATHS = [
    "vessels.CCA.radius",
    "vessels.ECA.radius",
    "vessels.ICA.length",
    "scale.inflow",
    "oxygen.wall.enhancement",
]
OUTPUTS = ["VO2", "VO2.ICA", "CCA.wall_uptake.max", "ECA.wall_uptake.mean"]


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", PATHS)
def test_paper_bifurcated_against_central_differences(path: str, mode: str) -> None:
    check_against_central_differences(paper_bifurcated(), path, OUTPUTS, mode=mode)


def test_paper_bifurcated_adjoint_equals_forward() -> None:
    check_adjoint_equals_forward(paper_bifurcated(), PATHS, OUTPUTS)


def facilitated_y() -> dict[str, Any]:
    """The Y network of the other oxygen tests (Hill's law) with a Graetz wall of the
    forward-flow mean, facilitated by the haemoglobin (E_Hb, fixed by the inlet and wall
    PO2: the flow parameters leave it alone), ×8 so that the wall takes a few per cent."""
    m = copy.deepcopy(Y)
    m["oxygen"]["wall"] = {
        "model": "graetz",
        "po2": 40.0,
        "flow": "forward-mean",
        "enhancement": 8.0,
    }
    return m


@pytest.mark.parametrize("path", ["vessels.d2.radius", "vessels.d1.length", "scale.inflow"])
def test_facilitated_graetz_wall_by_flow_parameters(path: str) -> None:
    outputs = ["d1.po2_out.mean", "SvO2.d1", "VO2", "parent.wall_uptake.mean"]
    check_against_central_differences(facilitated_y(), path, outputs, mode="adjoint")


def paper_bifurcated_as_shipped(enhancement: bool = False) -> dict[str, Any]:
    """paper-bifurcated as shipped (its Graetz wall's inlet renewal), with its enhancement
    written out (1, the default) when it is to be a parameter. Its wall shear barely runs
    backward: the renewal adds nothing measurable there (``renewing`` below)."""
    m = copy.deepcopy(oxyline.load_model("paper-bifurcated").source)
    if enhancement:
        m["oxygen"]["wall"] = {**m["oxygen"]["wall"], "enhancement": 1.0}
    return m


def renewing(m: dict[str, Any]) -> dict[str, Any]:
    """``m`` (paper-bifurcated) with its inflow's harmonics doubled (the flow keeps its sign:
    at least 0.88 mL/s) and a blood viscosity of 1.2 mPa s (larger Womersley numbers): the
    wall shear runs backward for part of the beat, and the renewal raises VO2 by 0.8 %."""
    m = copy.deepcopy(m)
    wave = m["boundary_conditions"]["inlet"]["fourier"]
    wave["cos"] = [2 * c for c in wave["cos"]]
    wave["sin"] = [2 * c for c in wave["sin"]]
    m["blood"] = {**m["blood"], "viscosity": 1.2e-3}
    return m


RENEWAL_PATHS = [
    "vessels.CCA.radius",
    "vessels.ECA.radius",
    "vessels.ICA.length",
    "scale.inflow",
    "boundary_conditions.ica_out.resistance",
]


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", [*RENEWAL_PATHS, "oxygen.wall.enhancement"])
@pytest.mark.parametrize("renews", [False, True], ids=["as-shipped", "renewing"])
def test_inlet_renewal_against_central_differences(path: str, mode: str, renews: bool) -> None:
    model = paper_bifurcated_as_shipped(enhancement=path.startswith("oxygen."))
    check_against_central_differences(
        renewing(model) if renews else model, path, OUTPUTS, mode=mode
    )


@pytest.mark.parametrize("renews", [False, True], ids=["as-shipped", "renewing"])
def test_inlet_renewal_adjoint_equals_forward(renews: bool) -> None:
    model = paper_bifurcated_as_shipped()
    check_adjoint_equals_forward(renewing(model) if renews else model, RENEWAL_PATHS, OUTPUTS)


def test_inlet_renewal_is_at_work_in_the_renewing_model() -> None:
    """The renewing model's uptake exceeds its forward-mean law's (so the tests above follow
    the renewal's own derivative, not the forward-mean law's)."""
    model = renewing(paper_bifurcated_as_shipped())
    renewed = oxyline.sensitivities(model, [], OUTPUTS).values
    model["oxygen"]["wall"] = {**model["oxygen"]["wall"], "flow": "forward-mean"}
    plain = oxyline.sensitivities(model, [], OUTPUTS).values
    # VO2 and the CCA's largest wall uptake: 0.8 % and 1.6 % above
    assert renewed[0] / plain[0] > 1.005, (renewed, plain)
    assert renewed[2] / plain[2] > 1.01, (renewed, plain)


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", ["oxygen.wall.po2", "oxygen.hill.p50", "scale.inflow"])
def test_facilitated_wall_behind_a_permeability_against_central_differences(
    path: str, mode: str
) -> None:
    """E_Hb moves the layer's conductance, and the series g = 1/(1/G + 1/G_p) takes the
    share 1 − g/G_p of it; the inflow moves the layer's mean flow likewise."""
    m = copy.deepcopy(Y)
    m["oxygen"]["wall"] = {
        "model": "graetz",
        "po2": 40.0,
        "flow": "forward-mean",
        "enhancement": 8.0,
        "permeability": 1e-4,
    }
    check_against_central_differences(m, path, ["VO2", "d1.po2_out.mean", "SvO2.d1"], mode=mode)
