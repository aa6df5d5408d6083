"""svZeroDSolver's chamber and valve cases through the drop-in: the
stored references (generalized-α, svZeroDSolver's own step) and svzerod run 20x finer (RK4),
plus the element laws against closed forms."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pandas as pd
import pytest
from conftest import svzerod_run

import oxyline
from oxyline import svzerod as svz
from tests.conftest import data_path

#: cases the drop-in runs; every svZeroDSolver variable is output, the tanh valves'
#: valve_status and the chamber volume Vc among them
CHAMBER_CASES = ["valve_tanh", "chamber_elastance_inductor"]


def case(name: str) -> Any:
    return data_path("svzerod", "cases", f"{name}.json")


def reference(name: str) -> pd.DataFrame:
    return pd.read_json(data_path("svzerod", "cases", "results", f"result_{name}.json"))


def compare(actual: pd.DataFrame, expected: pd.DataFrame) -> dict[str, float]:
    """max|a - e| / range(e) per variable present in both (variable-based frames), times
    matched to 1e-9 s."""
    out = {}
    for name, e in expected.groupby("name", sort=False):
        a = actual[actual["name"] == name]
        if a.empty:
            continue
        np.testing.assert_allclose(a["time"].to_numpy(), e["time"].to_numpy(), atol=1e-9)
        ev, av = e["y"].to_numpy(float), a["y"].to_numpy(float)
        scale = max(np.ptp(ev), 1e-12 * max(np.max(np.abs(ev)), 1.0), 1e-12)
        out[name] = float(np.max(np.abs(av - ev)) / scale)
    return out


@pytest.mark.parametrize("name", CHAMBER_CASES)
def test_generalized_alpha_matches_reference(name: str) -> None:
    actual = svz.simulate(str(case(name)))
    errors = compare(actual, reference(name))
    # every variable, valve_status among them (svZeroDSolver's ValveTanh internal variable)
    assert set(errors) == set(reference(name)["name"])
    assert any(n.startswith("valve_status:") for n in errors)
    # 1e-6 of each variable's range: svZeroDSolver's Newton tolerance (1e-9 absolute) and the
    # reference's 10 stored decimals, far below any modelling difference
    assert max(errors.values()) <= 1e-6, errors


def test_closed_loop_heart_decomposed_matches_reference() -> None:
    """closedLoopHeart_singleVessel_decomposed: svZeroDSolver's closed-loop heart written as
    four chambers (exponential atria with the wrapping-cosine activation, ventricles with the
    Fourier one), four tanh valves, a flow-through RC pulmonary bed (BloodVesselRC) and
    systemic vessels, no boundary condition, started from the chambers' initial volumes."""
    name = "closedLoopHeart_singleVessel_decomposed"
    actual = svz.simulate(str(case(name)))
    expected = reference(name)
    assert list(actual["name"]) == list(expected["name"])
    errors = {}
    for c in ("flow_in", "flow_out", "pressure_in", "pressure_out"):
        a, e = actual[c].to_numpy(float), expected[c].to_numpy(float)
        errors[c] = float(np.max(np.abs(a - e)) / np.max(np.abs(e)))
    # scaled as tests/test_svzerod.py: svZeroDSolver's Newton tolerance 1e-8 and 10 decimals
    assert max(errors.values()) <= 1e-6, errors


def test_rk4_matches_svzerod_20x_finer() -> None:
    """valve_tanh (chamber_elastance_inductor: see test_rk4_stiff_chamber_inductor_...)."""
    name = "valve_tanh"
    pytest.importorskip("svzerod")
    cfg = json.loads(case(name).read_text())
    errors = compare(svz.simulate(cfg, method="rk4"), svzerod_run(cfg, 20))
    # svZeroDSolver's valve_status is an algebraic variable solved at its generalized-α
    # stage: after a switch it oscillates around f(Δp), shrinking by ρ∞ each step (1.2e-2 of
    # its range at 20x finer), an artefact of that integrator; RK4's is f(Δp) itself, and the
    # pressures it follows are compared
    errors.pop("valve_status:valve")
    assert len(errors) >= 4
    # discretisation error: 1.8e-4 of the inflow's range (1.6e-4 against svzerod 80x finer),
    # at the valve's switch (tanh of steepness 100 over pressures of order 1, a width of 0.01):
    # the drop-in's RK4 sub-step follows the stability bound and the table spacing, not the
    # switch, which the other peer cases (1e-4) do not have
    assert max(errors.values()) <= 5e-4, errors


#: RK4 against svzerod 20x finer (max|a - e| / range(e) per variable, `Vc` included),
#: measured: piecewise valves driven by pressure differences, no chamber outlet inductor
RK4_CHAMBER_CASES = {
    "closed_loop_two_hill": 1.5e-4,  # zero start: the peer's first-order start transient
    "piecewise_Chamber_and_Valve": 3.2e-5,
}


