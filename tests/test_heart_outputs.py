"""Chamber volumes and valve status in the native Result, checked against
physics rather than against the columns they are read from: a chamber's volume against its
own flow balance dV/dt = Q_in − Q_out (the vessel's recorded flows, integrated), a closed
valve against its flow, and the heart block's isovolumic phases (both left-heart valves
closed: the ventricle's volume does not change, docs/physics.md §1.10)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import oxyline
from oxyline import svzerod as svz
from tests.conftest import data_path
from tests.test_svzerod_chambers import CLOSED_LOOP


@pytest.fixture(scope="module")
def loop() -> oxyline.Result:
    return oxyline.simulate(oxyline.load_model(copy.deepcopy(CLOSED_LOOP)), cycles=4,
                            method="generalized-alpha", dt=1e-4, output_every=1e-4,
                            output_cycles="all")


def test_chamber_volume_follows_its_flow_balance(loop: oxyline.Result) -> None:
    lv = loop.vessel("lv")
    v = loop.chamber_volume["lv"]
    net = lv.flow_in - lv.flow_out
    # trapezoid integral of the recorded flows over the recorded steps (generalized-α's own
    # quadrature differs from the trapezoid by O(dt²) per step around the valve switches)
    integral = v[0] + np.concatenate([[0.0], np.cumsum(0.5 * (net[1:] + net[:-1])
                                                       * np.diff(loop.time))])
    stroke = np.ptp(v[-8000:])
    err = float(np.max(np.abs(v - integral)) / stroke)
    assert stroke > 1e-5 and err < 1e-3, (stroke, err)


def test_valve_status_matches_its_flow(loop: oxyline.Result) -> None:
    for name in ("aortic_valve", "mitral_valve"):
        status = loop.valve_status[name]
        q = loop.vessel(name).flow_in
        assert status.dtype == np.int8 and set(np.unique(status)) == {0, 1}
        # closed (R → R_max = 1e11 Pa s/m^3): a leak ΔP/R_max of at most 5e-7 m^3/s for the
        # ~5e4 Pa across a closed valve, 2.7e-3 of the open valve's peak flow (2e-4 m^3/s)
        assert np.max(np.abs(q[status == 0])) < 1e-2 * np.max(np.abs(q)), name
    # the two valves of the ventricle are never open together (isovolumic phases between)
    both = loop.valve_status["aortic_valve"] & loop.valve_status["mitral_valve"]
    assert both.mean() < 0.01, both.mean()
    ds = loop.to_xarray()
    assert ds["valve_status"].dims == ("time", "valve")
    np.testing.assert_array_equal(ds["chamber_volume"].sel(chamber="lv"), loop.chamber_volume["lv"])
    table = loop.heart_table()
    assert {"Vc:lv", "valve_status:aortic_valve"} <= set(table.columns)


def test_heart_block_isovolumic_phases() -> None:
    """svZeroDSolver's closed-loop heart as the native `heart_pulmonary` element with RK4's
    explicit valve law: while the mitral and aortic valves are both closed, the left
    ventricle's volume is constant (a closed valve's flow is held at zero)."""
    model = oxyline.load_model(svz.to_oxyline_dict(str(data_path(
        "svzerod", "cases", "closedLoopHeart_singleVessel.json"))))
    res = oxyline.simulate(model, method="rk4", cycles=4, output_every=1e-3)
    names = {f"CLH:{v}" for v in ("tricuspid", "pulmonary", "mitral", "aortic")}
    assert set(res.valve_status) == names
    lv = res.chamber_volume["CLH:left_ventricle"]
    closed = (res.valve_status["CLH:mitral"] == 0) & (res.valve_status["CLH:aortic"] == 0)
    pairs = closed[1:] & closed[:-1]
    assert pairs.sum() > 20  # both isovolumic phases are sampled
    change = np.max(np.abs(np.diff(lv)[pairs])) / np.ptp(lv)
    # the closed valves' flows are exactly zero: only round-off of the volume sums
    assert change < 1e-12, change
    # ejection happens: the aortic valve opens once per cycle
    assert 0.1 < res.valve_status["CLH:aortic"].mean() < 0.6


def test_heart_block_valve_status_with_generalized_alpha_follows_rk4() -> None:
    """With generalized-α a closed heart valve keeps the small flow of the last Newton
    correction (of either sign); the status must not read that as open. RK4's explicit law
    (closed flows exactly zero) is the independent check: the open fraction of each valve
    agrees within 0.1 of the cycle and the samples agree where the two schemes' valve timing
    does (≥ 85 % of them: they differ near the switches by the schemes' own timing error)."""
    model = oxyline.load_model(svz.to_oxyline_dict(str(data_path(
        "svzerod", "cases", "closedLoopHeart_singleVessel.json"))))
    runs = {m: oxyline.simulate(model, method=m, cycles=4, output_every=1e-3, newton_atol=1e-8)
            for m in ("generalized-alpha", "rk4")}
    for name, rk in runs["rk4"].valve_status.items():
        ga = runs["generalized-alpha"].valve_status[name]
        assert abs(ga.mean() - rk.mean()) < 0.1, (name, ga.mean(), rk.mean())
        assert (ga == rk).mean() > 0.85, name
    assert 0.1 < runs["generalized-alpha"].valve_status["CLH:aortic"].mean() < 0.6


def test_left_heart_runs_under_the_default_error_control() -> None:
    """A left heart (tanh valves of width 200 Pa around an elastance-inductor chamber, into
    a Windkessel) under the default settings (error control, rtol 1e-3): plain Newton cycles
    at the aortic valve's switch at every step size (its algebraic rows do not shrink with
    the step), so the step is taken again with Newton's line search (docs/physics.md §10.5).
    Six cycles (the run failed at 4.3 s before the retry). Its cardiac output over the last
    cycle against an independent fixed step of 50 µs (its own error measured 2e-8 of the
    output against 20 µs), within 2x rtol."""
    from tests.test_sensitivity_heart import HEART

    def cardiac_output(res: oxyline.Result) -> float:
        q, t = res.vessel("aortic").flow_in, res.time
        return float(np.sum(0.5 * (q[1:] + q[:-1]) * np.diff(t)) / (t[-1] - t[0]))

    controlled = copy.deepcopy(HEART)
    del controlled["simulation"]
    res = oxyline.simulate(oxyline.load_model(controlled), cycles=6, until_periodic=None,
                           output_every=1e-4)
    assert res.settings["rtol"] == 1e-3 and res.settings["method"] == "generalized-alpha"
    fixed = copy.deepcopy(HEART)
    fixed["simulation"]["dt"] = 5e-5
    ref = oxyline.simulate(oxyline.load_model(fixed), cycles=6, until_periodic=None,
                           output_every=1e-4)
    got, want = cardiac_output(res), cardiac_output(ref)
    assert want > 1e-5  # it ejects (~39 mL/s)
    assert abs(got - want) <= 2 * 1e-3 * want, (got, want)


def _flow_balance_error(v: np.ndarray, q_in: np.ndarray, q_out: np.ndarray, t: np.ndarray
                        ) -> tuple[float, float]:
    """(stroke volume, largest gap between a chamber's volume and its start volume plus the
    trapezoid integral of its recorded inflow minus outflow, relative to the stroke)."""
    net = q_in - q_out
    integral = v[0] + np.concatenate([[0.0], np.cumsum(0.5 * (net[1:] + net[:-1]) * np.diff(t))])
    stroke = float(np.ptp(v[len(v) // 2:]))
    return stroke, float(np.max(np.abs(v - integral)) / stroke)


def test_streamed_chamber_volume_follows_its_flow_balance(tmp_path) -> None:
    """The core hands each streamed chunk its chamber volumes and valve statuses: the store's
    volume (read back, 97-row chunks: borders inside every valve state) against the integral
    of the store's own flows, as for the in-memory result (same O(dt²) quadrature gap), and
    every valve both open and closed in the store."""
    model = oxyline.load_model(copy.deepcopy(CLOSED_LOOP))
    oxyline.simulate_to_zarr(model, tmp_path / "loop.zarr", time_chunk=97, cycles=4,
                             method="generalized-alpha", dt=1e-4, output_every=1e-4,
                             output_cycles="all")
    back = oxyline.open_result(tmp_path / "loop.zarr")
    lv = back.vessel("lv")
    stroke, err = _flow_balance_error(back.chamber_volume["lv"], lv.flow_in, lv.flow_out,
                                      back.time)
    assert stroke > 1e-5 and err < 1e-3, (stroke, err)
    for name, status in back.valve_status.items():
        assert 0.0 < status.mean() < 1.0, name


def test_ensemble_chamber_volume_follows_its_flow_balance() -> None:
    """Each ensemble variant's chamber volume (the core's, per variant; ``output="full"``)
    against the integral of that variant's own recorded flows: two systemic resistances, two
    stroke volumes, each volume within the quadrature gap of its flow balance; the full output
    holds the valve statuses too, on the chamber and valve coordinates."""
    model = copy.deepcopy(CLOSED_LOOP)
    patches = [{}, {"vessels": {"systemic": {"lumped": {"resistance": 1.0e8}}}}]
    ds = oxyline.simulate_ensemble(model, patches, output="full", cycles=4,
                                   method="generalized-alpha", dt=1e-4, output_every=1e-4,
                                   output_cycles="all", progress=False)
    strokes = []
    for i in range(len(patches)):
        v = ds["chamber_volume"].sel(chamber="lv").values[i]
        q_in = ds["flow_in"].sel(vessel="lv").values[i]
        q_out = ds["flow_out"].sel(vessel="lv").values[i]
        stroke, err = _flow_balance_error(v, q_in, q_out, ds["time"].values[i])
        assert stroke > 1e-5 and err < 1e-3, (i, stroke, err)
        strokes.append(stroke)
        for valve in ("aortic_valve", "mitral_valve"):  # each opens and closes every beat
            status = ds["valve_status"].sel(valve=valve).values[i]
            assert set(np.unique(status)) == {0.0, 1.0}, (i, valve)
    assert strokes[1] > strokes[0]  # the lower resistance moves more blood per beat
