"""The large-model default output: per-vessel summaries reduced while the run streams its rows.

Above :data:`oxyline.run.LARGE_MODEL_SEGMENTS` a run without an output selection no longer
keeps every vessel's time series in memory (at ~1e6 segments five vessel variables every
10 ms alone are ~1 kB per segment, as much as the network and the solver together). The core
hands its rows over a few at a time (the same chunked path as ``simulate_to_zarr``); the core
folds each chunk into every output column's time integral (trapezoidal rule, also across chunk
boundaries), minimum and maximum (``_core.ColumnStatsFold``), and only the rows of the inlet
vessels (those starting at a flow or pressure inlet) are kept as time series. The result's ``summary()`` is
then the table :func:`oxyline.io.results.summary` computes from a complete output: same index,
columns (``<variable>_<stat>``), units and values (the mean to rounding: the sum runs chunk by
chunk), at ~40 B per vessel and variable instead of 8 B per output time.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from oxyline import _core
from oxyline.result import UNITS

if TYPE_CHECKING:
    from oxyline.model import Model
    from oxyline.result import Result

#: rows handed over per chunk: at most this many bytes of output at once (at least one row)
CHUNK_BYTES = 16 << 20


def inlet_vessels(model: Model, vessels: list[str]) -> list[str]:
    """The vessels of ``vessels`` starting at a flow or pressure inlet (the model's first
    vessel when none does): the time series a summarized run keeps."""
    # the native description (``canonical`` of a whole tree would be built anew: ~185 B a
    # segment)
    source = model.source  # (read once: a large model's is unpacked on each read)
    bcs = source.get("boundary_conditions") or {}
    nodes = {str(n) for n, bc in bcs.items()
             if isinstance(bc, Mapping) and bc.get("type") in ("flow", "pressure")}
    chosen = set(vessels)
    found = [str(v["name"]) for v in source.get("vessels") or ()
             if isinstance(v, Mapping) and str(v.get("from")) in nodes
             and str(v.get("name")) in chosen]
    return found or vessels[:1]


def vessel_arrays(res: Result) -> list[tuple[str, Any, str]]:
    """(name, (time, vessel) array, units) of every per-vessel variable of ``res``: the
    variables ``res.to_xarray()`` gives dims (time, vessel), without building the dataset
    (its vessel index: 262 k names at 1e6 segments)."""
    out = [(name, getattr(res, name), UNITS[name]) for name in res.vessel_variables]
    out += [(name, arr, unit) for name, (kind, arr, unit) in res.species_variables().items()
            if kind == "vessel"]
    return out


class SummaryStream:
    """The chunk sink of a summarized run: has the core fold each chunk of rows (core layout
    of the settings ``s``: every default vessel, no segments) into per-column statistics (read
    back as per-vessel ones by :meth:`summary`) and keeps the
    inlet vessels' columns of every row. ``layout``:
    the core's output layout of ``s`` (the caller resolves it once per run), without its
    ``transport`` part when the run has no transport."""

    def __init__(self, model: Model, layout: Mapping[str, Any], result_of: Any) -> None:
        self._result_of = result_of  # rows (core layout of s) -> Result
        lay = layout
        self.vessels = [str(v) for v in lay["vessels"]]
        self.inlets = inlet_vessels(model, self.vessels)
        index = {v: i for i, v in enumerate(self.vessels)}
        kv, nv = len(lay["vessel_variables"]), len(self.vessels)
        width = int(lay["n_columns"])
        keep = [i * kv + j for v in self.inlets for j in range(kv) for i in (index[v],)]
        self._flow_cols = np.array(keep, dtype=np.intp)
        tl = lay.get("transport")
        self._species_cols = None
        species_width = 0
        if tl is not None:
            kvs, cols = len(tl["vessel_variables"]), int(tl["columns_per_species"])
            per = [i * kvs + j for v in self.inlets for j in range(kvs) for i in (index[v],)]
            per += list(range(nv * kvs, cols))  # the mass balance (no segments, no tissue)
            self._species_cols = np.array([k * cols + c for k in range(len(tl["species"]))
                                           for c in per], dtype=np.intp)
            species_width = cols * len(tl["species"])
        self.rows = max(1, CHUNK_BYTES // (8 * (width + species_width)))
        self._row_bytes = 8 * (width + species_width)
        self._reduced = len(lay["vessel_variables"]) + (
            (len(tl["vessel_variables"]) + 1) * len(tl["species"]) if tl is not None else 0)
        self._times: list[np.ndarray] = []
        self._flow: list[np.ndarray] = []
        self._species: list[np.ndarray] = []
        self._species_names: list[str] = []
        self._initial: list[float] = []
        # every core column's time mean, min and max, folded by the core chunk by chunk (the
        # flow rows, the species rows), and the first rows (the summary of a run of one row),
        # held only until a later time arrives: the output times increase, so the folds'
        # statistics then exist (a row of a 1e6-segment tree's summary is ~12 B per segment,
        # held through the whole run before)
        self._folds = [_core.ColumnStatsFold(width),
                       _core.ColumnStatsFold(species_width)]
        self._t_first: float | None = None
        self._first: list[np.ndarray] = []

    def bytes(self) -> float:
        """Estimated bytes beside the kept rows: the chunk in flight (twice: the core's rows
        and their result's arrays), the running sums, minima, maxima, first and last rows
        and the summary table (3 numbers), 8 bytes per vessel and variable each (``po2_out``
        counted as one more species variable)."""
        return 2.0 * self.rows * self._row_bytes + 8.0 * 8 * self._reduced * len(self.vessels)

    def add(self, rows: dict[str, Any]) -> None:
        """One chunk of the core's rows (``chunk_sink``)."""
        t = np.asarray(rows["times"], dtype=float)
        if t.size == 0:
            return
        self._times.append(t.copy())
        self._flow.append(rows["data"][:, self._flow_cols])
        tr = rows.get("transport")
        blocks = [rows["data"], tr["data"] if tr is not None else np.zeros((t.size, 0))]
        if tr is not None and self._species_cols is not None:
            self._species.append(tr["data"][:, self._species_cols])
            self._species_names = list(tr["species"])
            self._initial = [float(x) for x in tr["initial_stored"]]
        for fold, block in zip(self._folds, blocks, strict=True):
            fold.push(t, np.ascontiguousarray(block, dtype=float))
        if self._t_first is None:
            self._t_first = float(t[0])
            self._first = [b[0].copy() for b in blocks]
        if self._first and float(t[-1]) > self._t_first:
            self._first = []  # two rows over a positive span: the folds' statistics exist

    def summary(self, model_name: str) -> Any:
        """The per-vessel table of :func:`oxyline.io.results.summary` (mean, min, max): the
        folded statistics as three rows of the run's layout, read as a result."""
        import pandas as pd

        cols: dict[str, Any] = {}
        units: dict[str, str] = {}
        if self._t_first is not None:
            firsts = self._first or [None] * len(self._folds)
            stats = [f.finish() or (first,) * 3 for f, first in zip(self._folds, firsts,
                                                                    strict=True)]
            rows: dict[str, Any] = {"times": np.arange(3.0), "data": np.stack(stats[0])}
            if self._species_cols is not None:
                rows["transport"] = {"species": self._species_names, "data": np.stack(stats[1]),
                                     "initial_stored": self._initial}
            for name, a, unit in vessel_arrays(self._result_of(rows)):
                for k, stat in enumerate(("mean", "min", "max")):
                    cols[f"{name}_{stat}"] = np.asarray(a[k], dtype=float)
                    units[f"{name}_{stat}"] = unit
        df = pd.DataFrame(cols, index=pd.Index(self.vessels, name="vessel"))
        df.attrs["units"] = units
        df.attrs["model"] = model_name
        return df

    def raw(self, raw: dict[str, Any]) -> dict[str, Any]:
        """The run's outcome with the kept rows (the inlets' layout) as its output."""
        raw = dict(raw)
        raw["times"] = np.concatenate(self._times) if self._times else np.zeros(0)
        raw["data"] = np.concatenate(self._flow) if self._flow \
            else np.zeros((0, self._flow_cols.size))
        if self._species_cols is not None:
            tr = dict(raw.get("transport") or {})
            tr.setdefault("species", self._species_names)
            tr.setdefault("initial_stored", self._initial)
            tr["data"] = np.concatenate(self._species) if self._species \
                else np.zeros((0, self._species_cols.size))
            raw["transport"] = tr
        return raw
