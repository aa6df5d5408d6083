"""The svZeroDSolver drop-in's remaining options against the peer: initial conditions
(``initial_condition`` of pressures and flows, ``initial_condition_d``), the cycle-to-cycle
rule without RCR, and the coronary outlets' zero start. Truths: the stored reference results
(``tests/data/svzerod/cases``) and fresh runs of the peer itself (PyPI ``svzerod``)."""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np
import pandas as pd
import pytest
from conftest import data_path

import oxyline
from oxyline import svzerod as svz

CASES = data_path("svzerod", "cases")
# generalized-alpha against the stored references: the drop-in runs svZeroDSolver's own
# discretisation, so only the references' rounding (10 decimals) and Newton's stop remain
GEN_ALPHA_TOL = 1e-6


def config(name: str) -> dict[str, Any]:
    return json.loads((CASES / f"{name}.json").read_text())


def reference(name: str) -> pd.DataFrame:
    return pd.read_json(data_path("svzerod", "cases", "results", f"result_{name}.json"))


def scaled_error(actual: pd.DataFrame, expected: pd.DataFrame) -> float:
    """max over value columns of max|a − e| / max|e|, after checking the layout."""
    assert list(actual.columns) == list(expected.columns)
    assert list(actual["name"]) == list(expected["name"])
    np.testing.assert_allclose(actual["time"], expected["time"], rtol=0, atol=1e-9)
    cols = [c for c in expected.columns if c not in ("name", "time")]
    return max(float(np.max(np.abs(actual[c].to_numpy(float) - expected[c].to_numpy(float)))
                     / max(np.max(np.abs(expected[c].to_numpy(float))), 1e-12)) for c in cols)


def peer(cfg: dict[str, Any]) -> pd.DataFrame:
    svzerod = pytest.importorskip("svzerod")
    return svzerod.simulate(copy.deepcopy(cfg))


#: the stored references keep 10 decimals: an absolute rounding of 5e-11, which is 1e-6 of the
#: range of closed_loop_two_hill's SI flows and volumes (m^3/s, m^3)
ROUNDING = 5e-11


def compare(actual: pd.DataFrame, expected: pd.DataFrame, rounding: float = 0.0
            ) -> dict[str, float]:
    """Variable-based frames: (max|a − e| − rounding) / range(e) per variable (same times);
    the variables must come in svZeroDSolver's order."""
    names = list(actual["name"].unique())
    assert [n for n in expected["name"].unique() if n in names] == names
    out = {}
    for name, a in actual.groupby("name", sort=False):
        e = expected[expected["name"] == name]
        np.testing.assert_allclose(a["time"].to_numpy(), e["time"].to_numpy(), atol=1e-9)
        ev, av = e["y"].to_numpy(float), a["y"].to_numpy(float)
        scale = max(np.ptp(ev), 1e-12 * max(np.max(np.abs(ev)), 1.0), 1e-300)
        out[name] = float(max(np.max(np.abs(av - ev)) - rounding, 0.0) / scale)
    return out


# ------------------------------------------------------------------------------------------
# initial conditions


@pytest.mark.parametrize("name", ["piecewise_Chamber_and_Valve", "closed_loop_two_hill"])
def test_initial_condition_cases_match_reference(name: str) -> None:
    # chambers, piecewise valves and vessels (BloodVesselCRL in closed_loop_two_hill) started
    # from the file's node pressures, flows and chamber volumes; closed loops, no condition
    actual, expected = svz.simulate(config(name)), reference(name)
    errors = compare(actual, expected, ROUNDING)
    assert len(errors) >= 32
    # 1e-6 of each variable's range beyond the references' rounding
    assert max(errors.values()) <= GEN_ALPHA_TOL, errors


def test_closed_loop_two_hill_matches_svzerod() -> None:
    # the same without the references' rounding: a fresh svzerod run, every variable (Vc too)
    cfg = config("closed_loop_two_hill")
    errors = compare(svz.simulate(cfg), peer(cfg))
    assert max(errors.values()) <= 1e-10, errors


def _start(cfg: dict[str, Any], rate: bool) -> dict[str, Any]:
    v = cfg["vessels"][0]
    name, bc = v["vessel_name"], v["boundary_conditions"]
    ic = {f"pressure:{bc['inlet']}:{name}": 1200.0, f"flow:{bc['inlet']}:{name}": 3.0,
          f"pressure:{name}:{bc['outlet']}": 900.0, f"flow:{name}:{bc['outlet']}": 2.0,
          "flow:no_such:node": 7.0}  # a name of no variable: ignored, as svZeroDSolver does
    cfg["initial_condition"] = ic
    if rate:
        cfg["initial_condition_d"] = {k: 10.0 * (i + 1) for i, k in enumerate(ic)}
    return cfg


