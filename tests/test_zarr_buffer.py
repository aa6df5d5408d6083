"""The rows a streamed store's run holds at once (``simulate_to_zarr``): without
``time_chunk`` the rows per chunk are the most whose copies in flight stay within the memory
budget, every chunk handed over holds at most that many, and the memory check before the run
counts them (a ``ResourceError`` before anything is written)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_zarr_regions import _tree

import oxyline
from oxyline import memory
from oxyline.io import results

pytest.importorskip("zarr")
xr = pytest.importorskip("xarray")

VARIABLES = ["segment_flow", "segment_wall_flux"]  # 124 segments each: no derived variable


def _stored_columns(ds: Any) -> int:
    """Values per output row in the store: time, and every time-dependent variable's."""
    return 1 + sum(int(np.prod(v.shape[1:])) for v in ds.data_vars.values()
                   if v.dims[:1] == ("time",))


def test_rows_per_chunk_keep_the_copies_in_flight_within_the_budget(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    budget = 50_000  # bytes: a few rows of ~250 columns
    monkeypatch.setattr(memory, "STREAM_BUDGET", budget)
    handed: list[int] = []
    append = results.ZarrAppender.append

    def spy(self: Any, ds: Any) -> None:
        handed.append(int(ds.sizes["time"]))
        append(self, ds)

    monkeypatch.setattr(results.ZarrAppender, "append", spy)
    ds = oxyline.simulate_to_zarr(_tree(), tmp_path / "s.zarr", cycles=1, variables=VARIABLES,
                                  segments=True)
    cols = _stored_columns(ds)
    rows = ds["segment_wall_o2_flux"].encoding["chunks"][0]
    print(f"{cols} columns: {rows} rows per chunk, chunks handed over {handed[:4]}...")
    # three copies of 8 bytes per value: within the budget, and one more row would not be
    assert memory.STREAM_COPIES * 8 * rows * cols <= budget
    assert memory.STREAM_COPIES * 8 * (rows + 1) * cols > budget
    assert rows < memory.STREAM_MAX_ROWS  # the fixed default would have held 1024 rows
    assert max(handed) == rows and sum(handed) == ds.sizes["time"]
    for name in ("segment_flow", "segment_wall_o2_flux", "o2_mass_stored"):
        assert ds[name].encoding["chunks"][0] == rows


def test_a_small_output_keeps_the_former_chunk_of_1024_rows(tmp_path: Path) -> None:
    ds = oxyline.simulate_to_zarr("bifurcation", tmp_path / "b.zarr", cycles=2,
                                  output_cycles="all")
    assert ds.sizes["time"] == 2001 and ds["pressure_in"].encoding["chunks"][0] == 1024


def test_last_cycle_output_above_the_budget_streams_only_the_last_cycle(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A cycle's rows above the budget are not held for the cycles before the last: the
    store still holds the whole last cycle, the rows of the in-memory run."""
    monkeypatch.setattr(memory, "STREAM_BUDGET", 50_000)
    ds = oxyline.simulate_to_zarr(_tree(), tmp_path / "s.zarr", cycles=2, variables=VARIABLES,
                                  segments=True)
    res = oxyline.simulate(_tree(), cycles=2, variables=VARIABLES, segments=True)
    np.testing.assert_array_equal(ds["time"].values, res.time)
    np.testing.assert_array_equal(ds["segment_flow"].values, res.segment_flow)


def test_the_memory_check_counts_the_rows_held(tmp_path: Path) -> None:
    """3 cycles of 1001 rows of 254 columns in one chunk: the core's table of 4096 rows, three
    copies, 25 MB, refused under max_memory = 10 MB before the store is created; the budget's
    chunk of 1024 rows (6.2 MB) runs."""
    path = tmp_path / "big.zarr"
    run = {"cycles": 3, "output_cycles": "all", "variables": VARIABLES, "segments": True,
           "max_memory": "10 MB"}
    with pytest.raises(oxyline.ResourceError, match="time_chunk") as info:
        oxyline.simulate_to_zarr(_tree(), path, time_chunk=100_000, **run)
    print(info.value)
    assert "streamed output's rows held at once" in str(info.value)
    assert not path.exists()
    ds = oxyline.simulate_to_zarr(_tree(), path, **run)
    assert ds.attrs["complete"] == 1 and ds.sizes["time"] == 3001


def test_the_chunk_rule() -> None:
    """Rows per chunk, worked by hand from 256 MiB / (3 copies x 8 bytes x columns): 1e7
    columns (a segment variable of ten million segments) 1.1 -> 1 row; 100 001 columns 111,
    rounded down to a power of two above 64 -> 64; 33 333 columns 335 -> 256; 10 columns
    1.1e6 -> at most 1024; a row alone above the budget -> 1 row, not none."""
    assert memory.stream_rows(10_000_001) == 1
    assert memory.stream_rows(100_001) == 64
    assert memory.stream_rows(33_333) == 256
    assert memory.stream_rows(10) == 1024
    assert memory.stream_rows(10**12) == 1
    # the core's table of a chunk: exactly the chunk at these sizes (64 doubled to 256)
    assert memory.table_rows(256, 256) == 256 and memory.table_rows(5, 5) == 5
    assert memory.table_rows(200, 200) == 256  # a chunk given by hand: 64, 128, 256


def test_a_chunk_is_never_longer_than_the_output(tmp_path: Path) -> None:
    """zarr holds a chunk whole (padded to its rows) while it encodes it: a time_chunk above
    the output's rows (two cycles every 10 ms: 201 rows) is cut to them."""
    ds = oxyline.simulate_to_zarr("bifurcation", tmp_path / "b.zarr", cycles=2,
                                  output_cycles="all", output_every=0.01, time_chunk=5000)
    assert ds.sizes["time"] == 201 and ds["pressure_in"].encoding["chunks"][0] == 201
