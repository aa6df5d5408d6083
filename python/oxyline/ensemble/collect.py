"""What an ensemble keeps of each finished variant (``output=``) and the dataset it returns.

* ``"summary"``: per (variant, vessel) ``<var>_mean``, ``_min`` and ``_max`` of the output
  (the last cycle by default), exactly :meth:`oxyline.Result.summary`; memory O(variants ×
  vessels); a model with chambers or valves also has ``chamber_volume_<stat>`` per (variant,
  chamber) and ``valve_status_<stat>`` per (variant, valve) (the mean: the fraction of the
  time open) of :attr:`oxyline.Result.chamber_volume` and ``valve_status``;
* ``"full"``: the variables of :meth:`oxyline.Result.to_xarray` with a leading ``variant``
  dim (``time`` and ``segment`` padded with NaN where variants differ in length);
* a callable ``f(result) -> {name: float}``: those scalars along ``variant``.

Every dataset has ``status`` (0 finished, see :data:`STATUS`), ``error`` (the message of a
failed variant), ``warning`` (what the physical-bounds monitor found in a finished variant's
species output, docs/physics.md §2.8; empty if nothing), ``period``, ``cycles_run`` and
``periodic_error`` per variant, and the patch values as coordinates along ``variant`` (their
dotted paths).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from oxyline._core import __version__
from oxyline.ensemble.patch import flatten
from oxyline.errors import (
    ModelError,
    OutputError,
    SimulationCancelled,
    SimulationInterrupted,
)
from oxyline.io.results import STATS, dataset, stats
from oxyline.model import Model
from oxyline.monitor import warn
from oxyline.result import Result

#: ``status`` of a variant: 0 finished; the others say why it has no output
STATUS = {"ok": 0, "model": 1, "unstable": 2, "solver": 3, "output": 4, "interrupted": 5,
          "resource": 6, "worker": 7, "not run": -1}
#: the heart outputs' summary variables and their dim besides ``variant``
HEART_DIMS = {"chamber_volume": "chamber", "valve_status": "valve"}
#: the per-variant facts every ensemble dataset has besides its outputs
FACTS = ("status", "error", "warning", "period", "cycles_run", "periodic_error")
ERROR_CHARS = 400  # stored error messages are cut to this length (fixed-width strings)

Output = str | Callable[[Result], Mapping[str, float]]


def check_output(output: Any) -> None:
    if not (callable(output) or output in ("summary", "full")):
        raise ModelError(f"simulate_ensemble: output must be 'summary', 'full' or a callable "
                         f"f(result) -> {{name: float}}, got {output!r}")


def summary_values(result: Result, column_stats: Sequence[np.ndarray] | None = None
                   ) -> dict[str, np.ndarray]:
    """``<var>_<stat>`` per vessel of a result: the values of :meth:`oxyline.Result.summary`
    (same variables, order and statistics), read from the result's arrays without building
    its dataset (a hundredth of the time: this runs once per variant). ``column_stats``: the
    (mean, min, max) per output column that the core computed on the worker thread, with
    numpy's arithmetic for arrays of two or more vessels (``column_stats`` in the core's
    ``ensemble`` module); the flow variables are then taken from them."""
    t = np.asarray(result.time, dtype=float)
    flow = _flow_stats(len(result.vessels), result.vessel_variables, result.data.shape[1],
                       column_stats)
    arrays = [(name, None if flow else getattr(result, name))
              for name in result.vessel_variables]
    arrays += [(name, arr) for name, (kind, arr, _) in result.species_variables().items()
               if kind == "vessel"]
    return {f"{name}_{stat}": val for name, arr in arrays
            for stat, val in zip(STATS, flow[name] if arr is None
                                 else stats(np.asarray(arr, dtype=float), t))}


def _flow_stats(nv: int, variables: Sequence[str], columns: int,
                column_stats: Sequence[np.ndarray] | None
                ) -> dict[str, tuple[np.ndarray, ...]] | None:
    """The (mean, min, max) per vessel of each flow variable (``variables`` of ``nv`` vessels,
    ``columns`` output columns) from the core's per-column statistics, or None where numpy
    would compute them otherwise (one vessel: numpy sums a single column pairwise; one time:
    plain means) or none were computed."""
    kv = len(variables)
    if column_stats is None or nv < 2 or len(column_stats[0]) != columns:
        return None
    block = [np.asarray(s)[: kv * nv] for s in column_stats]
    return {name: tuple(s[k::kv] for s in block) for k, name in enumerate(variables)}


def heart_summary(chamber_volume: Mapping[str, np.ndarray], valve_status: Mapping[str, Any],
                  t: np.ndarray) -> dict[str, np.ndarray]:
    """``chamber_volume_<stat>`` and ``valve_status_<stat>`` (one value per chamber or valve)
    of a result's heart outputs over its output times, as :func:`summary_values` takes the
    vessels' (time averages by the trapezoidal rule)."""
    out = {}
    for var, parts in (("chamber_volume", chamber_volume), ("valve_status", valve_status)):
        if parts:
            a = np.column_stack([np.asarray(v, dtype=float) for v in parts.values()])
            for stat, val in zip(STATS, stats(a, np.asarray(t, dtype=float))):
                out[f"{var}_{stat}"] = val
    return out


