"""Result files read back: :func:`open_result` rebuilds a :class:`~oxyline.Result` from a
NetCDF file, a Zarr store or an ``xarray.Dataset`` (the inverse of :meth:`Result.to_xarray` and
of the writers of :mod:`oxyline.io.results`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from oxyline.io._common import PathLike
from oxyline.io.results import _quiet, _zarr
from oxyline.result import (
    BALANCE,
    SEGMENT_VARIABLES,
    SPECIES_SEGMENT,
    SPECIES_VESSEL,
    TISSUE_BALANCE,
    TISSUE_SEGMENT,
    TISSUE_VESSEL,
    VESSEL_VARIABLES,
    Result,
    SpeciesResult,
    TissueResult,
)

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
    import xarray as xr

    p = Path(source)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or directory")
    if p.suffix.lower() == ".zarr" or (p.is_dir() and (p / ".zgroup").exists()):
        _zarr()
        with _quiet():
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


def _needer(ds: Any, label: str) -> Any:
    """``need(name, dims=None)``: the array of variable ``name`` of ``ds``, checked to exist
    (else the file is not an oxyline result) and, when ``dims`` is given, to have those dims."""
    import numpy as np

    def need(name: str, dims: tuple[str, ...] | None = None) -> Any:
        if name not in ds.variables:
            raise ValueError(f"{label} is not an oxyline result: no variable '{name}' "
                             "(oxyline.open_result reads files written by Result.to_netcdf, "
                             "Result.to_zarr or oxyline.simulate_to_zarr)")
        var = ds[name]
        if dims is not None and var.dims != dims:
            raise ValueError(f"{label}: variable '{name}' has dims {var.dims}, expected {dims}")
        return np.asarray(var.values)

    return need


def _segment_layout(ds: Any, need: Any, vessels: list[str], label: str
                    ) -> tuple[list[int], Any, int]:
    """(segments per vessel, segment positions, segment count) of the file; none without
    segments."""
    import numpy as np

    if "segment_vessel" not in ds.variables:
        return [], np.zeros(0, dtype=np.float64), 0
    seg_vessel = [str(v) for v in need("segment_vessel")]
    index = {n: i for i, n in enumerate(vessels)}
    try:
        owner = np.array([index[n] for n in seg_vessel], dtype=np.int64)
    except KeyError as exc:
        raise ValueError(f"{label}: segment of unknown vessel {exc.args[0]!r}") from None
    # the core numbers segments vessel by vessel; anything else has no Result layout
    if np.any(np.diff(owner) < 0):
        raise ValueError(f"{label}: segments are not grouped by vessel in vessel order")
    segment_count = np.bincount(owner, minlength=len(vessels)).tolist()
    positions = need("segment_position").astype(np.float64)
    return segment_count, positions, len(seg_vessel)


def _flow_data(ds: Any, need: Any, nt: int, nv: int, ns: int, seg: bool
               ) -> tuple[Any, tuple[str, ...], tuple[str, ...]]:
    """(the core's (time, column) data, vessel variables, segment variables) of the flow."""
    import numpy as np

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
    return data, vvars, svars


def _oxygen_of(ds: Any, attrs: dict[str, Any], need: Any, species: dict[str, Any]) -> Any:
    """The oxygen species' name (None without one); sets its PO2-per-concentration factor."""
    import numpy as np

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
    return oxygen


def _result_from_dataset(ds: Any, label: str) -> Result:
    import numpy as np

    need = _needer(ds, label)
    for name in REQUIRED:
        need(name)
    time = need("time").astype(np.float64)
    vessels = [str(v) for v in need("vessel")]
    nt, nv = len(time), len(vessels)
    seg = "segment_vessel" in ds.variables
    segment_count, positions, ns = _segment_layout(ds, need, vessels, label)
    data, vvars, svars = _flow_data(ds, need, nt, nv, ns, seg)

    attrs = {k: _plain(v) for k, v in ds.attrs.items()}
    species = _species_from_dataset(ds, attrs, need, nt, nv, ns, label)
    oxygen = _oxygen_of(ds, attrs, need, species)
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
    if "step_size" in ds.variables:  # an error-controlled run's step-size history
        result.step_sizes = need("step_size", ("step_time",)).astype(np.float64)
        result.step_times = need("step_time").astype(np.float64)
    # the accumulated-error estimate of every vessel (simulate(..., estimate_time_error=True))
    from oxyline.time_error import table_from_dataset

    result.time_error = table_from_dataset(ds, vessels)
    return result


def _species_from_dataset(ds: Any, attrs: dict[str, Any], need: Any, nt: int, nv: int,
                          ns: int, label: str) -> dict[str, Any]:
    """The :class:`~oxyline.result.SpeciesResult` of every species in ``ds``, in run order."""
    import numpy as np

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
