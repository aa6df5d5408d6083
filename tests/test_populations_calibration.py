"""Population calibration to in-vivo data (``oxyline.populations``): McEniery 2005's
statistics pooled as PWDB pools them, PWDB's 99 % ranges, and a decade's factors applied to
a subject's patch."""

from __future__ import annotations

from typing import Any

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


def _contradictions(table: dict) -> list[tuple[str, int, float, float]]:
    """The groups whose aortic PP differs by more than 2 mmHg from their own brachial PP over
    amplification or aortic SBP minus brachial DBP (aortic and brachial DBP agree within
    ~1 mmHg: the pressure's mean and diastole change little along the large arteries)."""
    out = []
    for g, sex in ((0, "men"), (2, "women")):
        for i, age in enumerate(P.MCENIERY_AGES):
            app = table["aortic_pp"][g][i]
            by_amp = table["brachial_pp"][g][i] / table["pp_amplification"][g][i]
            by_dbp = table["aortic_sbp"][g][i] - table["brachial_dbp"][g][i]
            if max(abs(app - by_amp), abs(app - by_dbp)) > 2.0:
                out.append((sex, age, by_amp, by_dbp))
    return out


def test_the_fit_table_agrees_with_each_groups_other_characteristics() -> None:
    """The transcribed table contradicts itself in one group (women, 75 y: 56 against 45.4
    and 47); the fit's table (``in_vivo(age, fit=True)``) in none, and differs from it only
    there; the 99 % ranges keep PWDB's value."""
    bad = _contradictions(P.MCENIERY)
    assert [(s, a) for s, a, *_ in bad] == [("women", 75)]
    assert bad[0][2] == pytest.approx(45.4, abs=0.05) and bad[0][3] == 47
    assert _contradictions(P.MCENIERY_FIT) == []
    n_m, n_w = P.MCENIERY_N[0][6], P.MCENIERY_N[1][6]
    assert P.in_vivo(75, fit=True)["aortic_pp"][0] == pytest.approx(
        (42 * n_m + 46 * n_w) / (n_m + n_w))
    assert P.in_vivo(75)["aortic_pp"][0] == pytest.approx((42 * n_m + 56 * n_w) / (n_m + n_w))
    for age in (25, 65, 85):
        assert P.in_vivo(age, fit=True) == P.in_vivo(age)
    assert P.plausible_ranges(75)["aortic_pp"][1] > 60  # PWDB's, with the transcribed 56


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


def test_characteristics_and_their_jacobian_from_known_pressures_and_feet() -> None:
    """Outputs made from known pressures and root-to-site transit times: the amplification is
    brachial PP over aortic PP, the cf-PWV the aorta-femoral minus aorta-carotid length over
    the difference of the mid-site transit times (PWDB's convention), and the complex-step
    Jacobian equals the analytic one (1e-12: both exact, rounding only)."""
    mm = 133.322387415
    lengths = np.array([0.08, 0.15, 0.60, 1.04])          # carotid in/out, femoral in/out
    times = np.array([0.010, 0.030, 0.070, 0.120])        # root-to-site feet [s]
    values = np.array([110 * mm, 32 * mm, 122 * mm, 76 * mm, 1e-4, *(lengths / times)])
    c = dict(zip(F.CHARACTERISTICS, F.characteristics(values, lengths), strict=True))
    assert c["pp_amplification"] == pytest.approx((122 - 76) / 32, rel=1e-14)
    cf = ((0.60 + 1.04) / 2 - (0.08 + 0.15) / 2) / ((0.070 + 0.120) / 2 - (0.010 + 0.030) / 2)
    assert c["cf_pwv"] == pytest.approx(cf, rel=1e-14)
    assert c["co"] == pytest.approx(6.0, rel=1e-14)
    jac = F._characteristics_jacobian(values, lengths)
    amp = F.CHARACTERISTICS.index("pp_amplification")
    expect = np.zeros(len(values))
    expect[[1, 2, 3]] = [-(122 - 76) / 32**2 / mm, 1 / 32 / mm, -1 / 32 / mm]
    np.testing.assert_allclose(jac[amp], expect, rtol=1e-12, atol=1e-20)
    # d cf / d pwv_k: t_k = L_k / v_k, dt_k / dv_k = -t_k / v_k; d cf / d t = -cf / Δt (±1/2)
    dt = (0.070 + 0.120) / 2 - (0.010 + 0.030) / 2
    signs = np.array([-0.5, -0.5, 0.5, 0.5])
    d_pwv = -cf / dt * signs * (-times / values[5:])
    np.testing.assert_allclose(jac[F.CHARACTERISTICS.index("cf_pwv"), 5:], d_pwv, rtol=1e-12)