@pytest.mark.parametrize("name", ["steadyFlow_RLC_R", "pulsatileFlow_R_RCR", "pulsatileFlow_CRL",
                                  "steadyFlow_R_steadyPressure"])
@pytest.mark.parametrize("rate", [False, True])
def test_initial_condition_matches_svzerod(name: str, rate: bool) -> None:
    cfg = _start(config(name), rate)
    cfg["simulation_parameters"].update(steady_initial=False, number_of_cardiac_cycles=1)
    actual = svz.simulate(cfg)
    # the start is the file's (the t = 0 row shows it) ...
    first = actual.groupby("name", sort=False).head(1)
    assert first["pressure_in"].iloc[0] == 1200.0
    # ... and the run is svZeroDSolver's: round-off
    assert scaled_error(actual, peer(cfg)) < 1e-9


def test_pressure_all_and_flow_all_match_svzerod() -> None:
    cfg = config("steadyFlow_bifurcationR_R1")
    cfg["simulation_parameters"].update(steady_initial=False, number_of_cardiac_cycles=1)
    cfg["initial_condition"] = {"pressure_all": 1000.0, "flow_all": 1.0,
                                "flow:J0:branch1_seg0": 3.0}
    assert scaled_error(svz.simulate(cfg), peer(cfg)) < 1e-9


def test_initial_condition_native_values_are_si() -> None:
    # the native vessel gets `initial` in the file's units (cgs here) and the model converts
    cfg = _start(config("steadyFlow_RLC_R"), True)
    native = svz.to_oxyline_dict(cfg)
    v = next(x for x in native["vessels"] if x["name"] == "branch0_seg0")
    assert v["initial"] == {"pressure_in": 1200.0, "flow_in": 3.0, "pressure_out": 900.0,
                            "flow_out": 2.0}
    assert v["initial_rate"]["flow_in"] == 20.0
    canonical = svz.to_model(cfg).canonical["vessels"]
    p = next(x for x in canonical if x["name"] == "branch0_seg0")["initial"]
    assert p["pressure_in"] == pytest.approx(120.0, rel=1e-15)  # dyn/cm^2 -> Pa
    assert p["flow_in"] == pytest.approx(3e-6, rel=1e-15)  # mL/s -> m^3/s


@pytest.mark.parametrize(("changes", "match"), [
    ({"initial_condition": {"pressure_c:OUT": 1.0}}, "internal variable"),
    ({"initial_condition_d": {"Vc:x": 1.0}}, "chamber volume's rate"),
])
def test_unsupported_initial_conditions_name_the_entry(changes: dict[str, Any], match: str
                                                       ) -> None:
    cfg = dict(config("steadyFlow_R_RCR"), **changes)
    with pytest.raises(oxyline.UnsupportedElement, match=match):
        svz.simulate(cfg)


def test_coronary_with_initial_pressures_is_refused() -> None:
    cfg = config("pulsatileFlow_R_coronary")
    cfg["initial_condition"] = {"pressure_all": 100.0}
    with pytest.raises(oxyline.UnsupportedElement, match="CORONARY boundary condition"):
        svz.simulate(cfg)


# ------------------------------------------------------------------------------------------
# use_cycle_to_cycle_error without RCR


def test_cycle_error_without_rcr_matches_reference() -> None:
    # 20 cycles, then 11 extra ones until the cap means converge, every row output (6201)
    name = "pulsatileFlow_R_coronary_cycle_error"
    actual, expected = svz.simulate(config(name)), reference(name)
    assert len(actual) == len(expected) == 20 * 200 + 1 + 11 * 200
    assert scaled_error(actual, expected) < GEN_ALPHA_TOL


@pytest.mark.parametrize("changes", [
    # a 2-cycle file with last-cycle output also keeps each extra cycle's end (time 0 again)
    {"number_of_cardiac_cycles": 2, "output_all_cycles": False},
    {"number_of_cardiac_cycles": 2, "output_all_cycles": False, "output_interval": 7},
    {"number_of_cardiac_cycles": 3, "output_interval": 4},
    {"number_of_cardiac_cycles": 4, "output_all_cycles": False, "steady_initial": True},
])
def test_cycle_error_rows_match_svzerod(changes: dict[str, Any]) -> None:
    cfg = config("pulsatileFlow_R_coronary")
    cfg["simulation_parameters"].update(use_cycle_to_cycle_error=True,
                                        sim_cycle_to_cycle_percent_error=1e-4, **changes)
    # the same discretisation: round-off only
    assert scaled_error(svz.simulate(cfg), peer(cfg)) < 1e-9


