"""Result files: NetCDF and Zarr (via xarray), read back by
:func:`oxyline.io.result_reader.open_result`, and per-vessel summary tables (CSV/Parquet).

The methods :meth:`oxyline.Result.to_netcdf`, :meth:`~oxyline.Result.to_zarr`,
:meth:`~oxyline.Result.summary`, :meth:`~oxyline.Result.to_csv` and
:meth:`~oxyline.Result.to_parquet` call these functions.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

from oxyline.errors import OutputError
from oxyline.io._common import PathLike
from oxyline.io.atomic import deferred_signals, replace_atomically

if TYPE_CHECKING:
    from oxyline.result import Result

STATS = ("mean", "min", "max")


def dataset(result: Result, *, coordinates: bool = True) -> Any:
    """``result.to_xarray()`` with file-level attributes (conventions, units system, creator);
    ``coordinates=False``: without the vessel and segment coordinates (for its attributes)."""
    ds = result.to_xarray(coordinates=coordinates)
    ds.attrs.setdefault("title", f"oxyline results for model '{result.model_name}'")
    ds.attrs["units_system"] = "SI (each variable's units in its 'units' attribute)"
    ds.attrs["source"] = "oxyline"
    if result.step_sizes.size:
        ds = with_step_history(ds, result.step_times, result.step_sizes)
    if result.time_error is not None:  # the accumulated error of every vessel, per kind
        from oxyline.time_error import table_variables

        ds = ds.assign(table_variables(result.time_error, result.vessels))
    for name in ds.variables:
        if ds[name].dtype == object:  # vessel names: plain strings for netCDF/zarr readers
            ds[name] = ds[name].astype(str)
    return ds


def step_history(step_sizes: Any) -> tuple[Any, Any]:
    """(start times into the cycle, sizes) of an error-controlled run's accepted steps."""
    import numpy as np

    sizes = np.asarray(step_sizes, dtype=float)
    return np.concatenate(([0.0], np.cumsum(sizes)[:-1])), sizes


def with_step_history(ds: Any, step_times: Any, step_sizes: Any) -> Any:
    """``ds`` with the last cycle's step-size history of an error-controlled run: the
    variable ``step_size`` over its own dimension ``step_time`` (not the output's times)."""
    ds = ds.assign_coords(step_time=("step_time", step_times, {"units": "s"}))
    ds["step_size"] = (("step_time",), step_sizes, {
        "units": "s", "description": "accepted steps of the last cycle (error control), "
        "at their start time into that cycle"})
    return ds


# NetCDF files up to this size are encoded in memory and written with one plain file write:
# h5py crashes the process (SIGSEGV) when the disk fills during its own writes, a plain write
# raises OSError. Larger files are written by h5py directly after a free-space check.
NETCDF_IN_MEMORY_BYTES = 512 << 20


def check_free_space(p: Path, need: int, result: Any = None) -> None:
    """Refuse to start writing ``need`` bytes into ``p``'s directory when it has less free."""
    free = shutil.disk_usage(p.parent).free
    if free < need + (16 << 20):
        raise OutputError(f"{p}: needs about {need / 2**20:.0f} MiB but its file system has "
                          f"{free / 2**20:.0f} MiB free; nothing was written", result)


class _Buffer(io.BytesIO):
    """An in-memory file that stays readable after xarray closes it."""

    def close(self) -> None:
        pass


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _encode_in_memory(ds: Any) -> memoryview | None:
    buf = _Buffer()
    ds.to_netcdf(buf, engine="h5netcdf", format="NETCDF4")  # never netCDF-3 via scipy
    data = buf.getbuffer()
    return data if bytes(data[:8]) == HDF5_SIGNATURE else None


@functools.cache
def netcdf4_in_memory() -> bool:
    """Whether the installed xarray encodes NetCDF-4 into a file object (older releases fall
    back to netCDF-3 through scipy there); probed once on a tiny numeric dataset."""
    import xarray as xr

    try:
        return _encode_in_memory(xr.Dataset({"probe": ("n", [0.0])})) is not None
    except Exception:  # noqa: BLE001 - no scipy, or a writer refusing file objects: not supported
        return False


