"""Result files: NetCDF and Zarr (via xarray), read back with :func:`open_result`, and
per-vessel summary tables (CSV/Parquet).

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

if TYPE_CHECKING:
    from oxyline.result import Result

STATS = ("mean", "min", "max")


def dataset(result: Result) -> Any:
    """``result.to_xarray()`` with file-level attributes (conventions, units system, creator)."""
    ds = result.to_xarray()
    ds.attrs.setdefault("title", f"oxyline results for model '{result.model_name}'")
    ds.attrs["units_system"] = "SI (each variable's units in its 'units' attribute)"
    ds.attrs["source"] = "oxyline"
    for name in ds.variables:
        if ds[name].dtype == object:  # vessel names: plain strings for netCDF/zarr readers
            ds[name] = ds[name].astype(str)
    return ds


# NetCDF files up to this size are encoded in memory and written with one plain file write:
# h5py crashes the process (SIGSEGV) when the disk fills during its own writes, a plain write
# raises OSError. Larger files are written by h5py directly after a free-space check.
NETCDF_IN_MEMORY_BYTES = 512 << 20


def _tmp_sibling(p: Path) -> Path:
    """A temporary name beside ``p`` (same file system, so that the final rename is atomic)."""
    return p.with_name(f".{p.name}.{os.getpid()}.partial")


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


def _netcdf4_bytes(ds: Any) -> memoryview | None:
    """``ds`` encoded as NetCDF-4 in memory (h5py cannot fail half-way through a full disk
    there), or None where the installed xarray cannot do that: the caller then writes the
    file directly, after a free-space check."""
    return _encode_in_memory(ds) if netcdf4_in_memory() else None


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
    tmp = _tmp_sibling(p)
    try:
        data = _netcdf4_bytes(ds) if ds.nbytes <= NETCDF_IN_MEMORY_BYTES else None
        if data is not None:
            with open(tmp, "wb") as fh:
                fh.write(data)
        else:
            check_free_space(p, int(ds.nbytes), result)
            ds.to_netcdf(tmp, engine="h5netcdf")
        os.replace(tmp, p)
    except OutputError:
        raise
    except (OSError, RuntimeError) as exc:
        tmp.unlink(missing_ok=True)
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise OutputError(f"{p}: cannot write the NetCDF file: {why}; nothing was written (the "
                          "result is still in memory: exc.result)", result) from exc
    return p


def _zarr() -> Any:
    try:
        import zarr
    except ImportError:
        raise ImportError("writing Zarr needs the zarr package: pip install 'oxyline[zarr]'") \
            from None
    return zarr


def _write_zarr(ds: Any, path: Path, time_chunk: int) -> None:
    """Write ``ds`` as a new Zarr store with ``time_chunk`` rows per chunk along ``time``."""
    zarr = _zarr()
    encoding = {}
    for name, var in ds.variables.items():
        if "time" in var.dims:
            encoding[name] = {"chunks": tuple(max(1, time_chunk if d == "time" else n)
                                              for d, n in zip(var.dims, var.shape))}
    import warnings

    kwargs: dict[str, Any] = {}
    if int(zarr.__version__.split(".")[0]) >= 3:
        kwargs["zarr_format"] = 2  # fixed-width strings have no Zarr v3 spec yet; v2 reads anywhere
    path.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds.to_zarr(path, mode="w", encoding=encoding, **kwargs)


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
    tmp = _tmp_sibling(p)
    try:
        _write_zarr(dataset(result), tmp, min(time_chunk, max(1, len(result.time))))
        if p.exists():  # overwrite: the old store goes only once the new one is complete
            old = p.with_name(f".{p.name}.{os.getpid()}.old")
            os.replace(p, old)
            os.replace(tmp, p)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, p)
    except (OSError, RuntimeError, ValueError) as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"{p}: cannot write the Zarr store: {_why(exc)}; nothing was written "
                          "(the result is still in memory: exc.result)", result) from exc
    return p


class ZarrAppender:
    """A Zarr store created from a zero-row template dataset (the variables, coordinates and
    attributes of :func:`dataset`) and grown along ``time`` chunk by chunk.

    The consolidated metadata that ``xarray.open_zarr`` reads is rewritten after every chunk,
    so the store stays valid if the process dies mid-run. A chunk that cannot be written
    (disk full) is rolled back, so the store keeps exactly the rows of the chunks before it,
    and :class:`oxyline.OutputError` says so.
    """

    def __init__(self, path: PathLike, template: Any, time_chunk: int,
                 overwrite: bool = False) -> None:
        self.path = Path(path)
        self.rows = 0
        self._zarr = _zarr()
        _refuse_existing(self.path, overwrite)
        try:
            _write_zarr(template, self.path, time_chunk)
            # the metadata of every array as stored, not the consolidated copy (stale once grown)
            self._group = self._zarr.open_group(self.path, mode="r+", zarr_format=2,
                                                use_consolidated=False)
        except (OSError, RuntimeError, ValueError) as exc:
            self.remove()
            raise OutputError(f"{self.path}: cannot create the Zarr store: {_why(exc)}") from exc
        self._timed = [n for n, v in template.variables.items() if "time" in v.dims]

    def append(self, ds: Any) -> None:
        """Append the rows of ``ds`` (a dataset with the template's variables) along time."""
        n = int(ds.sizes["time"])
        try:
            for name in self._timed:
                self._group[name].append(ds[name].values, axis=0)
            self._consolidate()
        except Exception as exc:
            self._roll_back()
            raise OutputError(
                f"{self.path}: writing output rows {self.rows}-{self.rows + n - 1} failed: "
                f"{_why(exc)}; the store keeps the {self.rows} rows written before (readable "
                "with oxyline.open_result)") from exc
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

    def finish(self, attrs: dict[str, Any]) -> None:
        """Replace the store's attributes (e.g. with the run's facts once it has ended)."""
        self._group.attrs.put(dict(attrs))
        self._consolidate()

    def remove(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)

    def _consolidate(self) -> None:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # consolidated metadata is not part of the v2 spec
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
    one at a time."""
    import numpy as np
    import pandas as pd

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
    df.to_csv(p, sep="\t" if p.suffix.lower() == ".tsv" else ",")
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


# ---------------------------------------------------------------------------------------------
# reading a result back: the inverse of Result.to_xarray (and of the files written from it)

#: what every oxyline result holds; anything less is not an oxyline result file
REQUIRED = ("time", "vessel")


def _plain(value: Any) -> Any:
    """A file attribute as a Python scalar (netCDF gives numpy scalars, Zarr plain JSON)."""
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    return value


def _names(value: Any) -> list[str]:
    """A list-of-names attribute: netCDF stores a one-element list as a plain string."""
    value = _plain(value)
    return [value] if isinstance(value, str) else [str(v) for v in value]


def _source(source: Any) -> tuple[Any, str, bool]:
    """(dataset, label for messages, whether we opened it and must close it)."""
    import os

    if not isinstance(source, (str, os.PathLike)):
        if not hasattr(source, "data_vars"):
            raise TypeError("open_result: expected a path to a .nc/.zarr file or an "
                            f"xarray.Dataset, got {type(source).__name__}")
        return source, "dataset", False
    import warnings

    import xarray as xr

    p = Path(source)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or directory")
    if p.suffix.lower() == ".zarr" or (p.is_dir() and (p / ".zgroup").exists()):
        _zarr()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # consolidated metadata is not part of the v2 spec
            return xr.open_zarr(p), str(p), True
    try:
        return xr.open_dataset(p), str(p), True
    except (OSError, ValueError) as exc:
        raise ValueError(f"{p}: cannot read as NetCDF or Zarr ({exc})") from None


def open_result(source: PathLike | Any) -> Result:
    """Rebuild a :class:`~oxyline.Result` from a NetCDF file, a Zarr store (also one written
    during the run by :func:`oxyline.simulate_to_zarr`, finished or interrupted) or the
    ``xarray.Dataset`` of :meth:`Result.to_xarray`.

    The inverse of :meth:`Result.to_xarray`: the pressure/flow arrays, segment data, species
    and oxygen outputs, model name, solver settings and ``complete`` flag come back as written,
    so ``open_result(res.to_xarray())`` has arrays identical to ``res`` (bit for bit) and works
    with :mod:`oxyline.plot`, :meth:`~Result.summary` and the writers. Derived variables (PO2,
    mass balance residuals, TL elements) are recomputed from the underlying arrays and equal
    the stored ones. What a file does not hold stays absent: settings that were ``None``, the
    species' per-segment arrays of a run without segment output, and the absolute stored
    amount at t = 0 (the file has the change since then: ``SpeciesResult.initial_stored`` is
    0 and ``balance_data``'s stored column is that change, so ``mass_balance`` is unchanged).
    The arrays are read into memory (a Result holds them all).

    Raises ``ValueError`` naming the missing variable when ``source`` is not an oxyline result.

    >>> import oxyline
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> back = oxyline.open_result(res.to_xarray())
    >>> bool((back.pressure_in == res.pressure_in).all()), back.model_name
    (True, 'bifurcation')
    """
    ds, label, opened = _source(source)
    try:
        return _result_from_dataset(ds, label)
    finally:
        if opened:
            ds.close()


def _result_from_dataset(ds: Any, label: str) -> Result:
    import numpy as np

    from oxyline.result import SEGMENT_VARIABLES, VESSEL_VARIABLES, Result

    def need(name: str, dims: tuple[str, ...] | None = None) -> Any:
        if name not in ds.variables:
            raise ValueError(f"{label} is not an oxyline result: no variable '{name}' "
                             "(oxyline.open_result reads files written by Result.to_netcdf, "
                             "Result.to_zarr or oxyline.simulate_to_zarr)")
        var = ds[name]
        if dims is not None and var.dims != dims:
            raise ValueError(f"{label}: variable '{name}' has dims {var.dims}, expected {dims}")
        return np.asarray(var.values)

    for name in REQUIRED:
        need(name)
    time = need("time").astype(np.float64)
    vessels = [str(v) for v in need("vessel")]
    nt, nv = len(time), len(vessels)
    seg = "segment_vessel" in ds.variables
    segment_count: list[int] = []
    positions = np.zeros(0, dtype=np.float64)
    ns = 0
    if seg:
        seg_vessel = [str(v) for v in need("segment_vessel")]
        index = {n: i for i, n in enumerate(vessels)}
        try:
            owner = np.array([index[n] for n in seg_vessel], dtype=np.int64)
        except KeyError as exc:
            raise ValueError(f"{label}: segment of unknown vessel {exc.args[0]!r}") from None
        # the core numbers segments vessel by vessel; anything else has no Result layout
        if np.any(np.diff(owner) < 0):
            raise ValueError(f"{label}: segments are not grouped by vessel in vessel order")
        segment_count = np.bincount(owner, minlength=nv).tolist()
        positions = need("segment_position").astype(np.float64)
        ns = len(seg_vessel)

    # the core's (time, column) layout: the vessel variables of each vessel, then the segment
    # variables of each segment, interleaved; an output selection wrote fewer of them
    # the flow variables written: all of them, unless the file records an output selection
    selected = _names(ds.attrs["output_variables"]) if "output_variables" in ds.attrs else None
    vvars = tuple(v for v in VESSEL_VARIABLES if selected is None or v in selected)
    # a file without segments: empty segment arrays of every variable (as it was written)
    svars = tuple(v for v in SEGMENT_VARIABLES if selected is None or v in selected) \
        if seg else SEGMENT_VARIABLES
    kv, ks = len(vvars), len(svars)
    data = np.empty((nt, kv * nv + ks * ns), dtype=np.float64)
    for k, name in enumerate(vvars):
        data[:, k:kv * nv:kv] = need(name, ("time", "vessel"))
    for k, name in enumerate(svars if seg else ()):
        data[:, kv * nv + k::ks] = need(name, ("time", "segment"))

    attrs = {k: _plain(v) for k, v in ds.attrs.items()}
    species = _species_from_dataset(ds, attrs, need, nt, nv, ns, label)
    oxygen = attrs.get("oxygen_species")
    if oxygen is None and "po2_in" in ds.variables:  # written before the attribute existed
        oxygen = next(iter(species), None)
    if oxygen is not None and oxygen in species:
        scale = ds["po2_in"].attrs.get("po2_per_concentration") if "po2_in" in ds.variables \
            else None
        if scale is None and "po2_in" in ds.variables:
            # older files: recover the factor from the two stored arrays (to rounding)
            c, p = species[oxygen].concentration_in, need("po2_in")
            ok = np.isfinite(c) & np.isfinite(p) & (c != 0)
            scale = float(np.median(p[ok] / c[ok])) if ok.any() else None
        species[oxygen].po2_per_concentration = None if scale is None else float(_plain(scale))
    settings = {k[len("solver_"):]: v for k, v in attrs.items() if k.startswith("solver_")}
    result = Result(model_name=str(attrs.get("model", Path(label).stem)), vessels=vessels,
                    time=time, data=data, segment_count=segment_count,
                    segment_position=positions, settings=settings,
                    complete=bool(attrs.get("complete", 1)), species=species,
                    oxygen=None if oxygen is None else str(oxygen), vessel_variables=vvars,
                    segment_variables=svars,
                    model_json=str(attrs["model_json"]) if "model_json" in attrs else None)
    # the heart outputs (Result.chamber_volume, Result.valve_status), if the model had them
    for var, dim, field in (("chamber_volume", "chamber", result.chamber_volume),
                            ("valve_status", "valve", result.valve_status)):
        if var in ds.variables:
            values = need(var, ("time", dim))
            field.update({str(n): values[:, k].copy() for k, n in enumerate(need(dim))})
    return result


def _species_from_dataset(ds: Any, attrs: dict[str, Any], need: Any, nt: int, nv: int,
                          ns: int, label: str) -> dict[str, Any]:
    """The :class:`~oxyline.result.SpeciesResult` of every species in ``ds``, in run order."""
    import numpy as np

    from oxyline.result import BALANCE, SPECIES_SEGMENT, SPECIES_VESSEL, SpeciesResult

    suffix = "_concentration_in"
    if "species" in attrs:
        names = _names(attrs["species"])
    else:  # files written before the attribute existed: the order the variables are listed in
        names = [str(n)[:-len(suffix)] for n in ds.data_vars if str(n).endswith(suffix)]

    def vessel_file(name: str, v: str) -> str:
        return f"wall_{name}_flux" if v == "wall_flux" else f"{name}_{v}"

    def segment_file(name: str, v: str) -> str:
        if v in ("tl_resistance", "tl_inductance"):  # flow-only: stored once for all species
            return v
        return f"segment_wall_{name}_flux" if v == "wall_flux" else f"segment_{name}_{v}"

    first = names[0] if names else ""
    # the variables an output selection kept (all of them by default), the same for every
    # species
    vvars = tuple(v for v in SPECIES_VESSEL if vessel_file(first, v) in ds.variables)
    svars = tuple(v for v in SPECIES_SEGMENT if segment_file(first, v) in ds.variables) \
        if ns > 0 else SPECIES_SEGMENT
    out: dict[str, Any] = {}
    for name in names:
        vessel = np.empty((nt, nv, len(vvars)), dtype=np.float64)
        for k, v in enumerate(vvars):
            vessel[:, :, k] = need(vessel_file(name, v), ("time", "vessel"))
        has_seg = ns > 0 and segment_file(name, svars[0]) in ds.variables if svars else False
        segment = np.empty((nt, ns if has_seg else 0, len(svars)), dtype=np.float64)
        for k, v in enumerate(svars if has_seg else ()):
            segment[:, :, k] = need(segment_file(name, v), ("time", "segment"))
        balance = np.empty((nt, len(BALANCE)), dtype=np.float64)
        for k, v in enumerate(BALANCE):
            # stored is written as the change since t = 0: with initial_stored = 0 the
            # recomputed mass balance equals the file's bit for bit
            balance[:, k] = need(f"{name}_mass_{v}", ("time",))
        out[name] = SpeciesResult(name=name, vessel_data=vessel, segment_data=segment,
                                  balance_data=balance, initial_stored=0.0,
                                  vessel_variables=vvars, segment_variables=svars,
                                  tissue=_tissue_from_dataset(ds, name, need, nt, nv, ns,
                                                              has_seg))
    return out


def _tissue_from_dataset(ds: Any, name: str, need: Any, nt: int, nv: int, ns: int,
                         has_seg: bool) -> Any:
    """The tissue-wall result of species ``name`` written by ``Result.to_xarray`` (None
    without one). Its segment block needs the file's segments; the balance is stored as
    changes since the first row, which ``TissueResult.mass_balance`` reproduces."""
    import numpy as np

    from oxyline.result import TISSUE_BALANCE, TISSUE_SEGMENT, TISSUE_VESSEL, TissueResult

    if f"{name}_wall_concentration_inner" not in ds.variables:
        return None
    vessel = np.stack([need(f"{name}_{k}", ("time", "vessel")) for k in TISSUE_VESSEL], axis=-1)
    seg_names = [f"segment_{name}_{k.removeprefix('segment_')}" for k in TISSUE_SEGMENT]
    seg_ok = has_seg and all(k in ds.variables for k in seg_names)
    segment = (np.stack([need(k, ("time", "segment")) for k in seg_names], axis=-1) if seg_ok
               else np.empty((nt, 0, len(TISSUE_SEGMENT))))
    balance = np.stack([need(f"{name}_wall_mass_{k.removeprefix('wall_')}", ("time",))
                        for k in TISSUE_BALANCE], axis=-1)
    vessels = [str(v) for v in ds["vessel"].values]
    counts = [int(c) for c in np.bincount(
        [vessels.index(str(v)) for v in ds["segment_vessel"].values], minlength=nv)] \
        if seg_ok else [0] * nv
    return TissueResult(vessels=vessels, segment_count=counts, vessel_data=vessel,
                        segment_data=segment, balance_data=balance)
