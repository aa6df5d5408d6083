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


# ---- Dask: workers that die, and cancel ---------------------------------------------------

POISON_SEGMENTS = 7  # the poison variant is the one whose aorta has 7 segments


def _peak(res: oxyline.Result) -> dict[str, float]:
    return {"p_max": float(res.pressure_in.max())}


def _poison(res: oxyline.Result) -> dict[str, float]:
    """Kills the worker process that runs the poison variant (a crash in its output)."""
    import os

    if res.segment_count[0] == POISON_SEGMENTS:
        os._exit(1)
    return _peak(res)


def _die() -> None:
    import os

    os._exit(1)


def test_dask_ensembles_survive_their_workers_killed_and_can_be_cancelled() -> None:
    distributed = pytest.importorskip("distributed")
    import threading

    radii = np.linspace(0.006, 0.01, 8)
    variants = [{"vessels": {"aorta": {"radius": r}}} for r in radii]
    healthy = oxyline.simulate_ensemble(STRAIGHT, variants, output=_peak, **FAST)
    assert (healthy.status.values == 0).all()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        # every worker killed once the first chunk is in: the restarted workers finish the
        # ensemble (the model is scattered to them again)
        killed = []

        def kill_all(done: int, total: int) -> None:
            if not killed:
                killed.append(done)
                try:
                    client.run(_die)
                except Exception:  # noqa: BLE001, S110 - the workers die while answering
                    pass

        ds = oxyline.simulate_ensemble(STRAIGHT, variants, client=client, output=_peak,
                                       cycles=2, progress=kill_all)
        assert killed and (ds.status.values == 0).all(), ds.status.values
        np.testing.assert_array_equal(ds.p_max.values, healthy.p_max.values)

        # cancel= stops a Dask ensemble (set here once the first chunk is in): the finished
        # variants come back, the others have status -1
        client.wait_for_workers(2, timeout=120)
        many = [{"vessels": {"aorta": {"radius": r}}} for r in np.linspace(0.006, 0.01, 40)]
        many_ok = oxyline.simulate_ensemble(STRAIGHT, many, output=_peak, **FAST)
        stop = threading.Event()
        with pytest.raises(oxyline.SimulationCancelled) as exc:
            oxyline.simulate_ensemble(STRAIGHT, many, client=client, output=_peak,
                                      cycles=2, cancel=stop,
                                      progress=lambda done, total: stop.set())
        st = exc.value.result.status.values
        done = st == 0
        assert 0 < done.sum() < 40 and set(st[~done].tolist()) == {-1}, st
        np.testing.assert_array_equal(exc.value.result.p_max.values[done],
                                      many_ok.p_max.values[done])
        with pytest.raises(oxyline.ModelError, match="variant_timeout is for ensembles"):
            oxyline.simulate_ensemble(STRAIGHT, variants, client=client, variant_timeout=5)


class _FakeFuture:
    """A Dask future as the ensemble's client loop sees it: a status and a key."""

    def __init__(self, key: str) -> None:
        self.key, self.status = key, "finished"


class _FakeClient:
    """The calls the ensemble's client loop makes, recorded: no cluster, so the order of
    Dask's messages (a chunk cancelled before the client hears its model is lost) is set
    here instead of left to timing."""

    def __init__(self) -> None:
        self.scattered: list[_FakeFuture] = []
        self.submitted = 0

    def scatter(self, data: list[Any], broadcast: bool) -> list[_FakeFuture]:
        self.scattered.append(_FakeFuture("model"))
        return [self.scattered[-1]]

    def wait_for_workers(self, n: int, timeout: float) -> None:
        pass

    def submit(self, *args: Any, **kwargs: Any) -> _FakeFuture:
        self.submitted += 1
        return _FakeFuture(f"chunk-{self.submitted}")


def test_a_chunk_cancelled_for_its_lost_model_scatters_the_model_again() -> None:
    """Every worker killed: Dask cancels the chunks that need the scattered model, and that
    cancellation can reach the client before the news that the model's copies are lost (its
    future still "finished"). The first such chunk scatters the model again and goes out on
    the new copy; a second chunk cancelled on the old copy goes out without another scatter;
    a chunk cancelled on the new copy scatters once more."""
    from concurrent.futures import CancelledError

    from oxyline.ensemble.cluster import _ClientRun

    client = _FakeClient()
    model = oxyline.load_model(STRAIGHT)
    run = _ClientRun(client, model, [{}] * 4, _peak, None, {}, collector=None)  # type: ignore[arg-type]
    run.sent_with = {range(2): 0, range(2, 4): 0}
    run.pending = set()
    assert len(client.scattered) == 1 and run.shared.status == "finished"
    assert run.failed(range(2), CancelledError()) is False
    assert len(client.scattered) == 2 and run.shared is client.scattered[-1]
    assert run.failed(range(2, 4), CancelledError()) is False
    assert len(client.scattered) == 2 and client.submitted == 2
    assert run.failed(range(2), CancelledError()) is False
    assert len(client.scattered) == 3 and client.submitted == 3


def test_a_dask_variant_that_kills_its_worker_fails_alone() -> None:
    """A variant that kills its worker process (os._exit in its output) fails with that
    error after it killed its worker on its own; the 7 healthy variants, 3 of them in its
    chunk, run. The cluster is the one Dask's own test suite uses to restart workers in
    milliseconds: workers forked from a preloaded forkserver, and a task failed at its
    first worker death (``allowed_failures=0``; the default 3 only repeats each death)."""
    distributed = pytest.importorskip("distributed")
    import dask

    variants = [{"vessels": {"aorta": {"radius": r}}} for r in np.linspace(0.006, 0.01, 8)]
    healthy = oxyline.simulate_ensemble(STRAIGHT, variants, output=_peak, **FAST)
    poisoned = copy.deepcopy(variants)
    poisoned[2]["vessels"]["aorta"]["segments"] = POISON_SEGMENTS
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                     dashboard_address=None,
                                     scheduler_kwargs={"allowed_failures": 0}) as cluster, \
            distributed.Client(cluster) as client:
        # it fails with that error; the others of its chunk run on (before:
        # FutureCancelledError and no result)
        ds = oxyline.simulate_ensemble(STRAIGHT, poisoned, client=client, output=_poison,
                                       **FAST)
    st = ds.status.values
    assert st[2] != 0 and "Dask worker failed" in str(ds.error.values[2])
    ok = np.arange(8) != 2
    assert (st[ok] == 0).all(), st
    np.testing.assert_array_equal(ds.p_max.values[ok], healthy.p_max.values[ok])
