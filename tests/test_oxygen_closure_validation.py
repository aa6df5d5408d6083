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

from oxyline.reference.validation import load_case, one_d, scenarios

DATA = json.loads((Path(__file__).parent / "data" / "oxygen_2d_uptakes.json").read_text())
STORED = {(r["case"], r["scenario"]): r for r in DATA["cases"]}
DEFAULT = {"model": "graetz"}  # forward-mean flow is the default


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
    validation): every row within 2 % of the stored 2-D uptake (measured worst +1.71 %)."""
    from oxyline.reference.validation import END_RENEWAL_C, end_renewal_number

    worst = 0.0
    for (case_name, label), row in STORED.items():
        case = load_case(case_name)
        flow = dict(scenarios(case))[label]
        fwd = one_d(case, flow, DEFAULT)[0]
        s = end_renewal_number(case, flow, fwd)
        law = {**DEFAULT, "enhancement": 1.0 + END_RENEWAL_C * s}
        worst = max(worst, abs(one_d(case, flow, law)[0] / row["womersley_mixed"] - 1))
    assert worst < 0.02
