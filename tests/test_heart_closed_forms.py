"""Time-varying chambers against closed forms (not svZeroDSolver's output): a chamber's time-varying
elastance E(t) and a tanh valve in both integrators, RK4's stability bound with E(t), and the
typed errors of the native heart elements and the coronary condition (docs/physics.md §1.7,
§1.8)."""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy.optimize import brentq

import oxyline

T = 0.8  # s
E_MAX, E_PASS, V_REST, V0 = 3.3e8, 1.2e7, 1.0e-5, 1.0e-4  # Pa/m³, Pa/m³, m³, m³
#: piecewise-cosine activation: contraction 0.1–0.35 s, relaxation 0.35–0.55 s
T_C0, T_C, T_R0, T_R = 0.1, 0.25, 0.35, 0.2


def chamber_model(resistance: float) -> dict[str, Any]:
    """A `linear` chamber emptying through a resistor into 0 Pa, no inflow."""
    return {
        "name": "emptying-chamber", "units": "SI", "period": T,
        "vessels": [
            {"name": "lv", "from": "in", "to": "lv_out", "chamber": {
                "law": "linear", "max_elastance": E_MAX, "passive_elastance": E_PASS,
                "rest_volume": V_REST, "period": T, "initial_volume": V0,
                "activation": {"kind": "piecewise-cosine", "contract_start": T_C0,
                               "relax_start": T_R0, "contract_duration": T_C,
                               "relax_duration": T_R}}},
            {"name": "r", "from": "lv_out", "to": "out", "arrangement": "RCL",
             "lumped": {"resistance": resistance}}],
        "boundary_conditions": {"in": {"type": "flow", "value": 0.0},
                                "out": {"type": "pressure", "value": 0.0}}}


def activation_integral(t: np.ndarray) -> np.ndarray:
    """∫₀ᵗ φ(s) ds of the piecewise-cosine activation (docs/physics.md §1.8), by hand."""
    cycles = np.floor(t / T + 1e-12)  # whole cycles (t on a cycle's end counts it)
    tau = t - cycles * T
    c = np.clip(tau - T_C0, 0.0, T_C)
    r = np.clip(tau - T_R0, 0.0, T_R)
    per_cycle = T_C / 2 + T_R / 2
    return (cycles * per_cycle
            + c / 2 - T_C / (2 * np.pi) * np.sin(np.pi * c / T_C)
            + r / 2 + T_R / (2 * np.pi) * np.sin(np.pi * r / T_R))


@pytest.mark.parametrize(("method", "dt", "tol"), [
    # RK4 is fourth order (the activation's kinks sit on the step grid): round-off level
    ("rk4", 1e-3, 1e-9),
    # generalized-α is second order: 2.9e-7 at 1 ms, 1.8e-8 at 0.25 ms (ratio 16)
    ("generalized-alpha", 1e-3, 1e-6),
    ("generalized-alpha", 2.5e-4, 6e-8),
])
def test_chamber_with_time_varying_elastance_empties_as_the_closed_form(
        method: str, dt: float, tol: float) -> None:
    """dV/dt = −E(t)(V − V_rest)/R: V − V_rest = (V₀ − V_rest) exp(−(E_pass t + E_max Φ(t))/R)
    with Φ the activation's integral: E(t) enters both integrators."""
    R = 1e8  # Pa s/m³: decay time R/E from 8 s (passive) to 0.3 s (peak systole)
    res = oxyline.simulate(oxyline.load_model(chamber_model(R)), cycles=2, dt=dt,
                           method=method, output_cycles="all", output_every=1e-3)
    t, v = res.time, res.chamber_volume["lv"]
    exact = V_REST + (V0 - V_REST) * np.exp(-(E_PASS * t + E_MAX * activation_integral(t)) / R)
    assert exact[-1] - V_REST < 0.5 * (V0 - V_REST)  # the test sees a real decay
    np.testing.assert_allclose(v, exact, rtol=0, atol=tol * (V0 - V_REST))


def test_rk4_stability_bound_uses_the_peak_instantaneous_elastance() -> None:
    """The chamber + resistor operator is −E(t)/R: RK4's real-axis limit 2.7853/|λ| at the
    largest E(t) = E_pass + E_max (reached at the activation's phase end, one of the sampled
    times), times the documented margin 0.9 (docs/physics.md §1.8)."""
    R = 1e7
    rk4_real_axis = 2.785293563405282  # |z| where |1 + z + z²/2 + z³/6 + z⁴/24| = 1 on z < 0
    dt_max, limited_by, _ = oxyline.load_model(chamber_model(R)).network.rk4_stability_limit()
    assert dt_max == pytest.approx(0.9 * rk4_real_axis * R / (E_PASS + E_MAX), rel=1e-9)
    assert "lv" in limited_by


