"""Space-discretisation error (``oxyline.convergence``): a uniform tube of n lumped segments
against the exact input impedance of the transmission line it stands for, computed here in
closed form,

    Z_in = Z_c (Z_T + Z_c tanh γℓ) / (Z_c + Z_T tanh γℓ),
    γ = √((r + iωl) iωc),  Z_c = √((r + iωl) / (iωc)),

r, l, c the tube's resistance, inductance and compliance per length, Z_T its outlet
resistance (mismatched, so that the line's reflections shape Z_in). The ladder converges to it
(second order in the segment's electrical length for π sections, first order for L), and the
change of one refinement must estimate the coarser model's true error: between 0.3 and 1.2
times it (Richardson: 3/4 of it for a second-order, 1/2 for a first-order ladder, up to the
next order's terms)."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline.convergence import convergence, estimate_space_error, refined

LENGTH = 0.2  # m
R, L, C = 2.0e7, 1.4e7, 3.0e-10  # whole tube: Pa s/m^3, Pa s^2/m^3, m^3/Pa (c ~ 3.1 m/s)
Z_T = 3.0e8  # outlet resistance, ~1/3 of the line's characteristic impedance
FREQS = np.array([1.0, 3.0, 6.0, 10.0])  # Hz: up to ~2/3 of a wavelength along the tube


def tube(arrangement: str, segments: int) -> dict[str, Any]:
    return {"name": "tube", "units": "SI", "arrangement": arrangement, "period": 1.0,
            "vessels": [{"name": "v", "from": "in", "to": "out", "segments": segments,
                         "lumped": {"resistance": R, "inductance": L, "capacitance": C}}],
            "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                    "out": {"type": "resistance", "resistance": Z_T}}}


def exact(f: np.ndarray) -> np.ndarray:
    w = 2 * np.pi * f
    z, y = (R + 1j * w * L) / LENGTH, 1j * w * C / LENGTH
    g, zc = np.sqrt(z * y), np.sqrt(z / y)
    t = np.tanh(g * LENGTH)
    return zc * (Z_T + zc * t) / (zc + Z_T * t)


@pytest.mark.parametrize(("arrangement", "order"), [("pi", 2), ("L", 1)])
def test_refinement_converges_to_the_transmission_line_and_estimates_the_error(
        arrangement: str, order: int) -> None:
    want = exact(FREQS)
    levels = convergence(tube(arrangement, 4), "in", FREQS, levels=4)
    assert [lv.segments for lv in levels] == [4, 8, 16, 32]
    errs = [np.abs(lv.impedance - want) / np.abs(want) for lv in levels]
    # the ladder converges to the line at its order (each doubling cuts the error ~2^order)
    for coarse, fine in itertools.pairwise(errs):
        ratio = coarse / fine
        assert np.all(ratio > 0.7 * 2**order), (arrangement, ratio)
    # one refinement's change estimates the coarser level's true error
    for k in range(1, len(levels)):
        est = levels[k].change
        assert np.all((0.3 * errs[k - 1] <= est) & (est <= 1.2 * errs[k - 1])), (
            arrangement, k, est / errs[k - 1])
    est = estimate_space_error(tube(arrangement, 4), "in", FREQS)
    np.testing.assert_allclose(est, levels[1].change, rtol=1e-12)


def test_bad_refinement_is_a_model_error() -> None:
    with pytest.raises(oxyline.ModelError, match="refinement factor"):
        refined(tube("pi", 2), 0)
    with pytest.raises(oxyline.ModelError, match="levels"):
        convergence(tube("pi", 2), "in", FREQS, levels=1)
