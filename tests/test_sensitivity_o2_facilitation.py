"""Oxygen sensitivities through the haemoglobin facilitation of boundary-layer walls
(``oxyline.sensitivities``): with haemoglobin a Lévêque or Graetz wall's conductance carries
the facilitation factor E_Hb, which reads the wall PO2 and the Hill law, so the wall's PO2
and P50 move the uptake through it as well.

* paper-bifurcated as shipped (its Graetz wall's inlet renewal) with Hill haemoglobin, by
  P50 and the wall PO2, and the Y network with a facilitated cycle-mean Lévêque wall by P50,
  the wall PO2 and its enhancement: against central differences of whole periodic runs
  (relative step 1e-4; each run's E_Hb recomputed by the model reader), forward and
  adjoint, judged as the other oxygen sensitivities (1e-6 of the quotient plus the outputs'
  rounding over h: the shooting solve's 1e-10 on E_Hb is ~1e-6 of the quotient at most);
  the adjoint against the forward tangents to 1e-8 of each row's scale.
* A facilitated wall with a permeability in series: E_Hb and the enhancement move the
  conductance by the blood side's share of the series (1 − g/G_p), against central
  differences and the adjoint against the forward tangents alike.
"""

from __future__ import annotations

import copy
import warnings
from typing import Any

import pytest
from test_sensitivity_o2 import Y, check_against_central_differences
from test_sensitivity_o2_adjoint import check_adjoint_equals_forward

import oxyline

pytest.importorskip("scipy")


def paper_bifurcated_hill() -> dict[str, Any]:
    """paper-bifurcated as shipped (dissolved O2, a Graetz wall at 55.5 mmHg on the inlet
    renewal) with Hill haemoglobin: its wall is then facilitated (E_Hb = 2.52)."""
    m = copy.deepcopy(oxyline.load_model("paper-bifurcated").source)
    m["oxygen"]["hemoglobin"] = "hill"
    m["oxygen"]["hill"] = {"p50": 26.8, "n": 2.7}
    return m


def leveque_y() -> dict[str, Any]:
    """:data:`Y` with a facilitated cycle-mean Lévêque wall at 40 mmHg, ×8 so that the wall
    takes a few per cent of the oxygen delivered."""
    m = copy.deepcopy(Y)
    m["oxygen"]["wall"] = {"model": "leveque", "po2": 40.0, "enhancement": 8.0}
    return m


PAPER_OUTPUTS = ["ICA.po2_out.mean", "SvO2.ICA", "VO2", "CCA.wall_uptake.max"]
Y_OUTPUTS = ["d1.po2_out.mean", "SvO2.d1", "VO2", "parent.wall_uptake.mean"]


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", ["oxygen.hill.p50", "oxygen.wall.po2"])
def test_paper_bifurcated_with_haemoglobin_against_central_differences(
    path: str, mode: str
) -> None:
    check_against_central_differences(paper_bifurcated_hill(), path, PAPER_OUTPUTS, mode=mode)


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", ["oxygen.hill.p50", "oxygen.wall.po2", "oxygen.wall.enhancement"])
def test_facilitated_leveque_wall_against_central_differences(path: str, mode: str) -> None:
    check_against_central_differences(leveque_y(), path, Y_OUTPUTS, mode=mode)


@pytest.mark.parametrize(
    ("model", "outputs"), [(paper_bifurcated_hill, PAPER_OUTPUTS), (leveque_y, Y_OUTPUTS)]
)
def test_facilitated_walls_adjoint_equals_forward(model: Any, outputs: list[str]) -> None:
    check_adjoint_equals_forward(model(), ["oxygen.hill.p50", "oxygen.wall.po2"], outputs)


def test_p50_moves_the_outlet_po2_through_the_wall() -> None:
    """d(ICA outlet PO2)/d ln P50 with the facilitated wall differs from the same model's
    with the facilitation switched off (the binding's part alone): E_Hb's derivative is in."""
    on = oxyline.sensitivities(paper_bifurcated_hill(), ["oxygen.hill.p50"], ["ICA.po2_out.mean"])
    m = paper_bifurcated_hill()
    m["oxygen"]["wall"] = {**m["oxygen"]["wall"], "hb_facilitation": False}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the facilitation switched off warns
        off = oxyline.sensitivities(m, ["oxygen.hill.p50"], ["ICA.po2_out.mean"])
    d_on = on.jacobian[0, 0] * on.parameter_values[0]
    d_off = off.jacobian[0, 0] * off.parameter_values[0]
    assert abs(d_on - d_off) > 0.05 * abs(d_off), (d_on, d_off)


def leaky_leveque_y() -> dict[str, Any]:
    """:func:`leveque_y` behind a wall permeability in series of 3e-4 m/s (comparable to
    the facilitated layer's own mass-transfer coefficient: the series takes a large share)."""
    m = leveque_y()
    m["oxygen"]["wall"]["permeability"] = 3e-4
    return m


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", ["oxygen.hill.p50", "oxygen.wall.po2", "oxygen.wall.enhancement"])
def test_facilitated_wall_behind_a_permeability_against_central_differences(
    path: str, mode: str
) -> None:
    check_against_central_differences(leaky_leveque_y(), path, Y_OUTPUTS, mode=mode)


def test_facilitated_wall_behind_a_permeability_adjoint_equals_forward() -> None:
    check_adjoint_equals_forward(
        leaky_leveque_y(), ["oxygen.hill.p50", "oxygen.wall.po2", "oxygen.wall.enhancement"],
        Y_OUTPUTS)