@pytest.mark.parametrize("variable_based", [False, True])
def test_cycle_error_with_derivatives_matches_svzerod(variable_based: bool) -> None:
    # the core's cycle-to-cycle rule and its own ẏ in one run: svZeroDSolver's rows and
    # derivatives (the coronary's volume_im too) to round-off, from the zero start (after the
    # steady start svZeroDSolver's coronary reference volume holds a leftover of its ẏ₀,
    # docs/svzerod.md: 5e-8 of max|ṗ| in the first steps)
    cfg = config("pulsatileFlow_R_coronary")
    cfg["simulation_parameters"].update(
        use_cycle_to_cycle_error=True, sim_cycle_to_cycle_percent_error=1e-4,
        number_of_cardiac_cycles=3, output_derivative=True, steady_initial=False,
        output_variable_based=variable_based)
    assert scaled_error(svz.simulate(cfg), peer(cfg)) < 1e-9


@pytest.mark.parametrize("name", ["closedLoopHeart_singleVessel", "pulsatileFlow_R_RCR"])
def test_derivatives_after_the_steady_start_match_svzerod(name: str) -> None:
    # ẏ after svZeroDSolver's steady iterations starts from what they leave (not 0), and the
    # heart block's variables carry their own: both the core's ẏ (when the drop-in rebuilt ẏ
    # from ẏ₀ = 0: 3.6e-8 of the range for the RCR case, 0.96 for the heart's variables)
    cfg = config(name)
    # (each file's own start: the RCR case's steady one, the heart's zero one)
    cfg["simulation_parameters"].update(output_derivative=True, output_variable_based=True)
    assert scaled_error(svz.simulate(cfg), peer(cfg)) < 1e-9


# ------------------------------------------------------------------------------------------
# the coronary outlets' zero start


@pytest.mark.parametrize("name", ["pulsatileFlow_R_coronary", "pulsatileFlow_R_coronary_varres"])
@pytest.mark.parametrize("varying", [False, True])
def test_coronary_zero_start_matches_svzerod(name: str, varying: bool) -> None:
    # svZeroDSolver measures the intramyocardial volume from the start state: from a zero start
    # its bed sees P_im(t) − P_im(0) (before, 0.21 of the pressure range off after 3 cycles)
    cfg = config(name)
    cfg["simulation_parameters"].update(steady_initial=False, number_of_cardiac_cycles=2)
    if varying:
        bc = cfg["boundary_conditions"][1]["bc_values"]
        bc["t"] = [k / 10 for k in range(11)]
        bc["Pim"] = [500.0 + 300.0 * np.sin(2 * np.pi * t) for t in bc["t"]]
    assert scaled_error(svz.simulate(cfg), peer(cfg)) < 1e-9


# ------------------------------------------------------------------------------------------
# the native `initial` (docs/physics.md §1.9)


@pytest.mark.parametrize("given_flow", [True, False])
@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
def test_native_initial_pressure_discharges_the_capacitor(method: str, given_flow: bool) -> None:
    # no inflow; an RCL vessel (R1, C, L = 0) drains through a resistance R2 to 0 Pa. Started
    # at P_in = P0 with no flow, its capacitor node starts at P0 (P_c = P_in − R1 Q_in) and
    # discharges as P0 exp(−t / (R2 C)) (exact). An absent `flow_in` is 0 (§1.9): the same
    # start (it once left the capacitor at 0 Pa)
    r1, r2, c, p0, tau = 1e7, 1e8, 1e-9, 1.0e4, 0.1
    initial = {"pressure_in": p0, "flow_in": 0.0} if given_flow else {"pressure_in": p0}
    model = oxyline.load_model({
        "period": 1.0,
        "vessels": [{"name": "v", "from": "in", "to": "out", "arrangement": "RCL",
                     "lumped": {"resistance": r1, "capacitance": c},
                     "initial": initial}],
        "boundary_conditions": {"in": {"type": "flow", "flow": 0.0},
                                "out": {"type": "resistance", "resistance": r2}},
        "simulation": {"cycles": 1, "dt": 1e-4, "method": method, "start": "zero",
                       "output": {"every": 0.01}},
    })
    assert r2 * c == pytest.approx(tau)
    res = oxyline.simulate(model)
    t, p = res.time, res.vessel("v").pressure_out
    # both methods are second order or better: 1e-4 s steps leave < 1e-6 of P0
    np.testing.assert_allclose(p, p0 * np.exp(-t / tau), rtol=0, atol=1e-6 * p0)


