"""An ensemble's Zarr store, written variant by variant as they finish.

The store is created before the first variant runs with every per-variant variable sized for
the whole ensemble (``status`` -1: not run) and one chunk per variant, so that writing a
variant is a region write of its own chunks and never rewrites another variant's: a killed
ensemble keeps every variant that finished (``status`` is written last, so a variant with
``status`` 0 is whole). Output variables appear when the first variant that has them
finishes. Zarr format 2, as :meth:`oxyline.Result.to_zarr`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from oxyline.ensemble.collect import ERROR_CHARS, Collector
from oxyline.errors import ModelError
from oxyline.io.results import _zarr

FACTS = ("period", "cycles_run", "periodic_error", "error", "warning")
TEXTS = ("error", "warning")  # fixed-width strings, cut to ERROR_CHARS


class StoreWriter:
    def __init__(self, path: str | Any, collector: Collector,
                 patches: Sequence[Mapping[str, Any]], attrs: Mapping[str, Any],
                 index: Any = None) -> None:
        if collector.output == "full":
            raise ModelError("simulate_ensemble: store= keeps summaries or the values of an "
                             "output callable; write a full run with oxyline.simulate_to_zarr")
        self.path = Path(path)
        self.collector = collector
        self._zarr = _zarr()
        template = collector.dataset(patches, {**attrs, "complete": 0}, index)
        for name in TEXTS:
            template[name] = template[name].astype(f"<U{ERROR_CHARS}")
        template = template.assign_coords(vessel=("vessel", np.array(collector.vessels, dtype=str)))
        encoding = {name: {"chunks": (1,) * template[name].ndim}
                    for name in template.data_vars}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # fixed-width strings: Zarr format 2 only
            template.to_zarr(self.path, mode="w", encoding=encoding, zarr_format=2)
        self._group = self._zarr.open_group(self.path, mode="r+", zarr_format=2,
                                            use_consolidated=False)
        self._written: set[str] = set()
        #: the variants whose rows (status last) are in the store, in the order written
        self.stored: list[int] = []
        #: the variant whose write failed and the error (disk full, ...); nothing is written
        #: after it, the ensemble runs on in memory
        self.failure: tuple[int, OSError] | None = None

    def _array(self, name: str, value: Any) -> Any:
        if name not in self._group:
            dims = ["variant", "vessel"] if np.ndim(value) else ["variant"]
            shape = (self.collector.n, len(self.collector.vessels))[:len(dims)]
            self._group.create_array(name, shape=shape, dtype="f8", chunks=(1,) * len(dims),
                                     fill_value=np.nan,
                                     attributes={"_ARRAY_DIMENSIONS": dims})
            self._consolidate()
        return self._group[name]

    def write(self, i: int) -> None:
        """Write variant ``i`` as the collector holds it (its status last). A write that fails
        (disk full, a lost mount) stops the writing, not the ensemble: the failure is kept for
        :meth:`failure_message`, and the variant's status in the store stays -1 (not run), so
        the store holds whole variants only."""
        if self.failure is not None:
            return
        c = self.collector
        try:
            if c.status[i] == 0:
                for name, arr in c.values.items():
                    self._array(name, arr[i])[i] = arr[i]
            for name in FACTS:
                value = getattr(c, name)[i]
                self._group[name][i] = str(value)[:ERROR_CHARS] if name in TEXTS else value
            self._group["status"][i] = c.status[i]
        except OSError as exc:
            self.failure = (i, exc)
            return
        self.stored.append(i)

    def failure_message(self) -> str:
        """What a failed store holds: the variant and error that stopped the writing and the
        variants written whole before it."""
        assert self.failure is not None
        i, exc = self.failure
        held = _ranges(sorted(self.stored))
        return (f"{self.path}: writing variant {i} failed ({type(exc).__name__}: "
                f"{exc.strerror or exc}); the store holds {len(self.stored)} of "
                f"{self.collector.n} variants whole ({held or 'none'}; status 0 or a failure "
                "code), the others have status -1 there. Every finished variant is in "
                "exc.result (in memory)")

    def close(self, complete: bool) -> None:
        try:
            self._group.attrs["complete"] = int(complete and self.failure is None)
            self._consolidate()
        except OSError as exc:
            if self.failure is None:
                self.failure = (-1, exc)

    def open(self) -> Any:
        import xarray as xr

        return xr.open_zarr(self.path)

    def _consolidate(self) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # consolidated metadata is not part of the v2 spec
            self._zarr.consolidate_metadata(self.path, zarr_format=2)


def _ranges(numbers: Sequence[int]) -> str:
    """``0-3, 7, 9-10``: sorted variant numbers as ranges."""
    runs: list[list[int]] = []
    for k in numbers:
        if runs and k == runs[-1][1] + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)
