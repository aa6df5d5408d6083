"""The public Python API: results layout, conversions, run control (periodicity, interruption,
GIL release), CLI. Physical correctness is tested in test_flow_physics.py."""

from __future__ import annotations

import os
import pickle
import signal
from pathlib import Path

import numpy as np
import pytest
from conftest import main_thread_ticks, signal_cli_run

import oxyline


@pytest.fixture(scope="module")
def result() -> oxyline.Result:
    return oxyline.simulate("bifurcation", cycles=3)


def test_result_arrays_are_views_of_the_core_buffer(result: oxyline.Result) -> None:
    assert result.pressure_in.shape == (1001, 3)
    assert np.shares_memory(result.pressure_in, result.data)
    assert result.time[0] == 0.0 and result.time[-1] == pytest.approx(1.0)


def test_conservation_at_the_junction_and_outlets(result: oxyline.Result) -> None:
    # inverted-L: the junction node stores volume, so parent outflow - daughters' inflow must
    # average to zero over a periodic cycle (mass conservation), and the inflow mean is the BC's.
    # Tolerance 2e-5 of the cycle's inflow volume: the run is error-controlled at rtol 1e-3
    # (the default) and its rows are the steps' continuous extension, so the trapezoid of the
    # rows conserves to the interpolant's error, not to rounding (measured 5.6e-6)
    parent, d1, d2 = (result.vessel(n) for n in ("parent", "daughter1", "daughter2"))
    stored = parent.flow_out - d1.flow_in - d2.flow_in
    assert abs(np.trapezoid(stored, result.time)) < 2e-5 * np.trapezoid(parent.flow_in, result.time)
    # (the inflow is an algebraic unknown of the error-controlled default run: held within
    # its rtol 1e-3 of its peak, ~4e-4 of the mean here)
    assert np.trapezoid(parent.flow_in, result.time) == pytest.approx(6.0e-6, rel=1e-3)
    # pressure continuity at the junction node
    np.testing.assert_allclose(parent.pressure_out, d1.pressure_in)
    np.testing.assert_allclose(parent.pressure_out, d2.pressure_in)


def test_xarray_dataset_has_dims_units_and_segments(result: oxyline.Result) -> None:
    ds = result.to_xarray()
    assert set(ds["pressure_in"].dims) == {"time", "vessel"}
    assert ds["flow_in"].attrs["units"] == "m^3/s"
    assert list(ds["vessel"].values) == ["parent", "daughter1", "daughter2"]
    assert ds.sizes["segment"] == 30
    v = result.vessel("daughter1")
    np.testing.assert_array_equal(ds["flow_out"].sel(vessel="daughter1").values, v.flow_out)
    assert v.segment_flow is not None and v.segment_flow.shape == (1001, 10)
    # the vessel's outlet flow is its last segment's flow
    np.testing.assert_array_equal(v.segment_flow[:, -1], v.flow_out)



def test_a_vessel_is_found_by_name_also_after_pickling(result: oxyline.Result) -> None:
    # the name -> column table is built at the first look-up: an unknown name is named, and
    # a pickled result (which does not carry the table) finds each vessel's own segments: a
    # vessel's first segment carries its inlet flow, its last its outlet flow
    with pytest.raises(KeyError, match="vessel 'nope' has no output"):
        result.vessel("nope")
    back = pickle.loads(pickle.dumps(result))
    for name in ("daughter2", "parent"):
        v = back.vessel(name)
        assert v.segment_flow is not None and v.segment_flow.shape == (1001, 10)
        np.testing.assert_array_equal(v.segment_flow[:, 0], v.flow_in)
        np.testing.assert_array_equal(v.segment_flow[:, -1], v.flow_out)

def test_pandas_table_has_svzerod_columns(result: oxyline.Result) -> None:
    df = result.to_pandas()
    assert list(df.columns) == ["name", "time", "flow_in", "flow_out", "pressure_in", "pressure_out"]
    assert len(df) == 3 * 1001


def test_until_periodic_stops_early_and_reports_the_change() -> None:
    res = oxyline.simulate("bifurcation", cycles=1, until_periodic=1e-8, max_cycles=50)
    assert res.settings["cycles_run"] < 50
    assert res.settings["periodic_error"] < 1e-8


def test_output_every_and_all_cycles() -> None:
    res = oxyline.simulate("bifurcation", cycles=2, output_every=0.01, output_cycles="all")
    assert len(res.time) == 201
    np.testing.assert_allclose(np.diff(res.time), 0.01)


def test_model_pickles_and_rebuilds() -> None:
    m = oxyline.load_model("bifurcation")
    m2 = pickle.loads(pickle.dumps(m))
    r1 = oxyline.simulate(m, cycles=1)
    r2 = oxyline.simulate(m2, cycles=1)
    np.testing.assert_array_equal(r1.data, r2.data)


def test_a_model_that_has_run_still_pickles() -> None:
    # a run caches the core's network and its output layout on the model; neither can be
    # pickled, so a model sent to a Dask worker after a run must leave both behind
    m = oxyline.load_model("bifurcation")
    r1 = oxyline.simulate(m, cycles=1)
    m2 = pickle.loads(pickle.dumps(m))
    np.testing.assert_array_equal(r1.data, oxyline.simulate(m2, cycles=1).data)


def test_interruption_keeps_the_partial_result() -> None:
    calls = []

    def stop(t: float, t_end: float) -> None:
        calls.append(t)
        if t > 0.5:
            raise KeyboardInterrupt

    with pytest.raises(oxyline.SimulationInterrupted) as info:
        oxyline.simulate("bifurcation", cycles=200, method="rk4", progress=stop,
                         output_cycles="all")
    partial = info.value.result
    assert partial is not None and not partial.complete
    assert len(partial.time) > 10 and np.isfinite(partial.data).all()


def test_callback_errors_propagate_unchanged() -> None:
    def boom(t: float, t_end: float) -> None:
        raise ValueError("from callback")

    with pytest.raises(ValueError, match="from callback"):
        oxyline.simulate("bifurcation", cycles=50, method="rk4", progress=boom)


def test_gil_is_released_during_integration() -> None:
    ticks = main_thread_ticks(
        lambda: oxyline.simulate("bifurcation", cycles=40, method="rk4", segments=False))
    assert ticks > 20  # the main thread kept running while Rust integrated


@pytest.mark.skipif(os.name != "posix", reason="needs SIGINT")
def test_ctrl_c_in_the_cli_exits_130_and_writes_the_partial_result(tmp_path: Path) -> None:
    out = tmp_path / "partial.nc"
    # SIGINT is restored to its default in the child even when this test runs under a process
    # that ignores it (nohup, background job), and the child is killed and reaped on any failure.
    returncode, text = signal_cli_run(out, signal.SIGINT)
    assert returncode == 130, text
    assert "Traceback" not in text
    import xarray as xr

    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.attrs["complete"] == 0
        assert ds.sizes["time"] > 0