def test_stiffness_factors_scale_the_arm_and_aortic_walls_only() -> None:
    row, _ = F.baseline_subject(55)
    patch = P.subject_patch(row)
    out = F.apply_factors(patch, {"arm_stiffness": 1.5, "aortic_stiffness": 0.8})
    for name, v in patch["vessels"].items():
        f = 1.5 if ("brachial" in name or "radial" in name or "digital" in name) else \
            0.8 if name.startswith(("ascending_aorta", "abdominal_aorta", "descending")) \
            else None
        if f is None and ("carotid" in name or "femoral" in name or "iliac" in name):
            f = 1.0
        if f is not None:
            assert out["vessels"][name]["youngs_modulus"] == pytest.approx(
                v["youngs_modulus"] * f, rel=1e-15), name
    with pytest.raises(ModelError, match="unknown factors.*leg_stiffness"):
        F.apply_factors(patch, {"leg_stiffness": 1.1})


def _summary(amp: float, pp_a: float = 33.0) -> dict[str, float]:
    """A subject summary with aortic PP ``pp_a`` and amplification ``amp`` around the 45-y
    means (brachial DBP 77, MAP 94)."""
    return {"aortic_root_sbp": 78.0 + pp_a, "aortic_root_dbp": 78.0,
            "brachial_sbp": 77.0 + amp * pp_a, "brachial_dbp": 77.0, "brachial_map": 94.0}


def test_implausible_names_the_characteristic_value_and_range() -> None:
    """Inside every 99 % range: nothing; an amplification of 2.0 at 45 y (range 1.34 ± 2.575
    x 0.16, up to ~1.76): the one record, with its value and PWDB's range."""
    assert F.implausible(45, _summary(1.35)) == []
    bad = F.implausible(45, _summary(2.0))
    names = [b["characteristic"] for b in bad]
    assert "pp_amplification" in names
    rec = bad[names.index("pp_amplification")]
    lo, hi = P.plausible_ranges(45)["pp_amplification"]
    assert rec["value"] == pytest.approx(2.0) and (rec["low"], rec["high"]) == (lo, hi)
    assert rec["value"] > hi


def test_population_excludes_the_implausible_and_lists_them() -> None:
    """PWDB's rule on a stand-in run (no simulation; subjects run in the given order, the
    2nd and 4th given an implausible amplification): ``plausible_only`` drops exactly those
    from the table and lists each with its value; without it every subject is kept and the
    same ones are listed."""
    picks = [0, 1, 2, 300, 728]
    high = {picks[1], picks[3]}

    def stand_in() -> Any:
        calls = iter(range(len(picks)))

        def run(model: dict) -> dict[str, float]:
            assert model["boundary_conditions"]["n1"]["flow"]   # a subject's model dict
            return _summary(2.0 if next(calls) in (1, 3) else 1.35)
        return run

    kept = F.population((45,), subjects=picks, plausible_only=True, run=stand_in())
    assert set(kept.excluded["subject"]) == high
    assert list(kept.table.index) == [i for i in picks if i not in high]
    assert len(kept.summaries) == len(kept.patches) == len(picks) - len(high)
    amp = kept.excluded[kept.excluded["characteristic"] == "pp_amplification"]
    np.testing.assert_allclose(amp["value"], 2.0)
    every = F.population((45,), subjects=picks, run=stand_in())
    assert len(every.table) == len(picks)
    assert set(every.excluded["subject"]) == high
    with pytest.raises(ModelError, match="subject 729"):
        F.population((45,), subjects=[729], run=stand_in())


def test_a_shrunk_subject_is_the_factorial_subject_at_those_levels() -> None:
    """A 45-y subject at +-1 SD (3 levels) with its levels halved is the 5-level factorial's
    subject at +-0.5 SD (HR, SV, MBP, diameter, cf-PWV target, CO: 1e-12, the same formulas
    in another order); at 0 it is the decade's baseline, at 1 itself (LVET included: PWDB
    normalises LVET over the factorial, so in between it is interpolated, not compared)."""
    three, five = P.parameters((45,), 3), P.parameters((45,), 5)
    levels = [f"{p}_sd" for p in P.VARIED]
    row = three.iloc[int(np.flatnonzero((three[levels].values == [1, -1, 1, 1, -1, 1])
                                        .all(axis=1))[0])].to_dict()
    half = five[(five[levels].values == [0.5, -0.5, 0.5, 0.5, -0.5, 0.5]).all(axis=1)]
    moved = F.shrunk_row(row, 0.5)
    for k in ("hr", "sv", "mbp", "dia", "pwv", "co", *levels):
        assert moved[k] == pytest.approx(float(half[k].iloc[0]), rel=1e-12, abs=1e-12), k
    base = three[(three[levels] == 0).all(axis=1)].iloc[0]
    for k in ("hr", "sv", "mbp", "dia", "pwv", "co", "lvet"):
        assert F.shrunk_row(row, 0.0)[k] == pytest.approx(float(base[k]), rel=1e-12), k
        assert F.shrunk_row(row, 1.0)[k] == pytest.approx(float(row[k]), rel=1e-12), k
    assert min(base["lvet"], row["lvet"]) < moved["lvet"] < max(base["lvet"], row["lvet"])
    with pytest.raises(ModelError, match="fraction 1.5"):
        F.shrunk_row(row, 1.5)


