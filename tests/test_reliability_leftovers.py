"""Hostile cases of the ensemble store, chamber inputs and Dask runs: a disk that fills while
an ensemble store is written, a float where an svZeroDSolver chamber case has a list, a Dask
variant that kills its worker, every worker killed mid-run, and a Dask ensemble cancelled."""

from __future__ import annotations

import copy
import errno
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import oxyline

DATA = Path(__file__).parent / "data"
STRAIGHT = "paper-straight"
FAST = {"cycles": 2, "progress": False}


# ---- a disk that fills while an ensemble store is written ---------------------------------

@pytest.mark.skipif(sys.version_info < (3, 11), reason="needs zarr (Python >= 3.11)")
def test_a_full_disk_says_which_variants_the_store_holds(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The disk fills (ENOSPC, injected deterministically into the store's writes) while the
    4th variant is stored: an OutputError names the store and the 3 variants it holds whole,
    the store opens with exactly those, and every variant is in exc.result."""
    import xarray as xr

    from oxyline.ensemble import store as store_module

    variants = [{"vessels": {"aorta": {"radius": 0.006 + 0.0005 * k}}} for k in range(6)]
    whole = oxyline.simulate_ensemble(STRAIGHT, variants, workers=1, **FAST)
    writes = {"variants": 0}
    real = store_module.StoreWriter.write

    def write(self: Any, i: int) -> None:  # the 4th variant's status write hits a full disk
        writes["variants"] += 1
        if writes["variants"] == 4:
            group = self._group

            class Full:
                def __getitem__(self, name: str) -> Any:
                    arr = group[name]
                    if name != "status":
                        return arr

                    class Failing:
                        def __setitem__(self, key: Any, value: Any) -> None:
                            raise OSError(errno.ENOSPC, "No space left on device")
                    return Failing()

                def __contains__(self, name: str) -> bool:
                    return name in group

            self._group = Full()
            try:
                real(self, i)
            finally:
                self._group = group
            return
        real(self, i)

    monkeypatch.setattr(store_module.StoreWriter, "write", write)
    path = tmp_path / "e.zarr"
    with pytest.raises(oxyline.OutputError) as exc:
        oxyline.simulate_ensemble(STRAIGHT, variants, workers=1, store=path, **FAST)
    msg = str(exc.value)
    assert str(path) in msg and "No space left on device" in msg
    assert "holds 3 of 6 variants whole (0-2;" in msg
    stored = xr.open_zarr(path)
    np.testing.assert_array_equal(stored.status.values, [0, 0, 0, -1, -1, -1])
    assert stored.attrs["complete"] == 0
    np.testing.assert_array_equal(stored.pressure_in_max.values[:3],
                                  whole.pressure_in_max.values[:3])
    mem = exc.value.result  # nothing computed is lost
    np.testing.assert_array_equal(mem.status.values, whole.status.values)
    np.testing.assert_array_equal(mem.pressure_in_max.values, whole.pressure_in_max.values)


def test_variant_ranges_are_written_compactly() -> None:
    from oxyline.ensemble.store import _ranges

    assert _ranges([0, 1, 2, 3, 7, 9, 10]) == "0-3, 7, 9-10"
    assert _ranges([]) == ""


# ---- a float where a chamber case has a list ----------------------------------------------

def _lists(d: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _lists(v, (*path, k))
    elif isinstance(d, list):
        if path and isinstance(path[-1], str) and path[-1] != "analytical results":
            yield path
        for i, v in enumerate(d):
            yield from _lists(v, (*path, i))


CHAMBER_CASES = ("chamber_elastance_inductor.json", "piecewise_Chamber_and_Valve.json",
                 "closed_loop_two_hill.json")


@pytest.mark.parametrize("case", CHAMBER_CASES)
def test_a_float_where_a_chamber_case_has_a_list_is_a_model_error_naming_the_key(
        case: str) -> None:
    cfg = json.loads((DATA / "svzerod" / "cases" / case).read_text())
    paths = list(_lists(cfg))
    assert len(paths) >= 5
    for path in paths:
        bad = copy.deepcopy(cfg)
        node = bad
        for p in path[:-1]:
            node = node[p]
        node[path[-1]] = 1.5
        with pytest.raises(oxyline.ModelError) as exc:
            oxyline.load_model(bad)
        assert str(path[-1]) in str(exc.value), (path, str(exc.value))
