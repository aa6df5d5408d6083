"""Error control with the explicit pair (docs/physics.md §10.4): Dormand–Prince 5(4) with its
continuous extension, against the closed-form periodic responses of single RC, RL and RLC
lines under sinusoidal forcing (the cases of tests/test_error_control.py); `method: auto`
choosing it on a non-stiff circuit and generalized-α on a stiff one; fixed-step runs equal
to the build before it; bad settings refused naming the setting."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import oxyline
from tests.test_error_control import achieved, rc, rl, rlc


@pytest.mark.parametrize("case", [rc, rl, rlc], ids=["rc", "rl", "rlc"])
def test_achieved_error_is_within_the_tolerance_and_not_far_below(case: Any) -> None:
    # from the exact periodic state, 3 cycles, output every 1 ms (mostly between steps):
    # achieved <= 2 rtol (the estimate may be off by 2x) and >= rtol/200 (not wastefully
    # over-resolved: the fifth-order solution is propagated, the fourth-order difference
    # judged, so the achieved error sits 1/100-1/3 below the estimate; rl at rtol 1e-6,
    # whose flow atol is its own scale's since the default follows it: 1/103)
    model, exact = case()
    for rtol in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6):
        res = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic",
                               output_every=1e-3, method="dopri5")
        assert res.settings["method"] == "dopri5"
        err = achieved(res, exact, rtol)
        assert rtol / 200 <= err <= 2 * rtol, (rtol, err)
        est = res.error_estimate
        assert 0 < max(est.values()) <= rtol * (1 + 1e-9)
        assert res.settings["steps"] > 0 and res.settings["dt_min"] <= res.settings["dt_max"]


def test_dense_output_between_steps_matches_the_closed_form() -> None:
    # 0.1 ms output: dozens of rows per step; the continuous extension (fourth order, and
    # the algebraic unknowns solved at each row's time) keeps the error within 2 rtol, and
    # the rows at the steps' spacing are what a coarse output gives (the output interval
    # never changes the solution)
    model, exact = rlc()
    for rtol in (1e-3, 1e-5):
        fine = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic",
                                output_every=1e-4, method="dopri5")
        assert fine.settings["steps"] < len(fine.time) / 10  # most rows are between steps
        assert achieved(fine, exact, rtol) <= 2 * rtol
        coarse = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic",
                                  output_every=2e-2, method="dopri5")
        assert coarse.settings["steps"] == fine.settings["steps"]
        assert np.array_equal(fine.vessel("v").flow_in[::200], coarse.vessel("v").flow_in)


def _stiff_line() -> dict[str, Any]:
    """The RC line of `rc` behind a second vessel whose tiny compliance relaxes in 2e-6 s (5e-6
    of the line's 0.16 s: stiff enough that the pair's stability ceiling, ~3e5 steps a cycle,
    is 30 times the bound below; a stiffer branch only makes the forced pair's run slower)."""
    model, _ = rc()
    model["vessels"].append({"name": "w", "from": "out", "to": "end",
                             "lumped": {"resistance": 1e6, "capacitance": 1e-12}})
    model["boundary_conditions"]["end"] = model["boundary_conditions"].pop("out")
    return model


def test_auto_takes_the_pair_on_a_non_stiff_line_and_the_implicit_method_on_a_stiff_one() -> None:
    model, exact = rc()
    res = oxyline.simulate(model, rtol=1e-4, cycles=2, start="periodic", method="auto")
    assert res.settings["method"] == "dopri5"
    assert achieved(res, exact, 1e-4) <= 2e-4
    stiff = oxyline.simulate(_stiff_line(), rtol=1e-4, cycles=2, method="auto")
    assert stiff.settings["method"] == "generalized-alpha"
    # asked for, the pair steps the stiff line at its stability ceiling: far more steps
    forced = oxyline.simulate(_stiff_line(), rtol=1e-4, cycles=1, method="dopri5")
    assert forced.settings["steps"] > 100 * stiff.settings["steps"] / 2


def test_species_ride_in_the_stages_and_match_a_fine_implicit_run() -> None:
    # paper-bifurcated with O2: PO2 and flow at rtol 1e-3 against generalized-alpha at
    # dt = 0.1 ms (its own error ~1e-6 of the flow, second order), within 2 rtol of each
    # variable's range; the dissolved O2 stays finite and the pair reports its species error
    ref = oxyline.simulate("paper-bifurcated", dt=1e-4, method="generalized-alpha", cycles=2,
                           output_every=1e-2)
    res = oxyline.simulate("paper-bifurcated", rtol=1e-3, method="dopri5", cycles=2,
                           output_every=1e-2)
    assert res.settings["method"] == "dopri5"
    assert res.error_estimate["species"] > 0
    for key in ("flow_out", "pressure_in", "po2_out"):
        a, b = getattr(res, key), getattr(ref, key)
        scale = np.max(np.abs(b))
        assert np.max(np.abs(a - b)) <= 2e-3 * scale, key


# Rows 3, 11 and 19 (every 50 ms, cycles 2) of fixed-step runs by the build before the
# explicit pair (hex floats): a given dt keeps its method and steps. Compared to 1e-12
# relative: the runs are bit-identical on one machine; the tolerance only allows another
# compiler's reassociation.
FIXED = {
    ('rc', 'rk4'): ('rk4', ['0x1.13e3a33f97777p+9', '0x1.3c41226e25fb9p+9', '0x1.f8290fd349957p+7'], ['0x1.145b49044eea7p-17', '0x1.f92fb832fd6c2p-19', '0x1.f92fb832fd6abp-19']),
    ('rc', 'generalized-alpha'): ('generalized-alpha', ['0x1.13e392a455d01p+9', '0x1.3c413d7dd0820p+9', '0x1.f828a284e9483p+7'], ['0x1.145b683758966p-17', '0x1.f92f889bec2f8p-19', '0x1.f92f886774b22p-19']),
    ('rc', 'auto'): ('rk4', ['0x1.13e3a33f97777p+9', '0x1.3c41226e25fb9p+9', '0x1.f8290fd349957p+7'], ['0x1.145b49044eea7p-17', '0x1.f92fb832fd6c2p-19', '0x1.f92fb832fd6abp-19']),
    ('rlc', 'rk4'): ('rk4', ['0x1.dc208b37c993ap+13', '0x1.505f74c8366cap+13', '0x1.505f74c8366c4p+13'], ['0x1.5b6681bfbdcbap-13', '0x1.130d21a3270fcp-14', '0x1.01b76a5d2ab6dp-13']),
    ('rlc', 'generalized-alpha'): ('generalized-alpha', ['0x1.dc20a8464bc66p+13', '0x1.505f69b39f060p+13', '0x1.505f69a767c2dp+13'], ['0x1.5b66b5311d38bp-13', '0x1.130cbd9093f47p-14', '0x1.01b77fd70f7b0p-13']),
    ('rlc', 'auto'): ('rk4', ['0x1.dc208b37c993ap+13', '0x1.505f74c8366cap+13', '0x1.505f74c8366c4p+13'], ['0x1.5b6681bfbdcbap-13', '0x1.130d21a3270fcp-14', '0x1.01b76a5d2ab6dp-13']),
}


def test_a_given_dt_keeps_the_fixed_step_runs() -> None:
    models = {"rc": rc()[0], "rlc": rlc()[0]}
    for (name, method), (ran, pressures, flows) in FIXED.items():
        res = oxyline.simulate(models[name], dt=1e-3, method=method, cycles=2, output_every=0.05)
        assert res.settings["method"] == ran
        v = res.vessel("v")
        for k, p, q in zip((3, 11, 19), pressures, flows, strict=True):
            assert float(v.pressure_in[k]) == pytest.approx(float.fromhex(p), rel=1e-12, abs=0)
            assert float(v.flow_out[k]) == pytest.approx(float.fromhex(q), rel=1e-12, abs=0)


#: the pair on the valve model at rtol 1e-5 against the small fixed step (measured 1.5e-8;
#: the fixed step's own error ~1e-7)
TOL_PAIR_VALVE = 1e-6


def test_the_pair_steps_a_valve_as_a_small_fixed_step_and_auto_keeps_the_implicit_method(
        ) -> None:
    """A tanh valve in series with a resistor: the pair at rtol 1e-5, its valve events
    located (docs/physics.md §10.5), against generalized-α at dt = 20 µs (second order: its
    own error ~1e-7 of the flow's range). The valve has no inductance: its law sits on an
    algebraic row, which the pair's stages solve by Newton, so `auto` keeps generalized-α
    (docs/solvers.md, "`auto`'s rule"): the volume through the valve over the cycle within
    2x rtol (measured 1.2e-4), the flow within 5 % of its range (measured 2.9 %, at the
    opening, where the second-order method's event timing errs most)."""
    model = {
        "name": "valve", "units": "SI", "period": 1.0,
        "vessels": [
            {"name": "mitral", "from": "in", "to": "mid", "valve": {
                "law": "tanh", "min_resistance": 1e6, "max_resistance": 1e10, "steepness": 0.01}},
            {"name": "r", "from": "mid", "to": "out", "arrangement": "RCL",
             "lumped": {"resistance": 1e8}}],
        "boundary_conditions": {
            "in": {"type": "pressure", "fourier": {"period": 1.0, "mean": 0.0, "sin": [2e3]}},
            "out": {"type": "pressure", "value": 0.0}}}
    res = oxyline.simulate(model, cycles=2, method="dopri5", rtol=1e-5, output_every=1e-3)
    ref = oxyline.simulate(model, cycles=2, method="generalized-alpha", dt=2e-5,
                           output_every=1e-3)
    assert res.settings["method"] == "dopri5" and res.valve_events
    q, want = res.vessel("mitral").flow_in, ref.vessel("mitral").flow_in
    np.testing.assert_allclose(q, want, rtol=0, atol=TOL_PAIR_VALVE * np.ptp(want))
    auto = oxyline.simulate(model, cycles=2, rtol=1e-3, output_every=1e-3)
    assert auto.settings["method"] == "generalized-alpha"
    got, t = auto.vessel("mitral").flow_in, auto.time
    volume = float(np.trapezoid(np.abs(want), t))
    assert abs(np.trapezoid(got, t) - np.trapezoid(want, t)) <= 2e-3 * volume
    np.testing.assert_allclose(got, want, rtol=0, atol=5e-2 * np.ptp(want))


@pytest.mark.parametrize(("model", "settings", "message"), [
    ("bifurcation", {"method": "dopri5", "dt": 1e-3}, "method 'dopri5' chooses its own steps"),
    ("bifurcation", {"method": "dopri5", "rtol": 0.0}, "rtol must be a finite number > 0"),
    ("bifurcation", {"method": "dopri4"}, "method must be one of .*'dopri5'"),
])
def test_bad_explicit_settings_name_the_setting(model: str, settings: dict[str, Any],
                                                message: str) -> None:
    with pytest.raises(oxyline.ModelError, match=message):
        oxyline.simulate(model, cycles=1, **settings)


def test_the_low_level_network_run_defaults_to_error_control() -> None:
    """``Network.simulate`` without ``rtol`` or ``dt`` runs as ``oxyline.simulate`` does
    (error control at rtol 1e-3, docs/solvers.md), and ``rtol=None`` keeps the automatic fixed
    step: the controlled run's rows match the fixed 0.1 ms step's to 1 % of the range (the
    tolerance's order), the fixed run reports no error estimate."""
    model = oxyline.load_model("bifurcation")
    net = model.network
    kw = {"period": model.period, "output_every": 1e-2, "cycles": 2, "until_periodic": None}
    default = net.simulate(**kw)
    fixed = net.simulate(**kw, rtol=None)
    fine = net.simulate(**kw, dt=1e-4, method="generalized-alpha")
    assert "error_estimate" in default and "error_estimate" not in fixed
    ref = np.asarray(fine["data"])
    np.testing.assert_allclose(np.asarray(default["data"]), ref, rtol=0,
                               atol=1e-2 * float(np.ptp(ref)))
