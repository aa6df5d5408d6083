"""Population calibration to in-vivo data (``oxyline.populations``): McEniery 2005's
statistics pooled as PWDB pools them, PWDB's 99 % ranges, and a decade's factors applied to
a subject's patch."""

from __future__ import annotations

import numpy as np
import pytest

from oxyline import ModelError
from oxyline import population_fit as F
from oxyline import populations as P


def test_pooled_statistics_are_those_of_the_merged_samples() -> None:
    """Two samples with the table's means, SDs and sizes (standardised draws): the pooled mean
    and SD are numpy's of the concatenation (1e-10: both are the same sums, in another
    order)."""
    rng = np.random.default_rng(3)
    groups = []
    for mu, sd, n in ((123.0, 10.0, 172), (113.0, 10.0, 133)):
        x = rng.standard_normal(n)
        groups.append(mu + sd * (x - x.mean()) / x.std(ddof=1))
    both = np.concatenate(groups)
    mean, sd = P._pooled((123.0, 10.0, 172), (113.0, 10.0, 133))
    assert mean == pytest.approx(both.mean(), rel=1e-10)
    assert sd == pytest.approx(both.std(ddof=1), rel=1e-10)


def test_in_vivo_interpolates_between_decades_and_ranges_are_99_percent() -> None:
    """At a decade's mid-age the pooled table value; halfway between two, the mean of theirs;
    the range is mean ± 2.575 SD (PWDB's), and outside 15-85 y an error."""
    at25, at35, at30 = P.in_vivo(25), P.in_vivo(35), P.in_vivo(30)
    men, women = P.MCENIERY["aortic_sbp"][0][1], P.MCENIERY["aortic_sbp"][2][1]
    n_m, n_w = P.MCENIERY_N[0][1], P.MCENIERY_N[1][1]
    assert at25["aortic_sbp"][0] == pytest.approx((men * n_m + women * n_w) / (n_m + n_w))
    for k in at25:
        assert at30[k][0] == pytest.approx((at25[k][0] + at35[k][0]) / 2)
    lo, hi = P.plausible_ranges(25)["brachial_pp"]
    m, s = at25["brachial_pp"]
    assert (lo, hi) == pytest.approx((m - 2.575 * s, m + 2.575 * s))
    with pytest.raises(ModelError, match="15-85"):
        P.in_vivo(90)


def test_factors_scale_every_outlet_and_the_inflow() -> None:
    row, _ = F.baseline_subject(45)
    patch = P.subject_patch(row)
    f = {"distal_resistance": 1.1, "proximal_resistance": 0.9, "capacitance": 1.3,
         "inflow": 1.05}
    out = F.apply_factors(patch, f)
    for node, bc in patch["boundary_conditions"].items():
        if node == "n1":
            np.testing.assert_allclose(out["boundary_conditions"][node]["flow"],
                                       np.asarray(bc["flow"]) * 1.05, rtol=1e-15)
            continue
        for k in F.FACTORS:
            assert out["boundary_conditions"][node][k] == pytest.approx(bc[k] * f[k],
                                                                        rel=1e-15)
    assert patch["boundary_conditions"]["n1"]["flow"] is not \
        out["boundary_conditions"]["n1"]["flow"]