def test_tanh_valve_follows_its_algebraic_law_in_both_integrators() -> None:
    """A tanh valve in series with a resistor R₀ under P_in(t) = A sin(2πt/T): the flow is the
    root of P_in = (R(ΔP) + R₀) Q with ΔP = R₀ Q − P_in (docs/physics.md §1.8), found here by
    bracketing (brentq), independent of the core's Newton."""
    A, R0, rmin, rmax, k = 2000.0, 1e8, 1e6, 1e10, 0.01
    model = {
        "name": "valve", "units": "SI", "period": T,
        "vessels": [
            {"name": "valve", "from": "in", "to": "mid", "valve": {
                "law": "tanh", "min_resistance": rmin, "max_resistance": rmax, "steepness": k}},
            {"name": "r", "from": "mid", "to": "out", "arrangement": "RCL",
             "lumped": {"resistance": R0}}],
        "boundary_conditions": {
            "in": {"type": "pressure",
                   "fourier": {"period": T, "mean": 0.0, "cos": [0.0], "sin": [A]}},
            "out": {"type": "pressure", "value": 0.0}}}

    def resistance(dp: float) -> float:
        return 0.5 * (rmax + rmin) + 0.5 * (rmax - rmin) * np.tanh(k * dp)

    def exact(p: float) -> float:
        b = abs(p) / R0 + 1e-30
        return brentq(lambda q: (resistance(R0 * q - p) + R0) * q - p, -b, b, xtol=1e-30)

    # RK4 solves the algebraic valve row by Newton at every stage time (tolerance-level
    # agreement); generalized-α imposes it at t_{n+α_f}: second order (5.9e-5 at 1 ms, 3.7e-6
    # at 0.25 ms, ratio 16)
    for method, dt, tol in (("rk4", 1e-3, 1e-6), ("generalized-alpha", 1e-3, 1e-4),
                            ("generalized-alpha", 2.5e-4, 7e-6)):
        res = oxyline.simulate(oxyline.load_model(model), cycles=2, dt=dt, method=method,
                               output_every=1e-3)
        q = res.vessel("valve").flow_in
        want = np.array([exact(p) for p in A * np.sin(2 * np.pi * res.time / T)])
        assert want.max() > 50 * -want.min() > 0  # open forward, nearly shut backward
        np.testing.assert_allclose(q, want, rtol=0, atol=tol * np.ptp(want), err_msg=method)


# --- bad input: a typed error naming the element and the value ----------------------------

VALVE = {"law": "tanh", "min_resistance": 1.0e6, "max_resistance": 1.0e11, "steepness": 0.05}


def loop() -> dict[str, Any]:
    """The schema page's minimal closed loop (one chamber, two tanh valves)."""
    m = chamber_model(1.3e8)
    lv = m["vessels"][0]
    lv["from"] = "mitral_out"
    return {"name": "loop", "units": "SI", "period": T, "boundary_conditions": {}, "vessels": [
        lv,
        {"name": "aortic_valve", "from": "lv_out", "to": "aorta", "valve": dict(VALVE)},
        {"name": "systemic", "from": "aorta", "to": "veins", "arrangement": "RCL",
         "lumped": {"resistance": 1.3e8, "capacitance": 1.5e-8}},
        {"name": "mitral_valve", "from": "veins", "to": "mitral_out", "valve": dict(VALVE)}]}


def chamber(m: dict[str, Any]) -> dict[str, Any]:
    return m["vessels"][0]["chamber"]


def valve(m: dict[str, Any]) -> dict[str, Any]:
    return m["vessels"][1]["valve"]


@pytest.mark.parametrize(("change", "words"), [
    (lambda m: chamber(m).update(max_elastance=-3.3e8), ["'lv'", "max_elastance", "-3.3e8"]),
    (lambda m: chamber(m).update(passive_elastance=-1.0), ["'lv'", "passive_elastance", "-1"]),
    (lambda m: chamber(m).update(max_elastance=float("nan")), ["'lv'", "max_elastance", "nan"]),
    (lambda m: chamber(m).update(initial_volume=-1e-3), ["'lv'", "initial_volume", "-0.001"]),
    (lambda m: chamber(m).update(period=0.9), ["'lv'", "period", "0.9", "0.8"]),
    (lambda m: chamber(m).pop("max_elastance"), ["'lv'", "max_elastance"]),
    (lambda m: chamber(m)["activation"].update(contract_duration=-0.1),
     ["'lv'", "contract_duration", "-0.1"]),
    (lambda m: valve(m).update(min_resistance=-1.0), ["'aortic_valve'", "min_resistance", "-1"]),
    (lambda m: valve(m).update(max_resistance=1e5), ["'aortic_valve'", "max_resistance", "100000"]),
    (lambda m: valve(m).update(steepness=0.0), ["'aortic_valve'", "steepness", "0"]),
    (lambda m: valve(m).update(steepness=float("inf")), ["'aortic_valve'", "steepness", "inf"]),
    (lambda m: valve(m).pop("steepness"), ["'aortic_valve'", "steepness"]),
    (lambda m: valve(m).update(law="bar"), ["'aortic_valve'", "law", "bar"]),
], ids=["chamber-negative-elastance", "chamber-negative-passive", "chamber-nan-elastance",
        "chamber-negative-volume", "chamber-period-mismatch", "chamber-missing-elastance",
        "chamber-negative-duration", "valve-negative-resistance", "valve-max-below-min",
        "valve-zero-steepness", "valve-infinite-steepness", "valve-missing-steepness",
        "valve-unknown-law"])
