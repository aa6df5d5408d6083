"""Every svZeroDSolver reference case with a stored result, compared on ALL its stored columns:
the drop-in must return the same variables in the same order (vessel rows,
or svZeroDSolver's variable table with its nodes, the blocks' internal variables, the heart
block's, chamber volumes and valve status) and the same numbers.

The truth is svZeroDSolver's own stored output (``tests/data/svzerod/cases/results``, written
by upstream at the commit named in its README). Error of a column: max|a − e| / scale, with
scale its range over the case (its max|e| for a column constant to the file's rounding, as the
steady cases and the means have).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pandas as pd
import pytest
from conftest import data_path

from oxyline import svzerod as svz

#: the reference files are rounded to 10 decimals (``DataFrame.to_json``): an absolute floor
#: of half a unit in the last place on top of the relative tolerance (it matters for the
#: chamber volumes of closed_loop_two_hill, 5e-5 m³ ranges in SI numbers)
ROUNDING = 0.5e-10
TOL = 1e-6

FAMILIES = {
    "vessel": ["pulsatileFlow_CRL", "pulsatileFlow_CStenosis_steadyPressure",
               "pulsatileFlow_CStenosis_steadyPressure_definedPeriod", "pulsatileFlow_R_RCR",
               "pulsatileFlow_R_RCR_variable", "pulsatileFlow_bifurcationR_RCR_cycle_error",
               "steadyFlow_RC_R", "steadyFlow_RLC_R", "steadyFlow_RL_R", "steadyFlow_R_R",
               "steadyFlow_R_RCR", "steadyFlow_R_steadyPressure", "steadyFlow_bifurcationR_R1",
               "steadyFlow_bifurcationR_R1_blockNames", "steadyFlow_bifurcationR_R2",
               "steadyFlow_blood_vessel_junction", "steadyFlow_confluenceR_R",
               "steadyFlow_stenosis_R"],
    "coronary": ["pulsatileFlow_R_coronary", "pulsatileFlow_R_coronary_varres",
                 "pulsatileFlow_R_coronary_cycle_error", "steadyFlow_R_coronary"],
    "output_options": ["pulsatileFlow_R_RCR_derivative", "pulsatileFlow_R_RCR_derivative_variable",
                       "pulsatileFlow_R_RCR_mean", "pulsatileFlow_R_RCR_mean_derivative",
                       "pulsatileFlow_R_RCR_mean_derivative_variable",
                       "pulsatileFlow_R_RCR_mean_variable"],
    "chambers_valves": ["chamber_elastance_inductor", "chamber_sphere", "valve_tanh",
                        "closed_loop_two_hill", "piecewise_Chamber_and_Valve",
                        "closedLoopHeart_singleVessel_decomposed"],
    "closed_loop": ["closedLoopHeart_singleVessel", "closedLoopHeart_withCoronaries",
                    "coupledBlock_closedLoopHeart_singleVessel",
                    "coupledBlock_closedLoopHeart_withCoronaries"],
}
#: the coronary coupled case: the heart block's on/off valves switch at iterate-dependent
#: steps, so svZeroDSolver's own reruns differ from its stored result (svzerod 3.2: 1.2e-4 of
#: the range in Q_LA:CLH; upstream's tolerance for it is 2e-1); measured 2.1e-4 (Q_LV:CLH,
#: the same against a fresh svzerod 3.2 run)
LOOSER = {"coupledBlock_closedLoopHeart_withCoronaries": 5e-4}


def case(name: str) -> dict[str, Any]:
    with open(data_path("svzerod", "cases", f"{name}.json")) as f:
        return json.load(f)


def reference(name: str) -> pd.DataFrame:
    return pd.read_json(data_path("svzerod", "cases", "results", f"result_{name}.json"))


def column_errors(actual: pd.DataFrame, expected: pd.DataFrame) -> dict[tuple[str, str], float]:
    """(variable or vessel, column) -> max|a − e| / scale beyond the rounding floor; the
    frames must have the same columns, names in the same order and the same times."""
    assert list(actual.columns) == list(expected.columns)
    names = list(dict.fromkeys(expected["name"]))
    assert list(dict.fromkeys(actual["name"])) == names
    out = {}
    for name in names:
        a, e = actual[actual["name"] == name], expected[expected["name"] == name]
        assert len(a) == len(e), name
        ta, te = a["time"].to_numpy(float), e["time"].to_numpy(float)
        assert np.array_equal(np.isnan(ta), np.isnan(te)), name
        np.testing.assert_allclose(ta[~np.isnan(ta)], te[~np.isnan(te)], atol=1e-9)
        for c in expected.columns:
            if c in ("name", "time"):
                continue
            ev, av = e[c].to_numpy(float), a[c].to_numpy(float)
            # a column constant to the file's rounding (steady cases, means) takes max|e|
            span, size = float(np.ptp(ev)), float(np.max(np.abs(ev)))
            scale = span if span > 2 * ROUNDING + 1e-9 * size else (size or 1.0)
            diff = np.maximum(np.abs(av - ev) - ROUNDING, 0.0)
            out[(name, c)] = float(np.max(diff)) / scale
    return out


def check(name: str) -> None:
    err = column_errors(svz.simulate(case(name)), reference(name))
    worst = max(err, key=err.get)
    tol = LOOSER.get(name, TOL)
    # (the cycle means of pulsatileFlow_R_RCR_mean_derivative*'s derivatives match to the
    # file's rounding: the core outputs generalized-α's own ẏ, svZeroDSolver's ẏ₀ after its
    # steady start included; docs/svzerod.md, `output_derivative`)
    for (var, col), e in err.items():
        assert e <= tol, (var, col, e, "worst", worst, err[worst])


@pytest.mark.parametrize("name", FAMILIES["vessel"])
def test_vessel_cases_every_column(name: str) -> None:
    check(name)


@pytest.mark.parametrize("name", FAMILIES["coronary"])
def test_coronary_cases_every_column(name: str) -> None:
    check(name)


@pytest.mark.parametrize("name", FAMILIES["output_options"])
def test_output_option_cases_every_column(name: str) -> None:
    check(name)


@pytest.mark.parametrize("name", FAMILIES["chambers_valves"])
def test_chamber_and_valve_cases_every_variable(name: str) -> None:
    # chamber volumes (Vc), a ChamberSphere's wall variables and the tanh valves'
    # valve_status are in the variable table, as svZeroDSolver writes them
    check(name)


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.slow) if n in LOOSER else n
    for n in FAMILIES["closed_loop"]])  # (the coronary coupled case: 100 × 1000 steps, ~1 min;
# tests/test_svzerod_sphere.py checks its every variable with upstream's rule)
def test_closed_loop_cases_every_variable(name: str) -> None:
    # the heart block's 12 internal variables (V_RA:CLH … Q_LV:CLH), the ClosedLoopRCR's P_c,
    # the closed-loop coronaries' volume_im and every node around the heart block
    check(name)


def test_every_case_with_a_result_is_in_a_family() -> None:
    stored = {p.name[len("result_"):-len(".json.gz")]
              for p in data_path("svzerod", "cases", "results").glob("result_*.json.gz")}
    listed = [n for family in FAMILIES.values() for n in family]
    assert len(listed) == len(set(listed)) and set(listed) == stored
