"""``simulate_ensemble(..., client=...)``: the variants in chunks on a Dask cluster.

Each chunk is one Dask task that runs the local ensemble (every core of its worker, the
GIL released) and returns what it collected; this process merges the chunks as they finish
into the same dataset a local run builds (or writes them to the store). Dask does the
scheduling, transfer and fault handling: there is no pool or RPC of oxyline's own.
"""

from __future__ import annotations

import hashlib
import pickle
from collections.abc import Mapping, Sequence
from typing import Any

from oxyline.ensemble.collect import FACTS, Collector, Output
from oxyline.ensemble.patch import Patcher
from oxyline.model import Model

#: at most this many tasks per worker thread: enough to balance chunks of unequal cost
TASKS_PER_THREAD = 4
#: the fewest variants of a task beyond the first per thread: a task costs a round trip to the
#: scheduler, its patches and results in transit and a thread pool on its worker, so it
#: should carry seconds of work (256 variants: ~3 s of a 31-vessel tree, ~1 min of pwdb-116)
MIN_TASK_VARIANTS = 256


def run_chunk(model: Model, patches: Sequence[Mapping[str, Any]], numbers: range,
              output: Output, workers: int | None, overrides: Mapping[str, Any]) -> Collector:
    """One task: variants ``numbers`` of the ensemble (``patches``, in that order) on this
    worker's threads (``workers``, default the Dask worker's thread count)."""
    from oxyline.ensemble.local import cached_base, run_local

    if workers is None:
        try:
            from distributed import get_worker

            workers = get_worker().state.nthreads
        except (ImportError, ValueError):
            workers = None
    collector = Collector(len(patches), output, model.vessel_names)
    # the scattered model is the same object in every task on this worker: its base is
    # parsed and prepared once per worker, not once per task
    run_local(model, patches, collector, workers=workers, output=output, progress=False,
              overrides=overrides, first=numbers, base=cached_base(model))
    return collector


def _chunks(n: int, threads: int) -> list[range]:
    """The variants of each task: (nearly) equally many, a whole number of tasks per worker
    thread (equal chunks then finish together): one per thread, more only while each still
    holds :data:`MIN_TASK_VARIANTS`. A task takes every T-th variant (T tasks), not a block
    of neighbours: the variants of a sweep or a population are ordered by their parameters,
    and their cost follows them (a young PWDB subject runs 12-18 cycles to periodicity, an
    old one 6), so blocks of neighbours gave one worker most of the work (+26 % wall time on
    200 subjects over local threads, which take the variants one by one)."""
    threads = max(1, threads)
    per_thread = max(1, min(TASKS_PER_THREAD, n // (threads * MIN_TASK_VARIANTS)))
    tasks = max(1, min(n, threads * per_thread))
    return [range(j, n, tasks) for j in range(tasks)]


def _placement(nthreads: Mapping[str, int], tasks: int) -> list[str | None]:
    """The worker each of ``tasks`` chunks should run on: the workers' threads in turn (a
    worker of 2 threads gets twice the chunks of a worker of 1). Given to Dask as a loose
    restriction (``allow_other_workers``): a chunk still runs elsewhere if its worker goes.
    Left to itself the scheduler put both chunks of a small ensemble on one of 2 idle
    workers (both hold the scattered model, and a chunk's duration was unknown or tiny): the
    second chunk waited for the first or for work stealing 0.5-1.9 s later, the whole of the
    LocalCluster's +113 % on 64 tree variants."""
    slots = [addr for addr, n in sorted(nthreads.items()) for _ in range(max(1, n))]
    if not slots:
        return [None] * tasks
    return [slots[j % len(slots)] for j in range(tasks)]


def _merge(into: Collector, part: Collector, rows: range) -> None:
    """Copy the rows of a finished chunk (variants ``rows``) into the ensemble's collector."""
    for j, i in enumerate(rows):
        for name in FACTS:
            getattr(into, name)[i] = getattr(part, name)[j]
        if j in part.datasets:
            into.datasets[i] = part.datasets[j]
    for name, arr in part.values.items():
        dest = into.values.get(name)
        if dest is None:
            import numpy as np

            dest = into.values[name] = np.full((into.n, *arr.shape[1:]), np.nan)
        dest[rows.start:rows.stop:rows.step] = arr


#: the model last scattered to each client's workers: (its pickle's digest, the future)
_SCATTERED: dict[int, tuple[str, Any]] = {}


def _scattered(client: Any, model: Model) -> Any:
    """``model`` on every worker of ``client``: scattered once, and again only when another
    model (other pickled bytes) comes. Later ensembles of the same model skip the transfer,
    and the workers keep the same object, so its base is parsed and prepared once per worker
    process for all of them (``cached_base``), not once per ensemble. Holds one model per
    client on its workers."""
    digest = hashlib.sha256(pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL)).hexdigest()
    hit = _SCATTERED.get(id(client))
    if hit is not None and hit[0] == digest and hit[1].client is client \
            and hit[1].status == "finished":
        return hit[1]
    [future] = client.scatter([model], broadcast=True)
    _SCATTERED[id(client)] = (digest, future)
    return future


def run_on_client(client: Any, model: Model, patches: list[dict[str, Any]], index: Any, *,
                  output: Output, store: Any, progress: Any, workers: int | None,
                  overrides: Mapping[str, Any]) -> Any:
    from distributed import as_completed

    from oxyline.ensemble import _attrs, _finish
    from oxyline.ensemble.local import _progress, run_settings

    patcher = Patcher(model)
    for k, patch in enumerate(patches):  # unknown names fail here, before any task starts
        patcher.check(patch, k)
    run_settings(model, output, overrides)  # so do unknown settings
    collector = Collector(len(patches), output, model.vessel_names)
    writer = None
    if store is not None:
        from oxyline.ensemble.store import StoreWriter

        writer = StoreWriter(store, collector, patches, _attrs(model, output), index)
    nthreads = client.nthreads()
    threads = sum(nthreads.values()) or 1
    chunks = _chunks(len(patches), threads)
    shared = _scattered(client, model)
    futures = {client.submit(run_chunk, shared, [patches[i] for i in c], c, output,
                             workers, dict(overrides), pure=False,
                             workers=None if where is None else [where],
                             allow_other_workers=where is not None): c
               for c, where in zip(chunks, _placement(nthreads, len(chunks)), strict=True)}
    tick, close = _progress(progress, len(patches))
    finished = True
    try:
        for fut in as_completed(futures):
            rows = futures[fut]
            _merge(collector, fut.result(), rows)
            for i in rows:
                if writer is not None:
                    writer.write(i)
                tick()
    except KeyboardInterrupt:
        finished = False
        client.cancel(list(futures))
    finally:
        close()
    return _finish(model, patches, index, collector, output, writer, finished)
