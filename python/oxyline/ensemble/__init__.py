"""Ensembles: many variants of one network (parameter sweeps, virtual populations,
uncertainty and sensitivity studies) on every core, or on a Dask cluster.

:func:`simulate_ensemble` runs each variant (a patch of the base model, see
:mod:`oxyline.ensemble.patch`) in the Rust core on ``workers`` threads with the GIL released:
the base model is parsed once, each variant assembles its own circuit values and runs with
its own state, and its results are bit-identical to ``oxyline.simulate`` of the patched model
whatever the number of workers. See docs/ensembles.md.
"""

from __future__ import annotations

import operator
import os
from collections.abc import Mapping
from typing import Any

from oxyline.ensemble.collect import (
    STATUS,
    Collector,
    Output,
    check_output,
    dataset_attrs,
    finish,
)
from oxyline.ensemble.patch import apply_patch, as_patches
from oxyline.errors import ModelError
from oxyline.loader import load_model
from oxyline.model import Model

__all__ = ["STATUS", "apply_patch", "simulate_ensemble"]


def simulate_ensemble(model: Model | str | os.PathLike[str] | Mapping[str, Any], variants: Any,
                      *, workers: int | None = None, client: Any = None,
                      output: Output = "summary", store: str | os.PathLike[str] | None = None,
                      progress: Any = True, **overrides: Any) -> Any:
    """Run every variant of ``model`` and return an ``xarray.Dataset`` along ``variant``.

    ``variants``: a sequence of patch dicts in the native model format (``{"vessels": {NAME:
    {prop: value}}, "boundary_conditions": {NODE: {...}}, "blood": {...}, "oxygen": {...},
    "scale": {...}}``), or a pandas DataFrame with dotted-path columns
    (``vessels.CCA.radius``). ``workers``: threads (default ``OXYLINE_NUM_THREADS`` or every
    core). ``client``: a ``dask.distributed.Client``; the variants then run in chunks on its
    workers. ``output``: ``"summary"`` (per vessel ``<var>_mean/_min/_max``), ``"full"``
    (``Result.to_xarray()`` variables with a leading ``variant`` dim) or a callable
    ``f(result) -> {name: float}``. ``store``: a Zarr store written as variants finish.
    ``progress``: a bar over variants, or a callback ``f(done, total)``. ``overrides``: the
    run settings of :func:`oxyline.simulate` (``cycles``, ``until_periodic``, ...).

    A variant that fails has ``status != 0`` and its ``error``; it never stops the others.
    Ctrl-C raises :class:`~oxyline.SimulationInterrupted` with the dataset of the finished
    variants as ``exc.result``.

    >>> import oxyline
    >>> ds = oxyline.simulate_ensemble("bifurcation", [{}, {"vessels": {"parent": {"radius":
    ...     0.004}}}], cycles=2, progress=False)
    >>> ds.status.values.tolist(), ds.pressure_in_mean.dims
    ([0, 0], ('variant', 'vessel'))
    """
    check_output(output)
    workers = _workers(workers)
    model = load_model(model)
    patches, index = as_patches(variants, model)
    if client is not None:
        from oxyline.ensemble.cluster import run_on_client

        return run_on_client(client, model, patches, index, output=output, store=store,
                             progress=progress, workers=workers, overrides=overrides)
    return _local(model, patches, index, workers=workers, output=output, store=store,
                  progress=progress, overrides=overrides)


def _workers(workers: Any) -> int | None:
    """``workers`` checked: None (``OXYLINE_NUM_THREADS`` or every core) or a whole number
    >= 1 (a numpy integer too), never a bool or a text."""
    if workers is None:
        return None
    try:
        if isinstance(workers, bool):
            raise TypeError
        n = operator.index(workers)
    except TypeError:
        n = None
    if n is None or n < 1:
        raise ModelError(f"simulate_ensemble: workers must be None (every core, or "
                         f"OXYLINE_NUM_THREADS) or a whole number >= 1, got {workers!r}")
    return n


def _local(model: Model, patches: list[dict[str, Any]], index: Any, *, workers: int | None,
           output: Output, store: Any, progress: Any, overrides: Mapping[str, Any]) -> Any:
    from oxyline.ensemble.local import run_local

    collector = Collector(len(patches), output, model.vessel_names)
    writer = None
    on_variant = None
    if store is not None:
        from oxyline.ensemble.store import StoreWriter

        writer = StoreWriter(store, collector, patches, dataset_attrs(model, output), index)
        on_variant = writer.write
    finished = run_local(model, patches, collector, workers=workers, output=output,
                         progress=progress, overrides=overrides, on_variant=on_variant)
    return finish(model, patches, index, collector, output, writer, finished)
