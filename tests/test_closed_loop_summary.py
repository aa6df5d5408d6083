"""The closed loop's summary and flow-weighted means, computed by the core
(``oxyline_core::transport::closed_loop_summary``), against their definitions evaluated here
in numpy on the recorded cycle the result exposes (flow-weighted cycle means of the ejected
blood, cycle-mean VO2 and uptake, Fick's and the mass-balance residuals). The core sums in
numpy's pairwise order, so the two agree to rounding; held to 1e-13 relative (a different
summation order would move them by ~1e-16 per term, far below; a wrong weight or term by
1e-3 or more)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import closed_loop
from oxyline.closed_loop import ML_O2, ClosedLoopO2Result

RTOL = 1e-13


def _weighted(r: ClosedLoopO2Result, var: np.ndarray, branch: str, compartment: str) -> float:
    q = r.flow[:, r.branches.index(branch)]
    return float(np.sum(q * var[:, r.compartments.index(compartment)]) / np.sum(q))


def _reference(r: ClosedLoopO2Result) -> dict[str, Any]:
    """The summary's definitions on the recorded arrays."""
    left = r.compartments.index("left_heart")
    q_a = r.tree.inflow if r.tree is not None else r.flow[:, r.branches.index("ejection_left")]

    def arterial(var: np.ndarray) -> float:
        return float(np.sum(q_a * var[:, left]) / np.sum(q_a))

    to_ml_min = 60.0 / ML_O2
    wall = r.tree.wall if r.tree is not None else np.zeros(len(r.time))
    vo2 = float(r.vo2.sum(axis=1).mean() + wall.mean())
    co = float(q_a.mean())
    ca = (float(np.sum(r.tree.in_flux) / np.sum(r.tree.inflow)) if r.tree is not None
          else arterial(r.total))
    cv = _weighted(r, r.total, "ejection_right", "right_heart")
    n = np.concatenate([[r.amount_start], r.amount])
    rate = r.uptake.sum(axis=1) - r.vo2.sum(axis=1) - wall
    out = {
        "SaO2": arterial(r.saturation),
        "SvO2": _weighted(r, r.saturation, "ejection_right", "right_heart"),
        "PaO2": arterial(r.po2), "PvO2": _weighted(r, r.po2, "ejection_right", "right_heart"),
        "CaO2": ca / ML_O2 * 1e-3, "CvO2": cv / ML_O2 * 1e-3,
        "VO2": vo2 * to_ml_min,
        "VO2_organs": {c: float(r.vo2[:, i].mean()) * to_ml_min
                       for i, c in enumerate(r.compartments) if np.any(r.vo2[:, i])},
        "VO2_tree_wall": float(wall.mean()) * to_ml_min,
        "lung_uptake": float(r.uptake.sum(axis=1).mean()) * to_ml_min,
        "cardiac_output": co * 6e4,
        "fick_residual": abs(vo2 - co * (ca - cv)) / vo2,
        "mass_balance_residual": float(np.max(np.abs(np.diff(n) - r.dt * rate)) / np.max(n)),
        "cycles": r.cycles, "periodic_error": r.periodic_error,
    }
    if r.tree is not None:
        out["DO2_organs"] = {k: float(r.tree.out_flux[:, i].mean()) * to_ml_min
                             for i, k in enumerate(r.tree.outlets)}
    return out


def _check(r: ClosedLoopO2Result) -> None:
    got, want = r.summary(), _reference(r)
    assert list(got) == list(want)
    for key, w in want.items():
        g = got[key]
        if isinstance(w, dict):
            assert list(g) == list(w), key
            for k in w:
                assert g[k] == pytest.approx(w[k], rel=RTOL, abs=0.0), f"{key}.{k}"
        elif key in ("fick_residual", "mass_balance_residual"):
            # a residual is a difference of nearly equal terms: held to their scale
            assert abs(g - w) <= 1e-15, key
        else:
            assert g == pytest.approx(w, rel=RTOL, abs=0.0), key


@pytest.fixture(scope="module")
def table() -> ClosedLoopO2Result:
    p = closed_loop.load("closed-loop-o2")
    p["dt"], p["flows"] = 4e-3, "table"
    return closed_loop.simulate_o2(p)


def test_summary_of_the_prescribed_flows_is_its_definitions(table: ClosedLoopO2Result) -> None:
    _check(table)
    assert table.summary()["fick_residual"] <= 1e-10


def test_summary_of_the_heart_block_and_tree_loops_is_their_definitions() -> None:
    for name in ("closed-loop-o2", "closed-loop-o2-tree"):
        p = closed_loop.load(name)
        p["dt"] = 4e-3
        r = closed_loop.simulate_o2(p)
        _check(r)
        assert r.summary()["fick_residual"] <= 1e-10, name
        assert ("DO2_organs" in r.summary()) == (name == "closed-loop-o2-tree")


def test_flow_weighted_means_of_every_variable_branch_and_compartment(
        table: ClosedLoopO2Result) -> None:
    r = table
    for name in ("volume", "total", "po2", "saturation", "vo2"):
        var = getattr(r, name)
        for b in r.branches:
            for c in r.compartments:
                want = _weighted(r, var, b, c)
                assert r.flow_weighted(var, b, c) == pytest.approx(want, rel=RTOL, abs=1e-300)
                assert r.flow_weighted(name, b, c) == r.flow_weighted(var, b, c)


def test_flow_weighted_names_what_it_accepts(table: ClosedLoopO2Result) -> None:
    with pytest.raises(ValueError, match="volume, total, po2, saturation, vo2"):
        table.flow_weighted(table.po2 * 2.0, "ejection_left", "left_heart")
    with pytest.raises(ValueError, match="not in list"):
        table.flow_weighted("po2", "no_branch", "left_heart")


def test_summary_is_a_copy(table: ClosedLoopO2Result) -> None:
    s = table.summary()
    s["VO2_organs"].clear()
    assert table.summary()["VO2_organs"]


def test_heart_run_options_are_the_cores() -> None:
    """svZeroDSolver's block runs with an absolute Newton tolerance of 1e-10 (docs/oxygen.md),
    the native heart without one; an unknown heart is named."""
    p = closed_loop.load("closed-loop-o2")
    assert closed_loop.heart_run_options(p) == {"newton_atol": 1e-10}
    assert closed_loop.heart_run_options({**p, "heart": "two-ventricle"}) == {}
    with pytest.raises(oxyline.ModelError, match="heart must be one of .*'pump'"):
        closed_loop.heart_run_options({**p, "heart": "pump"})