def stats_summary(raw: Mapping[str, Any], layout: Mapping[str, Any]
                  ) -> dict[str, np.ndarray] | None:
    """:func:`summary_values` of a finished variant read straight from the core's per-column
    statistics and its layout, without building its :class:`~oxyline.Result` (the calling
    thread's per-variant work), or None where that takes the result: species outputs (their
    statistics are numpy's, from the result's arrays) or no usable column statistics. The
    same arrays and names in the same order as :func:`summary_values`."""
    stats = _column_stats(raw)
    flow = None if stats is None else _flow_stats(
        len(layout["vessels"]), layout["vessel_variables"], raw["data"].shape[1], stats)
    if flow is None:
        return None
    return {f"{name}_{stat}": val for name, values in flow.items()
            for stat, val in zip(STATS, values)}


def _column_stats(raw: Mapping[str, Any]) -> Sequence[np.ndarray] | None:
    """The core's per-column statistics of a finished variant's run ``raw``, or None where
    its summary takes the result: species outputs (their statistics are numpy's) or no
    statistics of every output column."""
    stats, data = raw.get("column_stats"), raw.get("data")
    if "transport" in raw or stats is None or getattr(data, "ndim", 0) != 2 \
            or len(stats[0]) != data.shape[1]:
        return None
    return stats


class StatsBatch:
    """Summaries read from the core's column statistics (see :func:`stats_summary`), kept as
    the variants finish and written into the collector in one numpy pass at the end
    (:meth:`flush`): the collecting thread then does a list append per variant instead of
    ~20 small array operations. Only variants with the same output vessels and variables as
    the first one (every variant of a usual ensemble) and as many vessels as the collector
    join the batch; :meth:`add` returns False for the others, which take
    :func:`stats_summary`. The values are the same arrays, stored under the same names in
    the same order."""

    def __init__(self, collector: Collector) -> None:
        self.collector = collector
        self.key: tuple[list[str], list[str]] | None = None
        self.rows: list[int] = []
        self.stats: list[Sequence[np.ndarray]] = []

    def add(self, i: int, raw: Mapping[str, Any], layout: Mapping[str, Any]) -> bool:
        stats = _column_stats(raw)
        if stats is None:
            return False
        key = (list(layout["vessels"]), list(layout["vessel_variables"]))
        if self.key is None:
            if not 2 <= len(key[0]) == len(self.collector.vessels):
                return False
            self.key = key
        elif key != self.key:
            return False
        self.rows.append(i)
        self.stats.append(stats)
        return True

    def flush(self) -> None:
        """Write the batched variants' values into the collector (status 0)."""
        if not self.rows:
            return
        assert self.key is not None
        vessels, variables = self.key
        kv, nv, c = len(variables), len(vessels), self.collector
        rows = np.asarray(self.rows)
        blocks = [np.stack([np.asarray(s[j]) for s in self.stats])[:, : kv * nv]
                  for j in range(len(STATS))]
        for k, name in enumerate(variables):
            for stat, block in zip(STATS, blocks):
                arr = c.values.get(f"{name}_{stat}")
                if arr is None:
                    arr = c.values[f"{name}_{stat}"] = np.full((c.n, len(c.vessels)), np.nan)
                arr[rows] = block[:, k::kv]
        c.status[rows] = STATUS["ok"]
        self.rows, self.stats = [], []


def patch_coords(patches: Sequence[Mapping[str, Any]]) -> dict[str, np.ndarray]:
    """The scalar patch values by dotted path, one entry per variant (NaN/'' where a variant
    does not set it). One pass over the patches collects each path's (variant, value) pairs
    (a population's patch sets ~340 paths: looking every path up in every patch cost as much
    as checking the patches, on the calling thread after the last variant)."""
    columns: dict[str, tuple[list[int], list[Any]]] = {}
    for j, patch in enumerate(patches):
        for path, value in flatten(patch).items():
            col = columns.get(path)
            if col is None:
                col = columns[path] = ([], [])
            col[0].append(j)
            col[1].append(value)
    n = len(patches)
    coords = {}
    for path in sorted(columns):
        rows, vals = columns[path]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
            arr = np.full(n, np.nan)
            arr[rows] = [float(v) for v in vals]
            coords[path] = arr
        else:
            texts = [""] * n
            for j, v in zip(rows, vals, strict=True):
                texts[j] = str(v)
            coords[path] = np.array(texts)
    return coords


