"""A result's repr is one line of facts (a notebook cell echoing a result prints it)."""

from __future__ import annotations

import oxyline


def test_result_repr_is_short_and_factual() -> None:
    res = oxyline.simulate("paper-bifurcated", cycles=1)
    text = repr(res)
    assert "\n" not in text and len(text) < 200
    # the counts of the model file: 3 vessels of 10 segments each, 1 ms output over 1 s
    assert "'paper-bifurcated': 3 vessels, 30 segments, 1001 times (0-1 s)" in text
    assert "species=['o2']" in text
