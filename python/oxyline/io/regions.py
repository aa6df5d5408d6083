"""Per-region sums of a segment variable of a stored run, lazily with Dask, by integer codes.

A region is a set of vessels (a subtree, an organ's bed); a segment belongs to the region of
its vessel. The reduction never builds a per-segment string: the vessel of each segment is
read from the store's integer ``segment_index`` (segments are stored vessel by vessel, in the
order of the ``vessel`` dimension, each vessel's from index 0), its region from an integer
array over the vessels, and each chunk of segments is summed into the regions by runs of
equal codes. Memory is bounded by the store's chunks (a few per worker thread) plus one
int32 per segment chunk's codes: a ten-million-segment store is reduced chunk by chunk.

    import xarray as xr
    from oxyline.io.regions import region_sum

    ds = xr.open_zarr("tree.zarr", chunks={})
    per_region = region_sum(ds, "segment_wall_o2_flux", vessel_region, names)  # lazy
    delivery = per_region.integrate("time").compute() / period              # mol/s
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from oxyline.errors import ModelError


def segment_vessels(ds: Any) -> Any:
    """The position in ``ds.vessel`` of each segment's vessel, as a lazy int64 Dask array
    chunked as the store's segments: a new vessel starts at every ``segment_index`` 0."""
    import dask.array as da

    index = ds["segment_index"].data
    if not isinstance(index, da.Array):
        index = da.from_array(np.asarray(index), chunks=-1)
    return da.cumsum(index == 0) - 1


def _sum_by_code(block: np.ndarray, codes: np.ndarray, n: int) -> np.ndarray:
    """(rows, n) sums of the columns of ``block`` (rows, segments) by their code in
    0..n-1 (a negative code: in no region). The columns are summed run by run of equal codes
    (a vessel's segments are adjacent, so are a subtree's vessels often), then the runs
    added into their regions in column order: the same order for any chunking of time."""
    out = np.zeros((block.shape[0], n))
    if codes.size == 0:
        return out
    starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    runs = np.add.reduceat(np.asarray(block, dtype=float), starts, axis=1)
    run_codes = codes[starts]
    keep = run_codes >= 0
    np.add.at(out.T, run_codes[keep], runs[:, keep].T)
    return out


def _block_sums(block: np.ndarray, codes: np.ndarray, n: int) -> np.ndarray:
    return _sum_by_code(block, codes, n)[:, None, :]


def _region_codes(vessel_region: Any, n_vessels: int) -> tuple[np.ndarray, int]:
    """The checked int32 region code of every vessel, and the number of regions."""
    codes = np.asarray(vessel_region)
    if codes.shape != (n_vessels,) or not np.issubdtype(codes.dtype, np.integer):
        raise ModelError(f"region_sum: vessel_region must hold one integer region code per "
                         f"vessel of the store ({n_vessels}), got an array of shape "
                         f"{codes.shape} and dtype {codes.dtype}")
    n = int(codes.max()) + 1 if codes.size else 0
    if n > 2**31 - 1:
        raise ModelError(f"region_sum: region code {n - 1} is too large (int32 codes)")
    return codes.astype(np.int32), max(n, 0)


def region_sum(ds: Any, variable: str, vessel_region: Any,
               names: Sequence[Any] | None = None) -> Any:
    """The sum over each region's segments of the segment variable ``variable`` (dims
    ``time``, ``segment``) of the dataset ``ds`` (a store opened with
    ``xarray.open_zarr(path, chunks={})``), as a lazy ``xarray.DataArray`` with dims
    ``time``, ``region``.

    ``vessel_region``: one integer per vessel of ``ds.vessel`` (in its order), the code
    0..R-1 of the vessel's region, or -1 for a vessel in none. ``names``: the R regions'
    labels (the ``region`` coordinate; default 0..R-1). Each chunk of the variable is read
    once and reduced to (rows, R) sums; nothing per segment is held beyond a chunk."""
    import dask.array as da
    import xarray as xr

    if variable not in ds:
        raise ModelError(f"region_sum: the store has no variable {variable!r} (segment "
                         f"variables: {[v for v in ds.data_vars if 'segment' in ds[v].dims]})")
    var = ds[variable]
    if var.dims != ("time", "segment"):
        raise ModelError(f"region_sum: {variable!r} has dims {var.dims}, not (time, segment)")
    per_vessel, n = _region_codes(vessel_region, ds.sizes["vessel"])
    if names is not None and len(names) != n:
        raise ModelError(f"region_sum: {len(names)} region names for {n} region codes")
    data = var.data if isinstance(var.data, da.Array) else da.from_array(var.data)
    vessels = segment_vessels(ds).rechunk((data.chunks[1],))
    codes = vessels.map_blocks(lambda v: per_vessel[v], dtype=np.int32)
    parts = da.blockwise(_block_sums, "tjr", data, "tj", codes, "j", n=n, new_axes={"r": n},
                         adjust_chunks={"j": 1}, dtype=float, meta=np.zeros((0, 0, 0)))
    sums = parts.sum(axis=1)
    coords = {"time": ds["time"], "region": list(names) if names is not None else np.arange(n)}
    return xr.DataArray(sums, dims=("time", "region"), coords=coords,
                        attrs=dict(var.attrs), name=variable)