class Collector:
    """Per-variant facts and outputs of an ensemble of ``n`` variants, filled as variants
    finish (in any order); :meth:`dataset` builds the result."""

    def __init__(self, n: int, output: Output, vessels: list[str]) -> None:
        self.n, self.output, self.vessels = n, output, vessels
        self.status = np.full(n, STATUS["not run"], dtype=np.int64)
        self.error = np.full(n, "", dtype=object)
        self.warning = np.full(n, "", dtype=object)
        self.period = np.full(n, np.nan)
        self.cycles_run = np.zeros(n, dtype=np.int64)
        self.periodic_error = np.full(n, np.nan)
        self.values: dict[str, np.ndarray] = {}  # summary/callable outputs by name
        self.datasets: dict[int, Any] = {}  # full output
        #: the model's chambers and valves (coordinates of the heart summary variables)
        self.heart: dict[str, list[str]] = {}

    def fail(self, i: int, kind: str, message: str) -> None:
        # an error kind without its own code (a newer core's) is a solver failure, never a
        # KeyError that loses the finished variants
        self.status[i] = STATUS.get(kind, STATUS["solver"])
        self.error[i] = message

    def warn(self, i: int, messages: Sequence[str]) -> None:
        """Record the physical-bounds findings of finished variant ``i`` (cut to
        ERROR_CHARS like the errors)."""
        self.warning[i] = "; ".join(messages)[:ERROR_CHARS]

    def facts(self, i: int, period: float, raw: Mapping[str, Any] | None) -> None:
        self.period[i] = period
        if raw is not None:
            self.cycles_run[i] = raw["cycles_run"]
            self.periodic_error[i] = raw["periodic_error"]

    def outputs(self, result: Result, column_stats: Sequence[np.ndarray] | None = None
                ) -> dict[str, Any]:
        """What variant ``result`` contributes (may raise: the variant then fails);
        ``column_stats``: see :func:`summary_values`."""
        if self.output == "summary":
            return summary_values(result, column_stats)
        if self.output == "full":
            return {"": dataset(result)}
        values = self.output(result)  # type: ignore[operator]
        if not isinstance(values, Mapping):
            raise TypeError(f"output callable must return a mapping {{name: float}}, got "
                            f"{type(values).__name__}")
        return {str(k): float(v) for k, v in values.items()}

    def put(self, i: int, values: Mapping[str, Any]) -> None:
        """Store the outputs of finished variant ``i``."""
        if self.output == "full":
            self.datasets[i] = values[""]
        else:
            for name, v in values.items():
                arr = self.values.get(name)
                if arr is None:
                    arr = self.values[name] = np.full((self.n, *np.shape(v)), np.nan)
                arr[i] = v
        self.status[i] = STATUS["ok"]

    def dataset(self, patches: Sequence[Mapping[str, Any]], attrs: Mapping[str, Any],
                index: Any = None) -> Any:
        import xarray as xr

        coords: dict[str, Any] = {"variant": np.arange(self.n)}
        if index is not None:
            coords["variant_label"] = ("variant", np.asarray(index))
        for path, vals in patch_coords(patches).items():
            if path != "period":  # the ``period`` variable holds every variant's period
                coords[path] = ("variant", vals)
        data: dict[str, Any] = {
            "status": ("variant", self.status),
            "error": ("variant", self.error.astype(str)),
            "warning": ("variant", self.warning.astype(str)),
            "period": ("variant", self.period, {"units": "s"}),
            "cycles_run": ("variant", self.cycles_run),
            "periodic_error": ("variant", self.periodic_error),
        }
        if self.output == "full":
            ds = _stack_full(self.datasets, self.n)
            for name, var in data.items():
                ds[name] = var
            ds = ds.assign_coords({k: v for k, v in coords.items() if k != "variant"})
            ds.attrs.update(attrs)
            return ds
        dims = {name: next((d for var, d in HEART_DIMS.items() if name.startswith(f"{var}_")),
                           "vessel") for name, arr in self.values.items() if arr.ndim == 2}
        for dim in set(dims.values()):
            names = self.vessels if dim == "vessel" else self.heart.get(dim)
            if names is not None:
                coords[dim] = (dim, np.array(names, dtype=str))
        for name, arr in self.values.items():
            data[name] = (("variant", dims[name]) if arr.ndim == 2 else ("variant",), arr)
        return xr.Dataset(data, coords=coords, attrs=dict(attrs))


