"""Oxygen sensitivities on a network whose flow graph has a loop (its species step is
solved by the flow-order sweep, and the adjoint transposes that sweep's system).

* A ring of four vessels fed by a parent and drained at three of its junctions (one by a
  pendant vessel), with Hill's law and a mass-transfer wall: the adjoint against the
  forward tangents (both iterate to a periodic change of 1e-12: ~1e-11 of a row's scale;
  1e-8 tells a wrong transpose) for oxygen and flow parameters.
* Against central differences of whole periodic runs, forward and adjoint (relative step
  1e-4; 1e-6 of the quotient plus the outputs' rounding over h).
* ``calibrate(gradient="adjoint")`` recovers an outlet resistance and P50 on the ring from
  synthetic SvO2 / PO2 / VO2 targets.
* Still refused by name, in both modes: an outlet value while flow runs back through it.
"""

from __future__ import annotations

import copy
from typing import Any

import pytest
from test_sensitivity_o2 import check_against_central_differences, values
from test_sensitivity_o2_adjoint import check_adjoint_equals_forward

import oxyline
from oxyline import ModelError
from oxyline.calibrate import native_model

pytest.importorskip("scipy")

T = 0.8  # s


def _vessel(name: str, ends: str, length: float, radius: float, segments: int) -> dict[str, Any]:
    a, b = ends.split("-")
    return {"name": name, "from": a, "to": b, "length": length, "radius": radius,
            "wall_thickness": 0.15 * radius, "youngs_modulus": 6e5, "segments": segments}


#: the ring a → b → c → d → a (the vessels' own directions: the flow picks its own), fed at
#: a, drained at b (an RCR), d (a resistance) and c (the pendant and its RCR); asymmetric,
#: so its bridge b → c carries a small net flow. The wall's k is far above an artery's, so
#: that the wall takes a few per cent of the oxygen delivered (as in the Y network's tests)
RING: dict[str, Any] = {
    "name": "ring-o2", "units": "SI", "period": T,
    "vessels": [
        _vessel("parent", "in-a", 0.1, 0.004, 3), _vessel("ab", "a-b", 0.06, 0.003, 3),
        _vessel("bc", "b-c", 0.04, 0.0015, 2), _vessel("cd", "c-d", 0.05, 0.002, 2),
        _vessel("da", "d-a", 0.07, 0.0025, 3), _vessel("pendant", "c-o3", 0.04, 0.0015, 2),
        _vessel("b_out", "b-o1", 0.05, 0.0025, 2), _vessel("d_out", "d-o2", 0.05, 0.002, 2),
    ],
    "boundary_conditions": {
        "in": {"type": "flow", "fourier": {"period": T, "mean": 3e-6, "cos": [1e-6, -0.4e-6],
                                           "sin": [1.2e-6, 0.3e-6]}},
        "o1": {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-10,
               "distal_resistance": 1.2e9},
        "o2": {"type": "resistance", "resistance": 1.6e9},
        "o3": {"type": "rcr", "proximal_resistance": 3e8, "capacitance": 3e-10,
               "distal_resistance": 2.4e9},
    },
    "simulation": {"dt": T / 160, "method": "generalized-alpha"},
    "oxygen": {"inlet": {"po2": 85.0}, "hemoglobin": "hill",
               "hill": {"p50": 26.8, "n": 2.7},
               "wall": {"model": "mass-transfer", "k": 5e-3, "po2": 40.0}},
}
OUTPUTS = ["b_out.po2_out.mean", "pendant.saturation_out.min", "SvO2.d_out", "VO2",
           "VO2.bc.cd", "bc.wall_uptake.max"]
PATHS = ["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50", "vessels.bc.radius",
         "vessels.da.length", "vessels.ab.youngs_modulus", "boundary_conditions.o3.capacitance",
         "boundary_conditions.o2.resistance", "scale.inflow"]


def test_ring_adjoint_equals_forward() -> None:
    check_adjoint_equals_forward(RING, PATHS, [*OUTPUTS, "bc.pressure_in.mean"])


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
@pytest.mark.parametrize("path", ["oxygen.hill.p50", "vessels.bc.radius", "scale.inflow"])
def test_ring_against_central_differences(path: str, mode: str) -> None:
    check_against_central_differences(RING, path, OUTPUTS[:4], mode=mode)


def test_ring_calibrated_by_adjoint() -> None:
    paths = ["boundary_conditions.o2.resistance", "oxygen.hill.p50"]
    truth = native_model(RING, paths, [1.4e9, 28.0])
    outputs = ["SvO2.d_out", "b_out.po2_out.mean", "VO2"]
    target = values(truth, outputs)
    fit = oxyline.calibrate(RING, dict(zip(outputs, target, strict=True)), paths, method="lm",
                            gradient="adjoint")
    assert fit.success
    assert fit.parameters[paths[0]] == pytest.approx(1.4e9, rel=1e-6)
    assert fit.parameters[paths[1]] == pytest.approx(28.0, rel=1e-6)


@pytest.mark.parametrize("mode", ["forward", "adjoint"])
def test_outlet_value_at_backflow_is_refused_by_name(mode: str) -> None:
    """Still refused: an outlet value while flow runs back through it (the value carried
    back into the outlet is not differentiated), here the parent's under a reversing
    inflow."""
    m = copy.deepcopy(RING)
    m["boundary_conditions"]["in"]["fourier"]["cos"] = [6e-6, -0.4e-6]
    with pytest.raises(ModelError, match=r"parent.*backflow"):
        oxyline.sensitivities(m, ["oxygen.hill.p50"], ["parent.po2_out.mean"], mode=mode)