def test_bad_heart_element_is_a_model_error_naming_it(
        change: Callable[[dict[str, Any]], Any], words: list[str]) -> None:
    m = loop()
    change(m)
    with pytest.raises(oxyline.ModelError) as err:
        oxyline.simulate(oxyline.load_model(m), cycles=1, dt=1e-3, method="generalized-alpha")
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_the_loop_used_for_bad_input_runs() -> None:
    res = oxyline.simulate(oxyline.load_model(loop()), cycles=2, dt=1e-3,
                           method="generalized-alpha")
    assert np.all(np.isfinite(res.chamber_volume["lv"]))


CORONARY = {"type": "coronary", "arterial_resistance": 1e9, "microvascular_resistance": 2e9,
            "venous_resistance": 1e9, "arterial_capacitance": 1e-10,
            "intramyocardial_capacitance": 2e-10,
            "intramyocardial_pressure": {"time": [0.0, 0.3, 0.6, 1.0],
                                         "pressure": [0.0, 1.5e4, 0.0, 0.0]}}


def coronary(change: Callable[[dict[str, Any]], Any]) -> dict[str, Any]:
    bc = copy.deepcopy(CORONARY)
    change(bc)
    return {"name": "coronary", "units": "SI", "period": 1.0,
            "vessels": [{"name": "lca", "from": "in", "to": "out", "arrangement": "RCL",
                         "lumped": {"resistance": 1e8}}],
            "boundary_conditions": {"in": {"type": "pressure", "value": 1.2e4}, "out": bc}}


@pytest.mark.parametrize(("change", "words"), [
    (lambda bc: bc.pop("intramyocardial_pressure"), ["'out'", "intramyocardial_pressure"]),
    (lambda bc: bc["intramyocardial_pressure"].pop("pressure"),
     ["'out'", "intramyocardial_pressure", "pressure"]),
    (lambda bc: bc["intramyocardial_pressure"].pop("time"),
     ["'out'", "intramyocardial_pressure", "time"]),
    (lambda bc: bc["intramyocardial_pressure"].update(pressure=[0.0, 1.0]),
     ["'out'", "intramyocardial_pressure", "4", "2"]),
    (lambda bc: bc["intramyocardial_pressure"].update(pressure=[0.0, float("nan"), 0.0, 0.0]),
     ["'out'", "pressure[1]", "nan"]),
    (lambda bc: bc["intramyocardial_pressure"].update(time=[0.0, 0.3, 0.6, 0.9]),
     ["'out'", "period", "0.9"]),
    (lambda bc: bc.update(intramyocardial_capacitance=-1e-10),
     ["'out'", "intramyocardial_capacitance", "-1e-10"]),
    (lambda bc: bc.update(microvascular_resistance_max=5e9, contraction_time=0.3,
                          relaxation_time=0.4, cycle_period=0.8),
     ["'out'", "cycle_period", "0.8", "1 s"]),
], ids=["missing-p-im", "p-im-table-without-pressure", "p-im-table-without-time",
        "p-im-table-lengths", "p-im-table-nan", "p-im-period-mismatch", "negative-c-im",
        "varying-resistance-period-mismatch"])
def test_bad_coronary_is_a_model_error_naming_it(
        change: Callable[[dict[str, Any]], Any], words: list[str]) -> None:
    with pytest.raises(oxyline.ModelError) as err:
        oxyline.simulate(oxyline.load_model(coronary(change)), cycles=1, dt=1e-3)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_the_coronary_used_for_bad_input_runs() -> None:
    res = oxyline.simulate(oxyline.load_model(coronary(lambda bc: None)), cycles=2, dt=1e-3)
    assert np.all(np.isfinite(res.vessel("lca").flow_in))
    varying = coronary(lambda bc: bc.update(microvascular_resistance_max=5e9,
                                            contraction_time=0.3, relaxation_time=0.4,
                                            cycle_period=1.0))
    res = oxyline.simulate(oxyline.load_model(varying), cycles=2, dt=1e-3)
    assert np.all(np.isfinite(res.vessel("lca").flow_in))


def test_heart_block_out_of_step_with_the_model_period_is_named() -> None:
    from oxyline import closed_loop

    m = closed_loop.heart_model(closed_loop.load())
    block = next(v for v in m["vessels"] if "heart_pulmonary" in v)
    block["heart_pulmonary"]["period"] = 0.9 * m["period"]
    with pytest.raises(oxyline.ModelError, match=rf"vessel '{block['name']}' heart_pulmonary"
                                                 r".*period mismatch.*0\.72"):
        oxyline.load_model(m)