def to_netcdf(result: Result, path: PathLike) -> Path:
    """Write NetCDF-4 (h5netcdf engine): dims ``time``, ``vessel``, ``segment``; coordinates
    vessel names and segment positions; attrs with units, model name, solver settings and the
    oxyline version. Opens with ``xarray.open_dataset``, MATLAB ``ncread`` and ParaView.

    The file is written under a temporary name beside ``path`` and renamed when complete, so
    ``path`` is either the whole new file or left as it was. A failed write (disk full, no
    permission) raises :class:`oxyline.OutputError` naming the file, with the result attached
    (``exc.result``)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    ds = dataset(result)

    def write(tmp: Path) -> None:
        # encoded in memory (h5py cannot fail half-way through a full disk there) where the
        # installed xarray can, else written directly after a free-space check
        small = ds.nbytes <= NETCDF_IN_MEMORY_BYTES and netcdf4_in_memory()
        data = _encode_in_memory(ds) if small else None
        if data is not None:
            with open(tmp, "wb") as fh:
                fh.write(data)
        else:
            check_free_space(p, int(ds.nbytes), result)
            ds.to_netcdf(tmp, engine="h5netcdf")

    try:
        replace_atomically(p, write)
    except OutputError:
        raise
    except (OSError, RuntimeError) as exc:
        raise OutputError(f"{p}: cannot write the NetCDF file: {_why(exc)}; nothing was written "
                          "(the result is still in memory: exc.result)", result) from exc
    return p


def _zarr() -> Any:
    try:
        import zarr
    except ImportError:
        raise ImportError("writing Zarr needs the zarr package: pip install 'oxyline[zarr]'") \
            from None
    return zarr


def _format2(zarr: Any) -> dict[str, Any]:
    """``to_zarr``'s option for a Zarr format 2 store: fixed-width strings have no Zarr v3
    spec yet, and v2 reads anywhere."""
    return {"zarr_format": 2} if int(zarr.__version__.split(".")[0]) >= 3 else {}


@contextlib.contextmanager
def _quiet() -> Any:
    """zarr's warnings silenced (consolidated metadata is not part of the v2 spec)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


#: the dims a store may chunk besides ``time`` (``space_chunk`` entries per chunk)
SPACE_DIMS = ("vessel", "segment")


def _write_zarr(ds: Any, path: Path, time_chunk: int, space_chunk: int | None = None) -> None:
    """Write ``ds`` as a new Zarr store with ``time_chunk`` rows per chunk along ``time`` and,
    with ``space_chunk``, that many vessels or segments per chunk along ``vessel``/``segment``
    (so reading one region's segments reads only the chunks that hold them)."""
    zarr = _zarr()
    encoding = {}
    for name, var in ds.variables.items():
        if "time" in var.dims or (space_chunk and set(var.dims) & set(SPACE_DIMS)):
            encoding[name] = {"chunks": tuple(max(1, _chunk(d, n, time_chunk, space_chunk))
                                              for d, n in zip(var.dims, var.shape))}
    path.parent.mkdir(parents=True, exist_ok=True)
    with _quiet():
        ds.to_zarr(path, mode="w", encoding=encoding, **_format2(zarr))


def _chunk(dim: str, n: int, time_chunk: int, space_chunk: int | None) -> int:
    if dim == "time":
        return time_chunk
    return min(n, space_chunk) if space_chunk and dim in SPACE_DIMS else n


def _why(exc: BaseException) -> str:
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc) or repr(exc)


def _refuse_existing(p: Path, overwrite: bool) -> None:
    if p.exists() and not overwrite:
        raise OutputError(f"{p}: already exists; pass overwrite=True (CLI: --overwrite) to "
                          "replace it")


def to_zarr(result: Result, path: PathLike, time_chunk: int = 1024,
            overwrite: bool = False) -> Path:
    """Write a Zarr store (format 2), chunked along ``time`` (``time_chunk`` rows per chunk).

    This writes a finished in-memory result. To write the store *during* the run, with memory
    bounded by one chunk however long the output, use :func:`oxyline.simulate_to_zarr` (the
    CLI's ``-o out.zarr`` does). Needs ``zarr`` (``pip install 'oxyline[zarr]'``).

    The store is written under a temporary name and renamed when complete: an existing store at
    ``path`` is replaced only with ``overwrite=True`` and only once the new one is whole. A
    failed write raises :class:`oxyline.OutputError` with the result attached.
    """
    p = Path(path)
    _refuse_existing(p, overwrite)
    chunk = min(time_chunk, max(1, len(result.time)))
    try:
        # an existing store (overwrite) goes only once the new one is complete
        replace_atomically(p, lambda tmp: _write_zarr(dataset(result), tmp, chunk), sync=False)
    except (OSError, RuntimeError, ValueError) as exc:
        raise OutputError(f"{p}: cannot write the Zarr store: {_why(exc)}; nothing was written "
                          "(the result is still in memory: exc.result)", result) from exc
    return p