def test_native_initial_refuses_unknown_keys() -> None:
    with pytest.raises(oxyline.ModelError, match="initial"):
        oxyline.load_model({
            "vessels": [{"name": "v", "from": "in", "to": "out",
                         "lumped": {"resistance": 1e7}, "initial": {"pressure": 1.0}}],
            "boundary_conditions": {"in": {"type": "flow", "flow": 0.0},
                                    "out": {"type": "resistance", "resistance": 1e8}}})


# ------------------------------------------------------------------------------------------
# RESISTANCE and RCR at a vessel inlet (native `svzerod-inlet`)


def _inlet_case(kind: str) -> dict[str, Any]:
    """A vessel between an inlet RESISTANCE/RCR and an outlet RESISTANCE, driven by the
    distal pressures, or by a pulsatile outflow (FLOW at the outlet)."""
    t = [k / 20 for k in range(21)]
    inlet = ({"bc_name": "IN", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 1000.0}}
             if kind == "RESISTANCE" else
             {"bc_name": "IN", "bc_type": "RCR",
              "bc_values": {"Rp": 100.0, "C": 1e-4, "Rd": 1000.0, "Pd": 10000.0}})
    outlet = ({"bc_name": "OUT", "bc_type": "FLOW",
               "bc_values": {"t": t, "Q": [5.0 + 2.0 * np.sin(2 * np.pi * x) for x in t]}}
              if kind == "RESISTANCE" else
              {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 5000.0, "Pd": 0.0}})
    return {
        # svzerod 3.2's own steady start does not converge with an inlet RCR (its Newton stops
        # at the iteration limit): that case starts from zero
        "simulation_parameters": {"number_of_cardiac_cycles": 3,
                                  "number_of_time_pts_per_cardiac_cycle": 101,
                                  "steady_initial": kind == "RESISTANCE"},
        "boundary_conditions": [inlet, outlet],
        "vessels": [{"vessel_id": 0, "vessel_name": "v", "zero_d_element_type": "BloodVessel",
                     "zero_d_element_values": {"R_poiseuille": 500.0, "C": 1e-4, "L": 1.0},
                     "boundary_conditions": {"inlet": "IN", "outlet": "OUT"}}],
    }


@pytest.mark.parametrize("kind", ["RESISTANCE", "RCR"])
def test_inlet_resistance_and_rcr_match_svzerod(kind: str) -> None:
    cfg = _inlet_case(kind)
    actual = svz.simulate(cfg)
    # svZeroDSolver's P_in = Pd + R Q (not Pd − R Q): its own equations, round-off
    assert scaled_error(actual, peer(cfg)) < 1e-9
    if kind == "RESISTANCE":
        q, p = actual["flow_in"].to_numpy(), actual["pressure_in"].to_numpy()
        np.testing.assert_allclose(p, 1000.0 + 100.0 * q, rtol=1e-12)
    # the variable table's pressure_c of the inlet Windkessel: P_in − Rp Q
    cfg["simulation_parameters"]["output_variable_based"] = True
    assert scaled_error(svz.simulate(cfg), peer(cfg)) < 1e-9


def test_inlet_resistance_rk4_matches_svzerod_20x_finer() -> None:
    cfg = _inlet_case("RESISTANCE")
    actual = svz.simulate(cfg, method="rk4")
    fine = copy.deepcopy(cfg)
    sp = fine["simulation_parameters"]
    sp["number_of_time_pts_per_cardiac_cycle"] = 100 * 20 + 1
    sp["output_interval"] = 20
    expected = peer(fine)
    errors = [np.max(np.abs(actual[c].to_numpy() - expected[c].to_numpy())) / np.ptp(expected[c])
              for c in ("flow_in", "pressure_in", "pressure_out")]
    # the peer's own generalized-alpha error at 20x finer steps bounds the agreement
    assert max(errors) < 1e-4, errors


