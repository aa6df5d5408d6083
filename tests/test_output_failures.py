"""Disk full and bad output paths: a failed write is a typed error that names
the file and keeps the result, never a crash; output paths are checked before the run; an
existing store is never deleted without --overwrite. Disk full is simulated by a file-size limit
(RLIMIT_FSIZE: writes past it fail with EFBIG, as with ENOSPC) in a child process, or by a Zarr
store whose writes raise ENOSPC."""

from __future__ import annotations

import errno
import resource
import signal
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import run_child


def _netcdf4_in_memory() -> bool:
    from oxyline.io.results import netcdf4_in_memory

    return netcdf4_in_memory()


# Older xarray cannot encode NetCDF-4 into memory (it falls back to netCDF-3 through scipy), so
# oxyline writes the file directly after a free-space check, and h5py's own write can still
# crash on a disk that fills during it: the guarantee these tests check needs a newer xarray.
needs_in_memory_netcdf4 = pytest.mark.skipif(
    not _netcdf4_in_memory(), reason="this xarray cannot encode NetCDF-4 in memory")

import oxyline
from oxyline.cli import main

LIMIT = 20_000  # bytes per file: the bifurcation's NetCDF file is ~0.8 MB


def _small_files() -> None:
    """Child setup: SIGINT default (conftest) and files of at most LIMIT bytes."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, LIMIT))


@needs_in_memory_netcdf4
def test_netcdf_on_a_full_disk_is_an_output_error_that_keeps_the_result(tmp_path: Path) -> None:
    out = tmp_path / "out.nc"
    out.write_bytes(b"previous file")
    code = textwrap.dedent("""
        import sys, oxyline
        res = oxyline.simulate("bifurcation", cycles=1)
        try:
            res.to_netcdf(sys.argv[1])
        except oxyline.OutputError as exc:
            print("OutputError:", exc)
            print("kept", exc.result is res, exc.result.flow_in.shape)
    """)
    # before the fix h5py crashed the child with SIGSEGV (rc -11) inside its error handling
    done = run_child([sys.executable, "-c", code, str(out)], timeout=120,
                     preexec_fn=_small_files)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"OutputError: {out}: cannot write the NetCDF file: File too large" in done.stdout
    assert "kept True (1001, 3)" in done.stdout
    assert out.read_bytes() == b"previous file"  # replaced only by a complete file
    assert [p.name for p in tmp_path.iterdir()] == ["out.nc"]  # no temporary file left


@needs_in_memory_netcdf4
def test_cli_netcdf_on_a_full_disk_exits_3(tmp_path: Path) -> None:
    done = run_child([sys.executable, "-m", "oxyline.cli", "run", "bifurcation", "--cycles",
                      "1", "--quiet", "-o", "out.nc"], cwd=tmp_path, timeout=120,
                     preexec_fn=_small_files)
    assert done.returncode == 3, (done.returncode, done.stderr[-2000:])
    assert "error: out.nc: cannot write the NetCDF file" in done.stderr
    assert not any(tmp_path.iterdir())


def _fill_disk_after(monkeypatch: pytest.MonkeyPatch, chunks: int, writes: int) -> None:
    """Make the Zarr store's writes fail with ENOSPC from the ``writes``-th write of the chunk
    after ``chunks`` appended chunks on (a disk that stays full: the roll-back fails too)."""
    import zarr.storage

    from oxyline.io import results

    state = {"appended": 0, "writes": 0}
    set_ = zarr.storage.LocalStore.set
    append = results.ZarrAppender.append

    async def failing_set(self: object, key: str, value: object) -> None:
        if state["appended"] >= chunks:
            state["writes"] += 1
            if state["writes"] > writes:
                raise OSError(errno.ENOSPC, "No space left on device")
        await set_(self, key, value)

    def counting_append(self: results.ZarrAppender, ds: object) -> None:
        append(self, ds)
        state["appended"] += 1

    monkeypatch.setattr(zarr.storage.LocalStore, "set", failing_set)
    monkeypatch.setattr(results.ZarrAppender, "append", counting_append)


@pytest.mark.parametrize("writes", [0, 3])
def test_streamed_zarr_on_a_full_disk_keeps_the_rows_written(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, writes: int) -> None:
    pytest.importorskip("zarr")
    ref = oxyline.simulate("bifurcation", cycles=2, output_cycles="all")
    _fill_disk_after(monkeypatch, chunks=2, writes=writes)
    path = tmp_path / "s.zarr"
    with pytest.raises(oxyline.OutputError) as info:
        oxyline.simulate_to_zarr("bifurcation", path, cycles=2, output_cycles="all",
                                 time_chunk=256)
    msg = str(info.value)
    # before the fix: "conflicting sizes for dimension 'time'" and an unreadable store
    assert msg.startswith(f"{path}: writing output rows 512-767 failed: No space left on device")
    assert "keeps the 512 rows written before" in msg
    monkeypatch.undo()
    back = oxyline.open_result(path)
    assert back.time.size == 512 and not back.complete
    # streamed rows are the in-memory run's rows, bit for bit
    assert np.array_equal(back.pressure_in, ref.pressure_in[:512])
    assert np.array_equal(back.flow_out, ref.flow_out[:512])
    assert info.value.result is not None and info.value.result.sizes["time"] == 512


def test_existing_store_is_never_deleted_without_overwrite(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    pytest.importorskip("zarr")
    store = tmp_path / "old.zarr"
    store.mkdir()
    (store / "precious.txt").write_text("keep me")
    # before the fix, -o existing.zarr wiped the store when the run started
    assert main(["run", "bifurcation", "--cycles", "1", "--quiet", "-o", str(store)]) == 2
    assert "already exists; use --overwrite" in capsys.readouterr().err
    assert (store / "precious.txt").read_text() == "keep me"
    with pytest.raises(oxyline.OutputError, match="already exists"):
        oxyline.simulate_to_zarr("bifurcation", store, cycles=1)
    res = oxyline.simulate("bifurcation", cycles=1)
    with pytest.raises(oxyline.OutputError, match="already exists"):
        res.to_zarr(store)
    assert (store / "precious.txt").exists()
    assert main(["run", "bifurcation", "--cycles", "1", "--quiet", "-o", str(store),
                 "--overwrite"]) == 0
    assert not (store / "precious.txt").exists()
    assert oxyline.open_result(store).complete
    res.to_zarr(store, overwrite=True)
    assert np.array_equal(oxyline.open_result(store).flow_in, res.flow_in)


def _never_run(*args: object, **kwargs: object) -> None:
    raise AssertionError("the run started before the output path was checked")


@pytest.mark.parametrize("output", ["missing/out.nc", "file.txt/out.nc", "out.zarr/"])
def test_bad_output_paths_fail_before_the_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str],
                                              output: str) -> None:
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "out.zarr").mkdir()
    monkeypatch.setattr(oxyline, "simulate", _never_run)
    monkeypatch.setattr(oxyline, "simulate_to_zarr", _never_run)
    monkeypatch.chdir(tmp_path)
    assert main(["run", "bifurcation", "--quiet", "-o", output]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {output}")
    assert ("does not exist" in err) or ("already exists" in err)
    assert not (tmp_path / "missing").exists()  # -o no longer creates directories


def test_unwritable_output_directory_fails_before_the_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    target = Path("/proc/oxyline-test/out.nc") if Path("/proc/self").exists() else None
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        probe = ro / "probe"
        try:  # root writes into a read-only-mode directory: use /proc (no file can be made)
            probe.touch()
            probe.unlink()
        except OSError:
            target = ro / "out.nc"
        if target is None:
            pytest.skip("no unwritable directory on this machine")
        monkeypatch.setattr(oxyline, "simulate", _never_run)
        if target.parent.exists():
            assert main(["run", "bifurcation", "--quiet", "-o", str(target)]) == 2
            assert "cannot write into" in capsys.readouterr().err
        else:  # /proc/oxyline-test does not exist either
            assert main(["run", "bifurcation", "--quiet", "-o", str(target)]) == 2
            assert "does not exist" in capsys.readouterr().err
            assert main(["run", "bifurcation", "--quiet", "-o", "/proc/out.nc"]) == 2
            assert "cannot write into '/proc'" in capsys.readouterr().err
    finally:
        ro.chmod(0o700)