@pytest.mark.parametrize("name", [
    "closed_loop_two_hill",
    pytest.param("piecewise_Chamber_and_Valve", marks=pytest.mark.slow),  # 30 cycles, ~15 s
])
def test_rk4_chamber_cases_match_svzerod_20x_finer(name: str) -> None:
    pytest.importorskip("svzerod")
    cfg = json.loads(case(name).read_text())
    errors = compare(svz.simulate(cfg, method="rk4"), svzerod_run(cfg, 20))
    assert len(errors) >= 4
    # 3x the measured value: the piecewise valves switch within one RK4 sub-step
    assert max(errors.values()) <= 3 * RK4_CHAMBER_CASES[name], errors


def test_rk4_stiff_chamber_inductor_matches_svzerod_20x_finer() -> None:
    """chamber_elastance_inductor: the chamber's outlet inductor (L = 3.5e-4) drives the flow
    through valve1; closed (R_max = 1e5) that branch relaxes at R_max/L = 2.8e8 1/s (~3e9
    explicit steps for its 30 cycles). RK4 makes the branch algebraic while R(ΔP) Δt > L
    (docs/physics.md §1.8, "stiff branches"): the stability bound is then set by the vessel
    (4.2e-2 s, was ~1e-8 s), and the core's step doubling over the 30 cycles (docs/physics.md
    §1.8, "RK4's step for valves and chambers") picks 16 sub-steps per output step to resolve
    the valves' switch (tanh of width 0.01 over pressure swings of 10 in ~0.1 s)."""
    pytest.importorskip("svzerod")
    name = "chamber_elastance_inductor"
    cfg = json.loads(case(name).read_text())
    errors = compare(svz.simulate(cfg, method="rk4"), svzerod_run(cfg, 20))
    # the valves' valve_status: svZeroDSolver's generalized-α-stage artefact, left out as in
    # test_rk4_matches_svzerod_20x_finer (the pressures it follows are compared)
    for n in [n for n in errors if n.startswith("valve_status:")]:
        errors.pop(n)
    assert len(errors) >= 8
    # measured 2.5e-3 (16 sub-steps; 20 give the same): svzerod 20x finer is itself 2.5e-3
    # off svzerod 100x finer, while an RK4 run of 20 sub-steps is 2.7e-4 off it; the stability
    # bound's sub-step (one per output step, 1e-2 s) gives 1.2e-1 (Vc, the chamber volume
    # after 30 cycles), svZeroDSolver's own step 2.9e-1. 2x the measured value: the peer's own
    # discretisation error dominates the comparison
    assert max(errors.values()) <= 5e-3, errors


DECOMPOSED = "closedLoopHeart_singleVessel_decomposed"


def decomposed_variables() -> dict[str, Any]:
    """The decomposed closed-loop heart with every variable in the output."""
    cfg = json.loads(case(DECOMPOSED).read_text())
    cfg["simulation_parameters"]["output_variable_based"] = True
    return cfg


def loop_volume(frame: pd.DataFrame) -> np.ndarray:
    """The blood volume of the decomposed heart's closed loop: the four chambers' Vc plus the
    two BloodVessel capacitors' C·P_c (P_c = P_in − R·Q_in, svZeroDSolver's BloodVessel). The
    BloodVesselRC passes its flow through unchanged (docs/physics.md §1.8, `through_rc`), so it
    holds no loop volume."""
    def y(name: str) -> np.ndarray:
        return frame[frame["name"] == name]["y"].to_numpy(float)

    chambers = sum(y(f"Vc:{c}") for c in ("RA", "RV", "LA", "LV"))
    aortic_cap = 0.556854 * y("pressure:AV:aortic_cap")  # R = 0
    sys_rp = 0.238401833 * (y("pressure:J_sys1:sys_Rp") - 0.134156617 * y("flow:J_sys1:sys_Rp"))
    return np.asarray(chambers + aortic_cap + sys_rp)


@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
def test_closed_loop_heart_decomposed_conserves_volume(method: str) -> None:
    """No boundary condition: every flow balance of the loop is linear and exact in both
    integrators' discrete equations, whatever the stiff branches' mode (RK4's algebraic
    valve branches, docs/physics.md §1.8), so the loop's blood volume is an exact invariant."""
    out = svz.simulate(decomposed_variables(), method=method)
    v = loop_volume(out)
    assert len(v) == 1000 and v[0] == pytest.approx(269.0)  # 2 × (38.43 + 96.07)
    # round-off of ~1e3 steps, each a sum of O(10) terms of size ~v (measured ≤ 2e-15 v)
    assert np.max(np.abs(v - v[0])) <= 1e3 * 1e3 * np.finfo(float).eps * v[0]


