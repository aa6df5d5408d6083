"""The default wall closure against the 2-D reference's uptakes stored in
tests/data/oxygen_2d_uptakes.json (docs/validation-oxygen.md §6, §8): the issue-12 target of
2 % on the cycle-mean wall uptake, the known aortic miss, and the reference's outlet condition
that decides it. The 2-D values are data (the reference solver is tested in
test_reference_axisymmetric.py); only the 1-D model runs here."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("scipy")

from validation.closures import load_case, one_d, scenarios

DATA = json.loads((Path(__file__).parent / "data" / "oxygen_2d_uptakes.json").read_text())
STORED = {(r["case"], r["scenario"]): r for r in DATA["cases"]}
#: the default before the inlet-renewal fit (still selectable by name); the tests of this name document
#: its errors against the outlet-dependent references of §6–§12
DEFAULT = {"model": "graetz", "flow": "forward-mean"}


def _default_uptake(case_name: str, label: str) -> float:
    case = load_case(case_name)
    flow = dict(scenarios(case))[label]
    return one_d(case, flow, DEFAULT)[0]


def test_the_aortic_example_against_both_outlet_conditions() -> None:
    """paper-straight's own waveform: −2.34 % against the reference whose backflow re-enters
    mixed (flat, bulk PO2: it renews the near-wall layer at the outlet, §8) — the one case
    outside 2 % — and −0.10 % against the same reference with the layer continuing through
    the outlet (`backflow="profile"`). Tolerances: the measured values ± 0.1 % (the 1-D run
    is deterministic; the margin absorbs platform round-off in 12 cycles)."""
    label = next(k for c, k in STORED if c == "straight" and k.startswith("example"))
    row = STORED[("straight", label)]
    up = _default_uptake("straight", label)
    assert up / row["womersley_mixed"] - 1 == pytest.approx(-0.0234, abs=1e-3)
    assert abs(up / row["womersley_profile"] - 1) < 0.02


def test_the_default_closure_is_within_2_percent_of_the_reference_except_the_aorta() -> None:
    """Every scenario of docs/validation-oxygen.md §6 (27 rows): the default within 2 % of the
    stored 2-D uptake (mixed backflow), except the aortic example waveform (−2.34 %, §8)."""
    misses = {}
    for (case, label), row in STORED.items():
        err = _default_uptake(case, label) / row["womersley_mixed"] - 1
        if abs(err) > 0.02:
            misses[(case, label)] = err
    assert list(misses) == [("straight", next(k for c, k in STORED
                                              if c == "straight" and k.startswith("example")))]


def test_the_end_renewal_candidate_is_within_2_percent_everywhere() -> None:
    """The emulated end-renewal candidate of docs/validation-oxygen.md §8 (the default law
    times 1 + 0.035 s, s the Womersley near-wall excursion number; one constant fitted to
    these rows, so this guards the emulation and the stored data, it is not an independent
    validation): every row within 2 % of the stored 2-D uptake (measured worst +1.71 %). It
    fails on vessels outside these rows (§11, `test_the_end_renewal_candidate_on_held_out_
    vessels`), which is why it stays an emulation."""
    from validation.closures import END_RENEWAL_C, end_renewal_number

    worst = 0.0
    for (case_name, label), row in STORED.items():
        case = load_case(case_name)
        flow = dict(scenarios(case))[label]
        fwd = one_d(case, flow, DEFAULT)[0]
        s = end_renewal_number(case, flow, fwd)
        law = {**DEFAULT, "enhancement": 1.0 + END_RENEWAL_C * s}
        worst = max(worst, abs(one_d(case, flow, law)[0] / row["womersley_mixed"] - 1))
    assert worst < 0.02


HELDOUT = {r["case"]: r for r in json.loads(
    (Path(__file__).parent / "data" / "oxygen_2d_heldout.json").read_text())["cases"]}
#: the default's error vs the stored 'mixed' 2-D uptake of the held-out aortas (docs/validation-
#: oxygen.md §11): the Womersley end renewal that no cycle-mean law sees
HELDOUT_AORTIC_MISS = {"infrarenal aorta": -0.0330, "ascending aorta": -0.1321,
                       "paper aorta, L 5 cm": -0.0734, "thoracic aorta at exercise": -0.0437}


def _heldout() -> list:
    from validation.closures import heldout_cases

    return heldout_cases()


def test_the_default_closure_on_held_out_vessels() -> None:
    """The held-out vessels of docs/validation-oxygen.md §11 (none of them used to choose or fit
    a closure): the default within 2 % of the stored 2-D uptake where the Womersley near-wall
    reversal is weak (carotid, femoral, coronary at exercise, the aorta with a lower D), and the
    documented misses of the large-α aortas reproduced (measured value ± 0.1 %: the 1-D run is
    deterministic, the margin absorbs platform round-off over 12 cycles)."""
    for name, case in _heldout():
        err = one_d(case, case.flow, DEFAULT)[0] / HELDOUT[name]["womersley_mixed"] - 1
        miss = next((v for k, v in HELDOUT_AORTIC_MISS.items() if name.startswith(k)), None)
        if miss is None:
            assert abs(err) < 0.02, (name, err)
        else:
            assert err == pytest.approx(miss, abs=1e-3), (name, err)


@pytest.mark.xfail(strict=True, reason="docs/validation-oxygen.md §11: the end-renewal "
                   "candidate, fitted to the 27 rows of §8, misses the held-out aortas by "
                   "-2.5 to -11.7 %")
def test_the_end_renewal_candidate_on_held_out_vessels() -> None:
    """The candidate k (1 + 0.035 s) on vessels it was not fitted to: within 2 % of the stored
    2-D uptake in every held-out row (the issue-12 target). Expected to fail (strict): if a
    change makes it pass, §11 and the default must be revisited."""
    from validation.closures import END_RENEWAL_C, end_renewal_number

    worst = 0.0
    for name, case in _heldout():
        fwd = one_d(case, case.flow, DEFAULT)[0]
        s = end_renewal_number(case, case.flow, fwd)
        law = {**DEFAULT, "enhancement": 1.0 + END_RENEWAL_C * s}
        up = one_d(case, case.flow, law)[0]
        worst = max(worst, abs(up / HELDOUT[name]["womersley_mixed"] - 1))
    assert worst < 0.02


def test_the_inlet_renewal_candidate_on_held_out_vessels() -> None:
    """The inlet-renewal candidate of docs/validation-oxygen.md §12 (the Graetz law of the net
    mean flow plus A 2πRαΔP D B^{3/2}/sqrt(γ̄T), A fitted to the 27 rows of §2) on the 20
    held-out vessels, against the reference with the layer continuing through the outlet: the
    issue-12 target of 2 % (measured worst −0.95 %, the paper aorta 5 cm long), where the
    default misses by up to −7.8 % (the ascending aorta at exercise)."""
    from validation.closures import heldout_cases_2, heldout_cases_3, inlet_renewal_uptake

    worst, worst_default = 0.0, 0.0
    for name, case in _heldout() + heldout_cases_2() + heldout_cases_3():
        ref = HELDOUT[name]["womersley_profile"]
        worst = max(worst, abs(inlet_renewal_uptake(case, case.flow) / ref - 1))
        worst_default = max(worst_default, abs(one_d(case, case.flow, DEFAULT)[0] / ref - 1))
    assert worst < 0.02
    assert worst_default > 0.07


def test_wall_shear_is_the_gradient_of_the_womersley_profile() -> None:
    """`wall_shear` (which gives B) against a finite difference of the reference solver's own
    Womersley profile at the wall (validated in test_reference_axisymmetric.py), for the
    aortic example's two harmonics (Womersley 11 and 15.6): the sign error fixed earlier
    gave a 100 % difference in the oscillating part. Tolerance 1e-4 of the peak: the one-sided
    difference with step 1e-6 of the radius."""
    import math

    import numpy as np

    from validation.axisymmetric import womersley_shape
    from validation.closures import wall_shear

    case = load_case("straight")
    flow = case.flow
    t = np.linspace(0.0, flow.period, 500, endpoint=False)
    r, h = case.radius, 1e-6
    expected = np.full_like(t, 4.0 * flow.mean / (math.pi * r**3))
    for k, qk in flow.harmonics():
        a = case.tube().womersley(flow.period / k)
        edge = womersley_shape(np.array([1.0 - h, 1.0]), a)
        slope = (edge[0] - edge[1]) / h  # −d(shape)/dρ at the wall
        expected = expected + np.real(qk / (math.pi * r**3) * slope
                                      * np.exp(2j * math.pi * k * t / flow.period))
    got = wall_shear(case, flow, t)
    assert np.abs(got - expected).max() < 1e-4 * np.abs(expected).max()