class _StoreLock:
    """An exclusive lock on a store path for the life of one writer (``.<name>.lock`` beside
    it, ``flock``): a second process writing the same store is refused instead of both ending
    with a broken one. Where ``fcntl`` is missing (Windows) there is no lock."""

    def __init__(self, path: Path) -> None:
        self.file = path.with_name(f".{path.name}.lock")
        self.fd: int | None = None
        try:
            import fcntl
        except ImportError:
            return
        while self.fd is None:
            try:
                fd = os.open(self.file, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise OutputError(f"{path}: cannot create the store's lock file "
                                  f"{self.file.name}: {_why(exc)}") from exc
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                raise OutputError(f"{path}: another process is writing this store (lock "
                                  f"{self.file.name}); nothing was written") from None
            try:  # the holder before us may have removed the file between open and flock
                same = os.fstat(fd).st_ino == os.stat(self.file).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self.fd = fd
            else:
                os.close(fd)

    def release(self) -> None:
        if self.fd is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.file)
            os.close(self.fd)
            self.fd = None


class ZarrAppender:
    """A Zarr store created from a zero-row template dataset (the variables, coordinates and
    attributes of :func:`dataset`) and grown along ``time`` chunk by chunk. Its arrays are
    chunked by ``time_chunk`` rows and, with ``space_chunk``, by that many vessels or segments.

    The store is created under a temporary name and renamed into place. The consolidated
    metadata that ``xarray.open_zarr`` reads is the store's commit record: it is rewritten
    (atomically) only after every variable of a chunk has been appended, and SIGINT/SIGTERM
    are deferred while a chunk is appended, so an interrupted or killed run leaves a store
    that opens with whole rows. A chunk that cannot be written (disk full) is rolled back, so
    the store keeps exactly the rows of the chunks before it, and :class:`oxyline.OutputError`
    says so. One process at a time writes a store (a second one is refused).
    """

    def __init__(self, path: PathLike, template: Any, time_chunk: int,
                 overwrite: bool = False, space_chunk: int | None = None) -> None:
        self.path = Path(path)
        self.rows = 0
        self._zarr = _zarr()
        self._lock = _StoreLock(self.path)
        try:
            _refuse_existing(self.path, overwrite)
            replace_atomically(self.path, lambda tmp: _write_zarr(template, tmp, time_chunk,
                                                                 space_chunk),
                               sync=False)
            # the metadata of every array as stored, not the consolidated copy (stale once grown)
            self._group = self._zarr.open_group(self.path, mode="r+", zarr_format=2,
                                                use_consolidated=False)
        except OutputError:
            self._lock.release()
            raise
        except (OSError, RuntimeError, ValueError) as exc:
            self._lock.release()
            raise OutputError(f"{self.path}: cannot create the Zarr store: {_why(exc)}") from exc
        self._timed = [n for n, v in template.variables.items() if "time" in v.dims]

    def append(self, ds: Any) -> None:
        """Append the rows of ``ds`` (a dataset with the template's variables) along time:
        every variable, then the consolidated metadata, with signals deferred."""
        n = int(ds.sizes["time"])
        with deferred_signals():
            try:
                for name in self._timed:
                    self._group[name].append(ds[name].values, axis=0)
                self._consolidate()
            except Exception as exc:
                self._roll_back()
                raise OutputError(
                    f"{self.path}: writing output rows {self.rows}-{self.rows + n - 1} failed: "
                    f"{_why(exc)}; the store keeps the {self.rows} rows written before "
                    "(readable with oxyline.open_result)") from exc
            self.rows += n

    def _roll_back(self) -> None:
        """Cut every time-dependent array back to the rows written before a failed chunk (each
        array's metadata is a small file; if even that cannot be written, the consolidated
        metadata of the last good chunk still describes the store)."""
        with contextlib.suppress(OSError, RuntimeError, ValueError):  # a failing disk
            for name in self._timed:
                arr = self._group[name]
                if arr.shape[0] != self.rows:
                    arr.resize((self.rows, *arr.shape[1:]))
            self._consolidate()

    def finish(self, attrs: dict[str, Any], step_sizes: Any = None, *,
               release: bool = True, variables: Any = None) -> None:
        """Replace the store's attributes (e.g. with the run's facts once it has ended), add
        an error-controlled run's step-size history (``step_sizes``, the last cycle's accepted
        steps: the variables :func:`dataset` writes), and let other writers have the store
        (``release=False``: not yet, :meth:`release` does; e.g. until this writer has read
        the store back, which a writer starting now would otherwise overwrite first).
        ``variables``: data variables known only after the run (e.g. the per-vessel
        accumulated-error table over ``vessel``), added as they are."""
        try:
            with deferred_signals():
                if step_sizes is not None and len(step_sizes):
                    self._write_step_history(step_sizes)
                if variables:
                    self._write_variables(variables)
                self._group.attrs.put(dict(attrs))
                self._consolidate()
        finally:
            if release:
                self._lock.release()

    def release(self) -> None:
        """Let other writers have the store (after ``finish(..., release=False)``)."""
        self._lock.release()

    def _write_step_history(self, step_sizes: Any) -> None:
        import xarray as xr

        history = with_step_history(xr.Dataset(), *step_history(step_sizes))
        with _quiet():
            # the group's attributes are put right after (finish), whatever this leaves there
            history.to_zarr(self.path, mode="a", consolidated=False, **_format2(self._zarr))

    def _write_variables(self, variables: Any) -> None:
        import xarray as xr

        with _quiet():
            xr.Dataset(dict(variables)).to_zarr(self.path, mode="a", consolidated=False,
                                                **_format2(self._zarr))

    def remove(self) -> None:
        with deferred_signals():
            shutil.rmtree(self.path, ignore_errors=True)
            self._lock.release()

    def _consolidate(self) -> None:
        with _quiet():
            self._zarr.consolidate_metadata(self.path, zarr_format=2)