def test_rk4_closed_loop_heart_decomposed_matches_svzerod_20x_finer() -> None:
    """RK4 starts the decomposed heart as svZeroDSolver does: the ventricles' outlet inductors
    at rest, accelerating the flow through the opening aortic and pulmonary valves (the branch
    stays differential although its valve reads half-open at zero flow, docs/physics.md §1.8).
    The error is the valves' switch timing, first order in the sub-step (docs/physics.md §1.8,
    "RK4's step for valves and chambers"): 5.4e-2 (mitral flow at its opening) at the stability
    bound's sub-step, 2.6e-2 / 1.1e-2 / 5.0e-3 with 4 / 8 / 16 sub-steps. The drop-in's default
    takes the sub-step from the core's step doubling over the first cycle (16 here, estimated
    error 7.4e-3): no `rk4_substeps` needed."""
    pytest.importorskip("svzerod")
    cfg = decomposed_variables()
    rk4, fine = svz.simulate(cfg, method="rk4"), svzerod_run(cfg, 20)
    # the t = 0 row left out: svzerod writes its given start (pressures 0), RK4 the start's
    # consistent pressures (the chambers' E(0)(V − V_rest))
    errors = compare(rk4[rk4["time"] > 0], fine[fine["time"] > 0])
    # left out: svZeroDSolver's valve_status (its generalized-α-stage artefact, as in
    # test_rk4_matches_svzerod_20x_finer) and the pressure between the right atrium's outlet
    # inductor and the tricuspid valve while it is closed: a leak layer of width L/R_max that
    # svzerod 20x finer does not resolve either (svzerod at 10x finer is 9e-2 of that
    # pressure's range off it, at its own step 0.33; RK4 1.4e-1 at every sub-step)
    for n in [n for n in errors if n.startswith("valve_status:") or n == "pressure:RA:TV"]:
        errors.pop(n)
    assert len(errors) >= 35
    # measured 5.0e-3 (pressure:LA:MV; 32 sub-steps give the same 5.2e-3: svzerod 20x finer's
    # own error, e.g. its start, 2.3e-3 off svzerod 10x at t = 1 ms); the criterion is
    # "within discretisation error", the expert's 1e-2: 2x the measured value
    assert max(errors.values()) <= 1e-2, errors


def test_rk4_step_refinement_estimates_the_error() -> None:
    """The core's step doubling (docs/physics.md §1.8) on the decomposed heart: its estimate
    for the sub-step it picks bounds the error against the independent svzerod 20x finer
    (5.0e-3, the previous test) and meets the drop-in's tolerance; a circuit without valves or
    chambers gets factor 1 without a trial run."""
    from oxyline.io.svzerod import dropin

    cfg = decomposed_variables()
    model, s = svz.to_model(cfg), svz.run_settings(cfg)
    assert not s.steady_initial and s.cycles == 1
    # the drop-in's run: svZeroDSolver's zero start, one sub-step per output step (the
    # stability bound's)
    factor, estimate, converged = model.network.rk4_step_refinement(
        period=s.period, output_every=s.dt, tol=dropin.RK4_SWITCH_TOL, max_factor=64,
        dt=s.dt, method="rk4", start="svzerod-zero", cycles=1, segments=False)
    assert converged and factor in (8, 16, 32)  # a power of two; 1 and 2 are 5.4e-2 off
    # measured 7.4e-3 (16): the difference of the 8 and 16 sub-step runs, first order
    assert 5.0e-3 <= estimate <= dropin.RK4_SWITCH_TOL
    plain = svz.to_model(str(case("pulsatileFlow_R_RCR")))
    assert plain.network.rk4_step_refinement(
        period=1.0, output_every=0.01, tol=1e-2, max_factor=64, method="rk4") == (1, 0.0, True)


# ------------------------------------------------------------------------------------------
# a native closed loop: left ventricle, valves, arteries, veins (no boundary condition)

PERIOD = 0.8
CLOSED_LOOP = {
    "name": "minimal-closed-loop",
    "units": "SI",
    "period": PERIOD,
    "vessels": [
        {"name": "lv", "from": "mitral_out", "to": "lv_out",
         "chamber": {"law": "linear", "max_elastance": 3.3e8, "passive_elastance": 1.2e7,
                     "rest_volume": 1.0e-5, "period": PERIOD, "initial_volume": 1.0e-3,
                     "activation": {"kind": "piecewise-cosine", "contract_start": 0.1,
                                    "relax_start": 0.35, "contract_duration": 0.25,
                                    "relax_duration": 0.2}}},
        {"name": "aortic_valve", "from": "lv_out", "to": "aorta_in",
         "valve": {"law": "tanh", "min_resistance": 1.0e6, "max_resistance": 1.0e11,
                   "steepness": 0.05}},
        {"name": "aorta", "from": "aorta_in", "to": "arteries_out", "arrangement": "RCL",
         "lumped": {"resistance": 1.0e6, "capacitance": 1.5e-8, "inductance": 1.0e5}},
        {"name": "systemic", "from": "arteries_out", "to": "veins_in", "arrangement": "RCL",
         "lumped": {"resistance": 1.3e8}},
        {"name": "veins", "from": "veins_in", "to": "mitral_in", "arrangement": "RCL",
         "lumped": {"resistance": 1.0e6, "capacitance": 7.5e-7}},
        {"name": "mitral_valve", "from": "mitral_in", "to": "mitral_out",
         "valve": {"law": "tanh", "min_resistance": 1.0e6, "max_resistance": 1.0e11,
                   "steepness": 0.05}},
    ],
    "boundary_conditions": {},
    "simulation": {"cycles": 12, "output": {"every": 1e-3, "cycles": "all"}},
}