def _stack_full(datasets: Mapping[int, Any], n: int) -> Any:
    """The per-variant datasets of ``output="full"`` stacked along a leading ``variant`` dim,
    ``time`` and ``segment`` padded with NaN to the longest variant (a variant of another
    period or segmentation); failed variants are all NaN."""
    import xarray as xr

    if not datasets:
        return xr.Dataset(coords={"variant": np.arange(n)})
    first = datasets[min(datasets)]
    sizes = {d: max(ds.sizes.get(d, 0) for ds in datasets.values()) for d in first.sizes}
    out: dict[str, Any] = {}
    for name, var in first.variables.items():
        if name in first.dims and name != "time":
            continue  # index coordinates (vessel) go below
        shape = (n, *(sizes[d] for d in var.dims))
        dtype = var.dtype if var.dtype.kind in "fciu" else None
        if dtype is None:
            continue  # string coordinates (segment_vessel): taken from the first variant
        # (an integer variable, valve_status, becomes float: NaN for a failed variant)
        arr = np.full(shape, np.nan, dtype=np.result_type(dtype, np.float64))
        for i, ds in datasets.items():
            v = ds.variables[name]
            arr[(i, *(slice(0, s) for s in v.shape))] = v.values
        out[name] = (("variant", *var.dims), arr, dict(var.attrs))
    time = out.pop("time")
    ds = xr.Dataset({k: v for k, v in out.items() if k not in first.coords},
                    coords={"variant": np.arange(n), "vessel": first["vessel"].values})
    ds["time"] = time  # (variant, time): variants of other periods have other times
    ds = ds.set_coords("time")
    for name in first.coords:
        if name not in ds.variables and name != "vessel" and "segment" in first[name].dims \
                and sizes.get("segment", 0) == first.sizes.get("segment", 0):
            ds = ds.assign_coords({name: first[name]})
    # the chambers and valves (a patch changes values, not the model's structure)
    ds = ds.assign_coords({d: first[d].values for d in HEART_DIMS.values() if d in first.coords})
    ds.attrs.update({k: v for k, v in first.attrs.items() if not k.startswith("solver_")})
    return ds


def finish(model: Model, patches: list[dict[str, Any]], index: Any, collector: Collector,
            output: Output, writer: Any, finished: bool, cancelled: bool = False) -> Any:
    """The ensemble's dataset (the closed store, or the collected variants); an interrupted
    ensemble raises :class:`SimulationInterrupted` (:class:`SimulationCancelled` when its
    ``cancel`` was set) carrying it. Shared by the local and the Dask paths."""
    if writer is not None:
        writer.close(complete=finished)
        if writer.failure is not None:  # disk full: say what the store holds, lose nothing
            _warn_bounds(collector)
            raise OutputError(writer.failure_message(),
                              collector.dataset(patches, dataset_attrs(model, output), index))
        ds = writer.open()
    else:
        ds = collector.dataset(patches, dataset_attrs(model, output), index)
    _warn_bounds(collector)
    if not finished:
        done = int((ds["status"].values == 0).sum())
        cls = SimulationCancelled if cancelled else SimulationInterrupted
        raise cls(
            f"ensemble {'cancelled' if cancelled else 'interrupted'} after {done} finished "
            f"variant(s) of {len(patches)}; the dataset is in exc.result (status -1: not run, "
            "5: interrupted)", ds)
    return ds


def _warn_bounds(collector: Collector) -> None:
    """One :class:`~oxyline.PhysicalBoundsWarning` for the whole ensemble, naming the
    variants whose species output left its physical bounds (each variant's findings are in
    the dataset's ``warning``); the ensemble itself ran on."""
    hit = [i for i, w in enumerate(collector.warning) if w]
    if hit:
        shown = ", ".join(map(str, hit[:20])) + (", ..." if len(hit) > 20 else "")
        msg = (f"{len(hit)} variant(s) left their physical bounds (variants {shown}; each "
               f"variant's findings are in the dataset's 'warning'); variant {hit[0]}: "
               f"{collector.warning[hit[0]]}")
        # warn → _warn_bounds → finish → _local / run_on_client → simulate_ensemble → caller
        warn([msg], stacklevel=5)


def dataset_attrs(model: Model, output: Output) -> dict[str, Any]:
    return {"model": model.name, "oxyline_version": __version__,
            "output": output if isinstance(output, str) else getattr(output, "__name__",
                                                                      "callable"),
            "status_codes": ", ".join(f"{v}: {k}" for k, v in STATUS.items())}