def stats(a: Any, t: Any) -> tuple[Any, Any, Any]:
    """Mean, min and max over time (axis 0) of ``a`` sampled at times ``t``; the mean is the
    time average (trapezoidal rule), the plain mean for a single time."""
    import numpy as np

    if len(t) > 1 and t[-1] > t[0]:
        mean = np.trapezoid(a, t, axis=0) / (t[-1] - t[0])
    else:
        mean = a.mean(axis=0)
    return mean, a.min(axis=0), a.max(axis=0)


def summary(result: Result | Any) -> Any:
    """pandas DataFrame, one row per vessel (index ``vessel``), columns ``<variable>_<stat>``
    for every per-vessel variable (dims time × vessel) and stat in mean, min, max. Means are
    time averages over the output (trapezoidal rule; equal to the cycle mean for one periodic
    cycle). SI units, listed per column in ``df.attrs["units"]``. ``result`` may also be the
    dataset of a result (e.g. a store opened with ``xarray.open_zarr``): variables are read
    one at a time. A large model's default result (:mod:`oxyline.large_output`) gives the
    table of every vessel reduced during its run (a copy)."""
    import numpy as np
    import pandas as pd

    kept = getattr(result, "vessel_summary", None)
    if kept is not None:  # a large model's run: reduced while it ran (oxyline.large_output)
        return kept.copy()
    ds = result.to_xarray() if hasattr(result, "to_xarray") else result
    t = np.asarray(ds["time"].values, dtype=float)
    cols: dict[str, Any] = {}
    units: dict[str, str] = {}
    for name, var in ds.data_vars.items():
        if var.dims != ("time", "vessel"):
            continue
        for stat, val in zip(STATS, stats(np.asarray(var.values, dtype=float), t)):
            cols[f"{name}_{stat}"] = val
            units[f"{name}_{stat}"] = str(var.attrs.get("units", ""))
    df = pd.DataFrame(cols, index=pd.Index([str(v) for v in ds["vessel"].values], name="vessel"))
    df.attrs["units"] = units
    df.attrs["model"] = ds.attrs["model"]
    return df


def to_csv(result: Result | Any, path: PathLike) -> Path:
    """Write :func:`summary` (of a result or its dataset) as CSV (TSV for ``.tsv``), each
    column name with its unit (``pressure_in_mean [Pa]``): one header row, no comment line, so
    ``pandas.read_csv(path, index_col="vessel")`` reads it as it is."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    df = summary(result)
    units = df.attrs["units"]
    df = df.rename(columns={c: f"{c} [{units[c]}]" for c in df.columns if units.get(c)})
    sep = "\t" if p.suffix.lower() == ".tsv" else ","
    replace_atomically(p, lambda tmp: df.to_csv(tmp, sep=sep))  # a whole table or none
    return p


def to_parquet(result: Result | Any, path: PathLike) -> Path:
    """Write :func:`summary` as Parquet (needs pyarrow); units in the file's key-value metadata
    (``df.attrs``, restored by ``pandas.read_parquet``)."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise ImportError("writing Parquet needs pyarrow: pip install pyarrow") from None
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    summary(result).to_parquet(p)
    return p