def test_inlet_rcr_rk4_matches_svzerod_extrapolated() -> None:
    """RK4 with an inlet RCR: its capacitor row is −C dP_c/dt (svZeroDSolver's equations, see
    `svzerod_inlet.rs`), a differential row with a negative mass entry. The case starts from
    zero, where svzerod's generalized-α start transient is only first order (its error at 20x
    is 1.7e-3 of the flow range, halving with its step: docs/svzerod.md): the truth is the
    Richardson extrapolation 2·(80x) − (40x) of two fresh svzerod runs."""
    cfg = _inlet_case("RCR")
    actual = svz.simulate(cfg, method="rk4")
    runs = []
    for f in (40, 80):
        fine = copy.deepcopy(cfg)
        sp = fine["simulation_parameters"]
        sp["number_of_time_pts_per_cardiac_cycle"] = 100 * f + 1
        sp["output_interval"] = f
        runs.append(peer(fine))
    errors = {}
    for c in ("flow_in", "flow_out", "pressure_in", "pressure_out"):
        truth = 2.0 * runs[1][c].to_numpy() - runs[0][c].to_numpy()
        # the t = 0 row is the zero start itself (the peer's first step is not extrapolable)
        errors[c] = float(np.max(np.abs(actual[c].to_numpy()[1:] - truth[1:]))
                          / np.ptp(runs[1][c].to_numpy()))
    # measured 1.7e-5 (the extrapolation's own second-order remainder: 6.7e-5 from 20x/40x)
    assert max(errors.values()) < 1e-4, errors


def test_native_svzerod_inlet_must_sit_at_an_inlet() -> None:
    with pytest.raises(oxyline.ModelError, match="inlet end"):
        oxyline.simulate(oxyline.load_model({
            "vessels": [{"name": "v", "from": "in", "to": "out", "lumped": {"resistance": 1e7}}],
            "boundary_conditions": {"in": {"type": "flow", "flow": 1e-6},
                                    "out": {"type": "svzerod-inlet", "resistance": 1e8}}}))


# ------------------------------------------------------------------------------------------
# chamber volumes (svZeroDSolver's Vc)


@pytest.mark.parametrize("name", ["piecewise_Chamber_and_Valve", "closed_loop_two_hill"])
def test_chamber_volumes_are_output(name: str) -> None:
    actual, expected = svz.simulate(config(name)), reference(name)
    errors = compare(actual, expected, ROUNDING)
    volumes = {k: v for k, v in errors.items() if k.startswith("Vc:")}
    assert len(volumes) == 4
    # the variable table is svZeroDSolver's whole table now, in its order
    assert list(actual["name"].unique()) == list(expected["name"].unique())
    assert max(volumes.values()) <= GEN_ALPHA_TOL, volumes


def test_a_time_table_off_zero_is_looked_up_as_svzerod_does() -> None:
    """svZeroDSolver evaluates a table at fmod(t, P), P = t[-1] - t[0], linearly, with the first
    segment extended below t[0]: a table on [0.25, 1.25] rising with slope 2 to a kink at 0.75
    becomes, over [0, 1], the samples 0, 0.25, 0.75 and 1 at that rule's values (by hand:
    3.5 - 2 * 0.25 at 0, 4.5 - 2 * 0.25 at 1); a table that does not increase or starts
    before 0 is refused naming its entry."""
    from oxyline.io.svzerod.reader import to_oxyline_dict

    cfg = config("pulsatileFlow_R_RCR")
    vals = cfg["boundary_conditions"][0]["bc_values"]
    vals["t"], vals["Q"] = [0.25, 0.75, 1.25], [3.5, 4.5, 3.5]
    cfg["simulation_parameters"].pop("cardiac_period", None)
    bcs = to_oxyline_dict(cfg)["boundary_conditions"]
    flow = next(bc for bc in bcs.values() if bc["type"] == "flow")
    assert flow["time"] == [0.0, 0.25, 0.75, 1.0]
    assert flow["flow"] == pytest.approx([3.0, 3.5, 4.5, 4.0], rel=1e-15)  # one rounding
    vals["t"] = [0.25, 0.75, 0.75]
    with pytest.raises(oxyline.ModelError,
                       match=r"'INFLOW': 't' must be strictly increasing: t\[2\] = 0.75 <= "
                             r"t\[1\] = 0.75"):
        to_oxyline_dict(cfg)
    vals["t"] = [-0.25, 0.25, 0.75]
    with pytest.raises(oxyline.UnsupportedElement, match=r"starting before 0 \(t\[0\] = -0.25\)"):
        to_oxyline_dict(cfg)
