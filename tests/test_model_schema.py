"""The core's model schema on values Python's old checks could not even compare: a list or a
mapping where a heart element's law or activation kind is expected is a ModelError naming the
vessel and the value, never a raw TypeError."""

from __future__ import annotations

from typing import Any

import pytest

import oxyline


def _with_chamber(chamber: dict[str, Any]) -> dict[str, Any]:
    return {"name": "h", "period": 1.0,
            "vessels": [{"name": "LV", "from": "pv", "to": "ao", "chamber": chamber},
                        {"name": "aorta", "from": "ao", "to": "out", "length": 0.05,
                         "radius": 0.01}],
            "boundary_conditions": {"pv": {"type": "pressure", "value": 1000.0},
                                    "out": {"type": "resistance", "resistance": 1e8}}}


CHAMBER = {"law": "linear", "max_elastance": 1e8, "passive_elastance": 1e6,
           "rest_volume": 1e-5, "period": 1.0,
           "activation": {"kind": "half-cosine", "t_active": 0.2, "t_twitch": 0.3}}


@pytest.mark.parametrize("edit, pattern", [
    ({"law": [1.0, 2.0]}, (r"vessel 'LV': chamber law must be one of \['elastance-inductor', "
                           r"'exponential', 'linear'\], got \[1\.0, 2\.0\]")),
    ({"law": {"a": 1}}, r"chamber law .* got \{'a': 1\}"),
    ({"activation": {"kind": [1]}}, r"vessel 'LV': chamber needs an 'activation' with kind"),
])
def test_an_unhashable_law_or_kind_is_a_model_error(edit: dict[str, Any], pattern: str) -> None:
    oxyline.load_model(_with_chamber(CHAMBER))  # the unedited model is valid
    with pytest.raises(oxyline.ModelError, match=pattern):
        oxyline.load_model(_with_chamber({**CHAMBER, **edit}))