def test_population_resamples_the_implausible_towards_the_baseline() -> None:
    """A stand-in run (no simulation) that reads each subject's stroke volume from its inflow
    and gives it an implausible amplification above a volume: the subjects above are moved
    towards the baseline by the first fraction of :data:`SHRINK` whose volume is below it,
    listed in ``excluded`` (as generated) and ``resampled``; the table keeps every subject,
    with the moved values; none of its summaries is outside a range."""
    table = P.parameters((45,), 3)
    picks = [0, 364, 728]          # all levels -1, the baseline, all +1
    sv = table["sv"].iloc[picks].to_numpy()
    limit = sv[1] + 0.35 * (sv[2] - sv[1])   # the +1-SD subject above, down to fraction 0.3

    def run(model: dict) -> dict[str, float]:
        bc = model["boundary_conditions"]["n1"]
        volume = np.trapezoid(bc["flow"], bc["time"]) * 1e6
        return _summary(2.0 if volume > limit else 1.35)

    pop = F.population((45,), subjects=picks, resample=True, run=run)
    assert list(pop.table.index) == picks
    assert list(pop.resampled["subject"]) == [728]
    assert pop.resampled["fraction"].iloc[0] == pytest.approx(0.3)
    assert set(pop.excluded["subject"]) == {728}
    assert pop.table.loc[728, "sv"] == pytest.approx(sv[1] + 0.3 * (sv[2] - sv[1]), rel=1e-12)
    assert list(pop.table["fraction"]) == [1.0, 1.0, 0.3]
    for i, s in zip(pop.table.index, pop.summaries.to_dict("records"), strict=True):
        assert not F.implausible(45, s), i

    # a subject whose baseline too is outside leaves the table and stays listed
    def never(model: dict) -> dict[str, float]:
        return _summary(2.0)

    out = F.population((45,), subjects=[728], resample=True, run=never)
    assert len(out.table) == 0 and len(out.resampled) == 0
    assert set(out.excluded["subject"]) == {728}


@pytest.mark.slow
def test_baseline_fit_brings_amplification_to_the_in_vivo_mean() -> None:
    """45 y (the baseline's amplification 1.53 against McEniery's 1.34 ± 0.16): after the
    fit every characteristic is within 0.5 in-vivo SD of its target (the prior lets none be
    exact), the amplification closer than before, by stiffer arms (the factor with the
    largest effect on it), and the cardiac output held to 1 %."""
    out = F.calibrate_baseline(45)
    for k in F.CHARACTERISTICS:
        assert abs(out["after"][k] - out["target"][k]) < 0.5 * out["sigma"][k], k
    amp = "pp_amplification"
    assert abs(out["after"][amp] - out["target"][amp]) < \
        0.5 * abs(out["before"][amp] - out["target"][amp])
    assert out["factors"]["arm_stiffness"] > 1.1
    assert out["after"]["co"] == pytest.approx(out["target"]["co"], rel=0.01)


def test_a_high_pulse_pressure_subject_is_resampled_inside_the_ranges() -> None:
    """A real run: the 75-y subject at +1 SD stroke volume and stiffness and -1 SD diameter
    (the factorial's high-pulse-pressure corner, outside McEniery 2005's 99 % range of the
    pulse pressure) is moved towards the baseline until its simulated characteristics are
    inside every range; the move kept is the first of :data:`SHRINK` that is, so the one
    before it (if any) was outside."""
    table = P.parameters((75,), 3)
    levels = [f"{p}_sd" for p in P.VARIED]      # hr, sv, lvet, pwv, dia, mbp
    i = int(np.flatnonzero((table[levels].values == [0, 1, 0, 1, -1, 0]).all(axis=1))[0])
    pop = F.population((75,), subjects=[i], resample=True)
    assert set(pop.excluded["subject"]) == {i}
    assert any("pp" in c for c in pop.excluded["characteristic"])
    fraction = float(pop.resampled["fraction"].iloc[0])
    assert 0.0 <= fraction < 1.0
    summary = pop.summaries.iloc[0].to_dict()
    assert not F.implausible(75, summary)
    assert pop.table.loc[i, "sv"] < table.loc[i, "sv"]
