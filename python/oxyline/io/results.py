"""Result files: NetCDF and Zarr (via xarray), and per-vessel summary tables (CSV/Parquet).

The methods :meth:`oxyline.Result.to_netcdf`, :meth:`~oxyline.Result.to_zarr`,
:meth:`~oxyline.Result.summary`, :meth:`~oxyline.Result.to_csv` and
:meth:`~oxyline.Result.to_parquet` call these functions.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

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


def to_netcdf(result: Result, path: PathLike) -> Path:
    """Write NetCDF-4 (h5netcdf engine): dims ``time``, ``vessel``, ``segment``; coordinates
    vessel names and segment positions; attrs with units, model name, solver settings and the
    oxyline version. Opens with ``xarray.open_dataset``, MATLAB ``ncread`` and ParaView."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    dataset(result).to_netcdf(p, engine="h5netcdf")
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


def to_zarr(result: Result, path: PathLike, time_chunk: int = 1024) -> Path:
    """Write a Zarr store (format 2), chunked along ``time`` (``time_chunk`` rows per chunk).

    This writes a finished in-memory result. To write the store *during* the run, with memory
    bounded by one chunk however long the output, use :func:`oxyline.simulate_to_zarr` (the
    CLI's ``-o out.zarr`` does). Needs ``zarr`` (``pip install 'oxyline[zarr]'``).
    """
    p = Path(path)
    _write_zarr(dataset(result), p, min(time_chunk, max(1, len(result.time))))
    return p


class ZarrAppender:
    """A Zarr store created from a zero-row template dataset (the variables, coordinates and
    attributes of :func:`dataset`) and grown along ``time`` chunk by chunk.

    The consolidated metadata that ``xarray.open_zarr`` reads is rewritten after every chunk,
    so the store stays valid if the process dies mid-run.
    """

    def __init__(self, path: PathLike, template: Any, time_chunk: int) -> None:
        self.path = Path(path)
        self._zarr = _zarr()
        _write_zarr(template, self.path, time_chunk)
        # the metadata of every array as stored, not the consolidated copy (stale once grown)
        self._group = self._zarr.open_group(self.path, mode="r+", zarr_format=2,
                                            use_consolidated=False)
        self._timed = [n for n, v in template.variables.items() if "time" in v.dims]

    def append(self, ds: Any) -> None:
        """Append the rows of ``ds`` (a dataset with the template's variables) along time."""
        for name in self._timed:
            self._group[name].append(ds[name].values, axis=0)
        self._consolidate()

    def finish(self, attrs: dict[str, Any]) -> None:
        """Replace the store's attributes (e.g. with the run's facts once it has ended)."""
        self._group.attrs.put(dict(attrs))
        self._consolidate()

    def remove(self) -> None:
        import shutil

        shutil.rmtree(self.path, ignore_errors=True)

    def _consolidate(self) -> None:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # consolidated metadata is not part of the v2 spec
            self._zarr.consolidate_metadata(self.path, zarr_format=2)


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
        a = np.asarray(var.values, dtype=float)
        if len(t) > 1 and t[-1] > t[0]:
            mean = np.trapezoid(a, t, axis=0) / (t[-1] - t[0])
        else:
            mean = a.mean(axis=0)
        for stat, val in (("mean", mean), ("min", a.min(axis=0)), ("max", a.max(axis=0))):
            cols[f"{name}_{stat}"] = val
            units[f"{name}_{stat}"] = str(var.attrs.get("units", ""))
    df = pd.DataFrame(cols, index=pd.Index([str(v) for v in ds["vessel"].values], name="vessel"))
    df.attrs["units"] = units
    df.attrs["model"] = ds.attrs["model"]
    return df


def to_csv(result: Result | Any, path: PathLike) -> Path:
    """Write :func:`summary` (of a result or its dataset) as CSV (TSV for ``.tsv``); a first
    comment line gives the units."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    df = summary(result)
    sep = "\t" if p.suffix.lower() == ".tsv" else ","
    with p.open("w") as fh:
        fh.write("# oxyline summary of model '" + df.attrs["model"] + "'; units: "
                 + ", ".join(f"{k} [{u}]" for k, u in df.attrs["units"].items()
                             if k.endswith("_mean")).replace("_mean", "") + "\n")
        df.to_csv(fh, sep=sep)
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
