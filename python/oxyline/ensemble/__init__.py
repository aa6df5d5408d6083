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

from oxyline import memory as _memory
from oxyline.ensemble.collect import (
    STATUS,
    Collector,
    Output,
    check_output,
    dataset_attrs,
    finish,
)
from oxyline.ensemble.local import run_local, run_settings
from oxyline.ensemble.patch import apply_patch, as_patches
from oxyline.errors import ModelError, ResourceError
from oxyline.loader import load_model
from oxyline.model import Model
from oxyline.run import _output_size

__all__ = ["STATUS", "apply_patch", "simulate_ensemble"]


def simulate_ensemble(model: Model | str | os.PathLike[str] | Mapping[str, Any], variants: Any,
                      *, workers: int | None = None, client: Any = None,
                      output: Output = "summary", store: str | os.PathLike[str] | None = None,
                      progress: Any = True, cancel: Any = None,
                      variant_timeout: float | None = None, **overrides: Any) -> Any:
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

    ``cancel`` (a ``threading.Event``): setting it stops the ensemble (seen within 0.1 s: no
    more variants start, the running ones stop at their next check; on a Dask ``client`` its
    tasks are cancelled) with :class:`~oxyline.SimulationCancelled`; Ctrl-C also stops an ensemble running in a worker
    thread. ``variant_timeout`` (s of wall time): a variant running longer is stopped and
    fails with a solver error naming ``variant_timeout``; the others run on. ``output="full"``
    is estimated before any variant runs: above ``max_memory`` it is refused with
    :class:`~oxyline.ResourceError`.

    A variant that fails has ``status != 0`` and its ``error``; it never stops the others.
    Ctrl-C raises :class:`~oxyline.SimulationInterrupted` with the dataset of the finished
    variants as ``exc.result`` (``status`` -1: not run, 5: interrupted), as a cancel does
    with :class:`~oxyline.SimulationCancelled`.

    >>> import oxyline
    >>> ds = oxyline.simulate_ensemble("bifurcation", [{}, {"vessels": {"parent": {"radius":
    ...     0.004}}}], cycles=2, progress=False)
    >>> ds.status.values.tolist(), ds.pressure_in_mean.dims
    ([0, 0], ('variant', 'vessel'))
    """
    check_output(output)
    if overrides.get("estimate_space_error"):  # before: accepted and silently not computed
        raise ModelError("simulate_ensemble: estimate_space_error is an estimate of one model's "
                         "segmentation, not computed per variant; call "
                         "oxyline.estimate_space_error on the variants of interest")
    for key in ("estimate_time_error", "meet_rtol"):
        if overrides.get(key):  # the variants' runs do not compute it: refused, not ignored
            raise ModelError(f"simulate_ensemble: {key} is not computed per variant; call "
                             f"oxyline.simulate(..., {key}=True) on the variants of interest")
    workers = _workers(workers)
    control = _control(cancel, variant_timeout, client)
    model = load_model(model)
    _refuse_model_estimates(model, overrides)
    patches, index = as_patches(variants, model)
    if output == "full" and store is None:
        _check_full_output(model, len(patches), overrides)
    if client is not None:
        from oxyline.ensemble.cluster import run_on_client

        return run_on_client(client, model, patches, index, output=output, store=store,
                             progress=progress, workers=workers, overrides=overrides,
                             cancel=control["cancel"])
    return _local(model, patches, index, workers=workers, output=output, store=store,
                  progress=progress, overrides=overrides, control=control)


def _refuse_model_estimates(model: Model, overrides: Mapping[str, Any]) -> None:
    """The time-error estimates a model file asks for (``simulation: {estimate_time_error:
    true}`` or ``meet_rtol``) are estimates of one run, not computed per variant: refused by
    name instead of silently left out; the keyword ``False`` runs the variants without."""
    from oxyline.run import _resolve

    timed = _resolve(model, overrides)[3]
    asked = {"estimate_time_error": bool(timed) and timed != "meet", "meet_rtol": timed == "meet"}
    for key in (k for k, on in asked.items() if on):
        raise ModelError(f"simulate_ensemble: {key} (asked by the model's simulation section) "
                         "is not computed per variant; pass "
                         f"{key}=False to run the variants without it, and call "
                         f"oxyline.simulate(..., {key}=True) on the variants of interest")


def _control(cancel: Any, variant_timeout: Any, client: Any) -> dict[str, Any]:
    """``cancel`` and ``variant_timeout`` checked (``variant_timeout`` for ensembles on this
    machine; a Dask ensemble's cancel cancels its tasks)."""
    if client is not None and variant_timeout is not None:
        raise ModelError("simulate_ensemble: variant_timeout is for ensembles on this machine; "
                         "give the Dask workers their own limits (e.g. the nanny's memory "
                         "limit) or cancel= to stop the ensemble")
    if cancel is not None and not callable(getattr(cancel, "is_set", None)):
        raise ModelError(f"simulate_ensemble: cancel must be a threading.Event (anything with "
                         f"is_set()), got {cancel!r:.60}")
    if variant_timeout is not None:
        # (0, 1e9] holds no NaN, no infinity and no integer beyond a float
        if isinstance(variant_timeout, bool) or not isinstance(variant_timeout, (int, float)) \
                or not 0 < variant_timeout <= 1e9:
            raise ModelError(f"simulate_ensemble: variant_timeout must be seconds of wall time "
                             f"(a number > 0 and <= 1e9), got {variant_timeout!r:.40}")
        variant_timeout = float(variant_timeout)
    return {"cancel": cancel, "variant_timeout": variant_timeout}


def _check_full_output(model: Model, n: int, overrides: Mapping[str, Any]) -> None:
    """Before any variant runs: the full output of ``n`` variants (each the size of the base
    model's; a patch changes values, not the columns) must fit into the memory allowed, else
    :class:`~oxyline.ResourceError` with the estimate and what to change."""
    need, rows, cols = _output_size(model, run_settings(model, "full", overrides))
    where = "simulate_ensemble: max_memory"
    limit = _memory.limit(overrides.get("max_memory", model.simulation.get("max_memory")), where)
    if limit is not None and need * n > limit:
        raise ResourceError(
            f"simulate_ensemble: output='full' of {n} variants ({rows} rows x {cols} columns "
            f"each) needs about {_memory.human(need * n)} of memory (estimate), above "
            f"max_memory = {_memory.human(limit)}; use output='summary' or a callable, write "
            "the variants to a store (store=...), output fewer rows or columns, or raise "
            "max_memory")


def _workers(workers: Any) -> int | None:
    """``workers`` checked: None (``OXYLINE_NUM_THREADS`` or every core) or a whole number
    >= 1 (a numpy integer too), never a bool or a text."""
    if workers is None:
        return None
    try:
        n = 0 if isinstance(workers, bool) else operator.index(workers)
    except TypeError:
        n = 0
    if n < 1:
        raise ModelError(f"simulate_ensemble: workers must be None (every core, or "
                         f"OXYLINE_NUM_THREADS) or a whole number >= 1, got {workers!r}")
    return n


def _local(model: Model, patches: list[dict[str, Any]], index: Any, *, workers: int | None,
           output: Output, store: Any, progress: Any, overrides: Mapping[str, Any],
           control: Mapping[str, Any]) -> Any:
    collector = Collector(len(patches), output, model.vessel_names)
    writer = None
    on_variant = None
    if store is not None:
        from oxyline.ensemble.store import StoreWriter

        writer = StoreWriter(store, collector, patches, dataset_attrs(model, output), index)
        on_variant = writer.write
    finished = run_local(model, patches, collector, workers=workers, output=output,
                         progress=progress, overrides=overrides, on_variant=on_variant,
                         **control)
    cancel = control.get("cancel")
    return finish(model, patches, index, collector, output, writer, finished,
                  cancelled=cancel is not None and cancel.is_set())
