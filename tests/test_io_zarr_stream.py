"""Zarr written during the run (``oxyline.simulate_to_zarr``, CLI ``-o out.zarr``): the store
equals the in-memory result's, the core hands over at most one chunk at a time, and an
interrupted or failing run leaves a valid store with what it computed."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import run_child

import oxyline
from oxyline import catalogue
from oxyline.cli import main
from oxyline.io import results
from oxyline.run import _settings

pytest.importorskip("zarr")
xr = pytest.importorskip("xarray")


def _assert_store_equals_result(ds: Any, res: oxyline.Result) -> None:
    """Same variables, dims, coords, values, variable attrs and file attrs as ``to_zarr``."""
    ref = results.dataset(res)
    xr.testing.assert_identical(ds.load(), ref)
    assert ds.attrs == ref.attrs and ds.attrs["complete"] == int(res.complete)


@pytest.mark.parametrize(("name", "options", "chunk"), [
    ("bifurcation", {"cycles": 2, "output_cycles": "all"}, 300),  # 2001 rows, 7 chunks
    ("paper-bifurcated", {"cycles": 2, "output_cycles": "all"}, 300),  # oxygen
    ("paper-bifurcated", {"cycles": 2, "until_periodic": 1e-30, "max_cycles": 3}, 64),  # last
])
def test_streamed_store_equals_the_in_memory_result(tmp_path: Path, name: str,
                                                    options: dict[str, Any], chunk: int) -> None:
    model = catalogue.load(name)
    ds = oxyline.simulate_to_zarr(model, tmp_path / "s.zarr", time_chunk=chunk, **options)
    res = oxyline.simulate(model, **options)
    assert ds.sizes["time"] % chunk != 0
    _assert_store_equals_result(ds, res)
    assert ds["pressure_in"].encoding["chunks"][0] == chunk
    # and the same as the after-the-run writer
    written = xr.open_zarr(res.to_zarr(tmp_path / "r.zarr", time_chunk=chunk))
    xr.testing.assert_identical(ds.load(), written.load())
    if name == "paper-bifurcated":
        assert "po2_in" in ds and ds["po2_in"].attrs["units"] == "mmHg"


def test_the_core_hands_over_at_most_one_chunk() -> None:
    model = catalogue.load("paper-bifurcated")
    s = _settings(model, {"cycles": 2, "output_cycles": "all"})
    full = model.network.simulate(**s)
    chunks: list[dict[str, Any]] = []
    raw = model.network.simulate(**s, chunk_sink=chunks.append, chunk_rows=300)
    n = len(full["times"])
    assert full["max_buffered_rows"] == n  # without a sink the core holds the whole output
    assert raw["max_buffered_rows"] <= 300  # with one, never more than a chunk
    assert len(chunks) == math.ceil(n / 300) and n % 300 != 0
    assert [len(c["times"]) for c in chunks] == [300] * (n // 300) + [n % 300]
    assert raw["times"].shape == (0,) and raw["data"].shape == (0, full["data"].shape[1])
    np.testing.assert_array_equal(np.concatenate([c["times"] for c in chunks]), full["times"])
    np.testing.assert_array_equal(np.concatenate([c["data"] for c in chunks]), full["data"])
    np.testing.assert_array_equal(
        np.concatenate([c["transport"]["data"] for c in chunks]), full["transport"]["data"])
    assert chunks[0]["transport"]["species"] == full["transport"]["species"]
    np.testing.assert_array_equal(raw["final_state"], full["final_state"])


def test_python_appends_chunk_by_chunk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rows: list[int] = []
    append = results.ZarrAppender.append

    def spy(self: results.ZarrAppender, ds: Any) -> None:
        rows.append(ds.sizes["time"])
        # the store already holds every earlier chunk when the next one arrives
        assert xr.open_zarr(self.path).sizes["time"] == sum(rows[:-1])
        append(self, ds)

    monkeypatch.setattr(results.ZarrAppender, "append", spy)
    ds = oxyline.simulate_to_zarr("bifurcation", tmp_path / "s.zarr", time_chunk=500, cycles=2,
                                  output_cycles="all")
    assert rows == [500, 500, 500, 500, 1] and ds.sizes["time"] == 2001


def _stop_after(t_stop: float) -> Any:
    def stop(t: float, t_end: float) -> None:
        if t > t_stop:
            raise KeyboardInterrupt

    return stop


def test_interrupted_run_leaves_a_valid_store_with_the_chunks_so_far(tmp_path: Path) -> None:
    with pytest.raises(oxyline.SimulationInterrupted) as info:
        oxyline.simulate_to_zarr("bifurcation", tmp_path / "s.zarr", time_chunk=64, cycles=200,
                                 method="rk4", output_cycles="all", progress=_stop_after(0.3))
    ds = xr.open_zarr(tmp_path / "s.zarr")
    assert info.value.result is not None and info.value.result.sizes == ds.sizes
    n = ds.sizes["time"]
    assert n > 64 and ds.attrs["complete"] == 0
    # the rows written are exactly those of an uninterrupted run up to that time
    t_last = float(ds["time"][-1])
    full = oxyline.simulate("bifurcation", cycles=int(t_last) + 1, method="rk4",
                            output_cycles="all")
    ref = results.dataset(full).isel(time=slice(0, n))
    for name in ref.data_vars:
        np.testing.assert_array_equal(ds[name].values, ref[name].values, err_msg=name)


def test_a_failing_sink_stops_the_run_with_its_exception(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    append = results.ZarrAppender.append
    calls = []

    def disk_full(self: results.ZarrAppender, ds: Any) -> None:
        calls.append(ds.sizes["time"])
        if len(calls) == 2:
            raise OSError("disk full")
        append(self, ds)

    monkeypatch.setattr(results.ZarrAppender, "append", disk_full)
    with pytest.raises(OSError, match="disk full") as info:
        oxyline.simulate_to_zarr("paper-bifurcated", tmp_path / "s.zarr", time_chunk=100,
                                 cycles=3, output_cycles="all")
    assert calls == [100, 100]  # the run stopped: no further chunk was produced
    ds = xr.open_zarr(tmp_path / "s.zarr")
    assert ds.sizes["time"] == 100 and ds.attrs["complete"] == 0
    assert info.value.result.sizes["time"] == 100


def test_errors_before_the_run_leave_no_store(tmp_path: Path) -> None:
    with pytest.raises(oxyline.ModelError):
        oxyline.simulate_to_zarr("bifurcation", tmp_path / "s.zarr", method="rk4", dt=1.0)
    assert not (tmp_path / "s.zarr").exists()
    with pytest.raises(oxyline.ModelError, match="time_chunk"):
        oxyline.simulate_to_zarr("bifurcation", tmp_path / "s.zarr", time_chunk=0)


def test_summary_of_a_store_equals_the_results(tmp_path: Path) -> None:
    pd = pytest.importorskip("pandas")
    ds = oxyline.simulate_to_zarr("paper-bifurcated", tmp_path / "s.zarr", cycles=2)
    res = oxyline.simulate("paper-bifurcated", cycles=2)
    # (a store lists its variables alphabetically: the same columns in another order)
    pd.testing.assert_frame_equal(results.summary(ds), res.summary(), check_like=True)


def test_cli_streams_zarr_end_to_end(tmp_path: Path) -> None:
    out = run_child(
        [sys.executable, "-m", "oxyline.cli", "run", "paper-bifurcated", "--cycles", "2", "-o",
         "out.zarr", "--summary", "s.csv"],
        cwd=tmp_path, env=dict(os.environ), timeout=300)
    assert out.returncode == 0, out.stderr
    assert "results written to out.zarr" in out.stdout and "ICA" in out.stdout
    res = oxyline.simulate("paper-bifurcated", cycles=2)
    _assert_store_equals_result(xr.open_zarr(tmp_path / "out.zarr"), res)
    import pandas as pd

    summary = pd.read_csv(tmp_path / "s.csv", index_col="vessel")  # units in the header row
    assert summary.loc["ICA", "po2_out_mean [mmHg]"] == pytest.approx(
        res.summary().loc["ICA", "po2_out_mean"], rel=1e-12)  # the store's summary: round-off


def test_cli_interrupted_run_exits_130_with_the_partial_store(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from oxyline import run

    monkeypatch.setattr(run, "_progress_bar", lambda enabled, s=None, passes=1: (_stop_after(0.3), None))
    out = tmp_path / "out.zarr"
    assert main(["run", "bifurcation", "--cycles", "200", "--method", "rk4", "-o", str(out)]) \
        == 130
    assert "partial result written" in capsys.readouterr().err
    ds = xr.open_zarr(out)
    assert ds.attrs["complete"] == 0 and ds.sizes["time"] > 0
    assert np.isfinite(ds["pressure_in"].values).all()


@pytest.mark.parametrize("chunk", [97, 1000])
def test_streamed_heart_outputs_equal_the_in_memory_result(tmp_path: Path, chunk: int) -> None:
    """Chamber volumes and valve status in the streamed store: the same
    arrays bit for bit, also for the heart block's valves, whose status is a sequence (a
    closed valve reopens only by its pressure difference): carried across chunk borders."""
    import json

    from conftest import data_path

    from oxyline import svzerod as svz

    with open(data_path("svzerod", "cases", "closedLoopHeart_singleVessel.json")) as f:
        model = svz.to_model(json.load(f))
    options = {"cycles": 3, "output_cycles": "all"}
    ds = oxyline.simulate_to_zarr(model, tmp_path / "h.zarr", time_chunk=chunk, **options)
    res = oxyline.simulate(model, **options)
    assert ds.sizes["time"] % chunk != 0 and len(res.valve_status) == 4
    # every valve opens and closes in the run, so a chunk border falls inside each state
    assert all(0 < v.mean() < 1 for v in res.valve_status.values())
    _assert_store_equals_result(ds, res)
    back = oxyline.open_result(tmp_path / "h.zarr")
    for name, v in res.chamber_volume.items():
        np.testing.assert_array_equal(back.chamber_volume[name], v)
    for name, v in res.valve_status.items():
        np.testing.assert_array_equal(back.valve_status[name], v)


def test_a_finished_store_is_read_back_before_another_writer_may_have_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A writer starting between a run's last write and its read-back of the store is refused
    (the lock is held until the store is opened), so the run returns its own complete store,
    never the newcomer's overwrite in progress (attribute complete = 0)."""
    import xarray as xr

    from oxyline.errors import OutputError

    path = tmp_path / "run.zarr"
    newcomer: list[str] = []
    real_open = xr.open_zarr

    def open_after_a_newcomer(p: Any, *args: Any, **kwargs: Any) -> Any:
        if not newcomer:  # the newcomer starts right before the finished run reads its store
            try:
                oxyline.simulate_to_zarr("bifurcation", path, cycles=1, overwrite=True,
                                         progress=False)
                newcomer.append("wrote")
            except OutputError as exc:
                newcomer.append(str(exc))
        return real_open(p, *args, **kwargs)

    monkeypatch.setattr(xr, "open_zarr", open_after_a_newcomer)
    ds = oxyline.simulate_to_zarr("bifurcation", path, cycles=2, overwrite=True, progress=False)
    assert newcomer and "another process is writing this store" in newcomer[0], newcomer
    assert int(ds.attrs["complete"]) == 1