def test_schema_page_closed_loop_is_this_model() -> None:
    """The minimal closed loop of the schema page (docs/schema.md) is the model these tests
    run."""
    import re

    from ruamel.yaml import YAML

    from tests.conftest import REPO

    text = (REPO / "docs" / "schema.md").read_text()
    block = re.search(r"```yaml\n(name: minimal-closed-loop.*?)```", text, flags=re.DOTALL)
    assert block is not None
    readme = YAML(typ="safe", pure=True).load(block.group(1))  # YAML 1.2: 3.3e8 a number
    assert readme["vessels"] == CLOSED_LOOP["vessels"]
    assert readme["boundary_conditions"] == {}


@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
def test_native_closed_loop_pumps_forward(method: str) -> None:
    """No boundary condition: the heart drives the loop from the ventricle's initial volume.
    Every flow balance is exact in the discrete equations of both integrators (a linear
    invariant), so the blood volume stays the initial 1 L (core test);
    the valves keep the flow forward (backflow below 2 % of the stroke's peak)."""
    model = oxyline.load_model(CLOSED_LOOP)
    res = oxyline.simulate(model, method=method, dt=1e-3 if method == "generalized-alpha" else None)
    df = res.to_pandas()
    assert len(df) > 0
    aorta = df[df["name"] == "aorta"]
    veins = df[df["name"] == "veins"]
    # RCL: the capacitor pressure is P_in - R Q_in (C at the interior point)
    v_art = 1.5e-8 * (aorta["pressure_in"].to_numpy() - 1.0e6 * aorta["flow_in"].to_numpy())
    v_ven = 7.5e-7 * (veins["pressure_in"].to_numpy() - 1.0e6 * veins["flow_in"].to_numpy())
    lv = df[df["name"] == "lv"]
    # the chamber volume from its law at the recorded pressure is not exact at the output
    # times for generalized-α (the law holds at the α_f level); use the flow balance instead:
    # total volume = V_lv(0) + ∫(Q_in - Q_out) dt + ... is what conservation means, so check
    # the rate: d/dt(V_art + V_ven) = Q_out,lv - Q_in,lv up to the step's time error
    t = aorta["time"].to_numpy()
    dv = np.gradient(v_art + v_ven, t)
    net = lv["flow_out"].to_numpy() - lv["flow_in"].to_numpy()
    peak = np.max(np.abs(lv["flow_out"].to_numpy()))
    last = t >= t[-1] - PERIOD
    # finite differences of 1 ms output: O(h²) of a smooth volume, 1e-2 of the peak flow
    assert np.max(np.abs(dv - net)[last]) < 2e-2 * peak
    av = df[df["name"] == "aortic_valve"]["flow_in"].to_numpy()[last]
    assert av.max() > 1e-5  # m³/s: the heart ejects
    assert av.min() > -0.02 * av.max()


@pytest.mark.parametrize(("chamber", "key", "optional"), [
    ("RA", "Impedance", False),  # ChamberElastanceInductorExponential: required
    ("RA", "Kxv", False),
    ("RV", "Impedance", True),   # ChamberElastanceInductor: 0 when absent
    ("RV", "Vrs", False),
])
def test_missing_chamber_parameter_is_named(chamber: str, key: str, optional: bool) -> None:
    """A chamber without one of its parameters is refused naming the chamber and the key,
    unless svZeroDSolver gives it a default (the ChamberElastanceInductor's Impedance)."""
    cfg = json.loads(case("closedLoopHeart_singleVessel_decomposed").read_text())
    entry = next(c for c in cfg["chambers"] if c["name"] == chamber)
    del entry["values"][key]
    if optional:
        law = next(v["chamber"] for v in svz.to_oxyline_dict(cfg)["vessels"]
                   if v["name"] == chamber)
        assert law["inductance"] == 0.0
        return
    with pytest.raises(oxyline.ModelError, match=rf"{entry['type']} '{chamber}': missing '{key}'"):
        svz.to_oxyline_dict(cfg)
