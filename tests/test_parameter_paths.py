"""Parameter and patch paths that name a vessel whose name holds dots, and a heart element's
key a typo away: resolved against the model's own names (the longest wins) or named with the
nearest key, whichever front end reads the path (sensitivities, calibration's base values,
ensemble patches; a patch table's dotted columns: tests/test_ensemble.py).

The truths are independent of the resolver: a steady chain whose derivatives are closed-form
(a flow inlet Q through lumped resistances R_ab, R_c into a resistance outlet R_out: the
pressure at c's inlet is Q (R_c + R_out), which R_ab does not move), and the same model with
the dotted vessel renamed, whose Jacobian must be the same numbers."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import ModelError
from oxyline.calibrate import _base_value
from tests.test_sensitivity_heart import HEART

Q, R_AB, R_C, R_OUT = 1e-6, 2e8, 3e8, 1e9

CHAIN: dict[str, Any] = {
    "name": "chain", "period": 1.0,
    "vessels": [
        {"name": "a.b", "from": "in", "to": "j", "lumped": {"resistance": R_AB}},
        {"name": "a", "from": "j", "to": "k", "lumped": {"resistance": R_C}},
    ],
    "boundary_conditions": {"in": {"type": "flow", "value": Q},
                            "k": {"type": "resistance", "resistance": R_OUT}},
}
OUT = ["a.pressure_in.mean"]


def test_a_dotted_vessel_name_is_its_vessel_in_sensitivities() -> None:
    """``vessels.a.b.lumped.resistance`` is vessel ``a.b``'s, not ``a``'s (``a`` is a vessel
    too: the longest name wins): d P_a,in / d R_ab = 0 and d P_a,in / d R_a = Q, closed form
    (the steady state is exact to the periodic tolerance: 1e-9 relative of Q)."""
    s = oxyline.sensitivities(CHAIN, ["vessels.a.b.lumped.resistance",
                                      "vessels.a.lumped.resistance"], OUT)
    assert s.values[0] == pytest.approx(Q * (R_C + R_OUT), rel=1e-9)
    assert abs(s.jacobian[0, 0]) <= 1e-9 * Q
    assert s.jacobian[0, 1] == pytest.approx(Q, rel=1e-9)
    # the same model with the vessel renamed: the same arithmetic, the same numbers
    plain = copy.deepcopy(CHAIN)
    plain["vessels"][0]["name"] = "ab"
    r = oxyline.sensitivities(plain, ["vessels.ab.lumped.resistance",
                                      "vessels.a.lumped.resistance"], OUT)
    np.testing.assert_allclose(s.jacobian, r.jacobian, rtol=1e-12, atol=1e-12 * Q)


def test_a_dotted_vessel_name_in_calibrations_base_values() -> None:
    assert _base_value(CHAIN, "vessels.a.b.lumped.resistance") == R_AB
    assert _base_value(CHAIN, "vessels.a.lumped.resistance") == R_C


def test_a_name_of_no_vessel_names_the_path_and_the_nearest() -> None:
    """``x.b`` is one edit from ``a.b``; the path starts with no name of the model."""
    with pytest.raises(ModelError) as err:
        oxyline.sensitivities(CHAIN, ["vessels.x.b.lumped.resistance"], OUT)
    text = str(err.value)
    assert "parameter 'vessels.x.b.lumped.resistance'" in text, text
    assert "(nearest: a.b)" in text, text


@pytest.mark.parametrize(("path", "nearest"), [
    ("vessels.lv.chamber.max_elastanse", "nearest: max_elastance"),
    ("vessels.lv.chamber.activation.t_twich", "nearest: activation.t_twitch"),
    ("vessels.mitral.valve.steepnes", "nearest: steepness"),
])
def test_a_heart_key_typo_names_the_nearest_key(path: str, nearest: str) -> None:
    """In a sensitivity's parameter path and in calibration's base value alike."""
    with pytest.raises(ModelError) as err:
        oxyline.sensitivities(HEART, [path], ["lv.pressure_in.max"])
    assert f"parameter '{path}'" in str(err.value) and nearest in str(err.value), err.value
    with pytest.raises(ModelError) as err:
        _base_value(HEART, path)
    assert f"parameter '{path}'" in str(err.value) and nearest in str(err.value), err.value


def test_a_heart_key_typo_in_a_patch_is_raised_before_anything_runs() -> None:
    patches = [{}, {"vessels": {"lv": {"chamber": {"max_elastanse": 2e8}}}}]
    with pytest.raises(ModelError) as err:
        oxyline.simulate_ensemble(HEART, patches, output="summary", progress=False)
    text = str(err.value)
    assert text.startswith("variant 1: vessels.lv.chamber.max_elastanse: unknown property of "
                           "a elastance-inductor chamber (allowed: "), text
    assert text.endswith("; nearest: max_elastance)"), text
