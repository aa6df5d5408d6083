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

from oxyline.ensemble.collect import FACTS, Collector, Output, dataset_attrs, finish
from oxyline.ensemble.patch import Patcher
from oxyline.errors import ModelError
from oxyline.model import Model

#: tasks per worker thread of an ensemble that Dask balances (see :func:`_chunks`): the run
#: ends on a task's tail, so the smaller the tasks the shorter the idle tail
TASKS_PER_THREAD = 16
#: the fewest variants of a balanced ensemble's task. A task costs ~3 ms of a worker's CPU
#: besides its variants (its patches and results in transit, the chunk's collector; 64 tasks
#: of 1 tree variant: 0.78 s of worker CPU against 0.59 s as 2 tasks); the
#: scheduler's round trip is hidden as the next task is already on its worker. 8 variants:
#: ~70 ms of a 31-vessel tree, ~0.6 s of pwdb-116
MIN_TASK_VARIANTS = 8
#: Dask queues a task group on the scheduler only above 2 tasks per worker thread (its
#: "root-ish" rule, ``distributed.scheduler.Scheduler.is_rootish``); fewer are pinned
QUEUED_TASKS_PER_THREAD = 3


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
    """The variants of each task. A task takes every T-th variant (T tasks), not a block of
    neighbours: the variants of a sweep or a population are ordered by their parameters, and
    their cost follows them (a young PWDB subject needs more cycles to periodicity than an
    old one). A small ensemble gets one task per worker thread (:func:`_placement` pins
    them); a big one :data:`TASKS_PER_THREAD` per thread of at least
    :data:`MIN_TASK_VARIANTS` each, which Dask hands out as threads free up (:func:`_plan`):
    two static halves left one worker idle while the other finished its half, whenever its
    subjects or its share of a shared machine were slower (pwdb-200: +26 % median, -9 ...
    +49 %, over local threads, which take the variants one by one)."""
    threads = max(1, threads)
    per_thread = min(TASKS_PER_THREAD, n // (threads * MIN_TASK_VARIANTS))
    if per_thread < QUEUED_TASKS_PER_THREAD:
        per_thread = 1
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


def _plan(n: int, nthreads: Mapping[str, int]) -> tuple[list[range], list[str | None] | None]:
    """The chunks of an ensemble of ``n`` variants on workers of ``nthreads`` threads, and
    the worker each is pinned to, or None: Dask balances them. More tasks than 2 per thread,
    unrestricted and submitted in one graph, are "root-ish": the scheduler sends each worker
    only as many as it has threads (+ one, ``distributed.scheduler.worker-saturation`` 1.1)
    and keeps the rest queued, so a worker that finishes early takes the next task and the
    run no longer ends on one worker's half (Dask's scheduling-policies docs, "Avoid
    over-saturating workers"). Worker restrictions, even loose ones, exempt a task from that
    queue (``Scheduler.is_rootish``), so only the one-task-per-thread chunks of a small
    ensemble are pinned."""
    threads = sum(nthreads.values()) or 1
    chunks = _chunks(n, threads)
    if len(chunks) >= QUEUED_TASKS_PER_THREAD * threads:
        return chunks, None
    return chunks, _placement(nthreads, len(chunks))


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


#: Dask's retries of a task that raised (``retries=``). A task whose worker died (killed,
#: out of memory, lost node) is run again by the scheduler until it was on
#: ``allowed_failures + 1`` dying workers (``distributed.scheduler.allowed-failures``,
#: default 3), then fails with ``KilledWorker``; a chunk that fails so is split into one task
#: per variant, so that only a variant that kills its worker fails
RETRIES = 2


def _check_sendable(output: Output) -> None:
    """An output callable must reach the workers (pickled with cloudpickle, as Dask does)."""
    if not callable(output):
        return
    try:
        import cloudpickle

        cloudpickle.dumps(output)
    except Exception as exc:  # noqa: BLE001 - any pickling failure, named
        raise ModelError(f"simulate_ensemble: output {getattr(output, '__name__', output)!r} "
                         f"cannot be sent to the Dask workers ({type(exc).__name__}: {exc}); "
                         "use a module-level function of plain data") from None


#: seconds to wait for a restarted worker when every worker died (its nanny restarts it in
#: a few seconds; a cluster without nannies never does: then the ensemble stops with
#: Dask's TimeoutError)
WORKER_WAIT = 120.0

#: the model last scattered to each client's workers: (its pickle's digest, the future)
_SCATTERED: dict[int, tuple[str, Any]] = {}


def _scattered(client: Any, model: Model, *, again: bool = False) -> Any:
    """``model`` on every worker of ``client``: scattered once, and again only when another
    model (other pickled bytes) comes, or when ``again`` (its copies are known to be lost).
    Later ensembles of the same model skip the transfer, and the workers keep the same
    object, so its base is parsed and prepared once per worker process for all of them
    (``cached_base``), not once per ensemble. Holds one model per client on its workers."""
    digest = hashlib.sha256(pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL)).hexdigest()
    hit = _SCATTERED.get(id(client))
    if not again and hit is not None and hit[0] == digest and hit[1].client is client \
            and hit[1].status == "finished":
        return hit[1]
    [future] = client.scatter([model], broadcast=True)
    _SCATTERED[id(client)] = (digest, future)
    return future


class _Cancelled(Exception):
    """The ensemble's ``cancel`` event was set."""


def _watch(cancel: Any, client: Any, futures: Mapping[Any, range]) -> Any:
    """A thread that cancels the ensemble's tasks once ``cancel`` is set (checked every
    0.1 s), so that the wait for the next finished chunk ends at once; stopped with the
    event it returns."""
    import threading

    over = threading.Event()

    def watch() -> None:
        while not over.wait(0.1):
            if cancel.is_set():
                client.cancel(list(futures.copy()))  # a copy: the loop adds and pops
                return

    threading.Thread(target=watch, daemon=True, name="oxyline-ensemble-cancel").start()
    return over


def _cancelled(exc: BaseException) -> bool:
    """A chunk cancelled by Dask (its scattered model lost with the workers), not failed."""
    from concurrent.futures import CancelledError

    return isinstance(exc, CancelledError)


def _scatter_again(client: Any, model: Model) -> Any:
    """:func:`_scattered` once a worker is back: workers being restarted come and go while a
    dying one is still listed, so the scatter is tried again until it lands (at most
    :data:`WORKER_WAIT` seconds)."""
    import time

    deadline = time.monotonic() + WORKER_WAIT
    while True:
        try:
            client.wait_for_workers(1, timeout=max(1.0, deadline - time.monotonic()))
            return _scattered(client, model, again=True)
        except Exception:  # a worker that left mid-scatter (TimeoutError,
            # OSError, ValueError "Can not use replicate to delete data"): try again
            if time.monotonic() > deadline:
                raise


class _ClientRun:
    """One ensemble on a Dask client: the chunks sent, the failures sorted (a lost model sent
    again, a failed chunk split into single variants, a suspect variant run again alone),
    the parts merged into the collector."""

    def __init__(self, client: Any, model: Model, patches: list[dict[str, Any]],
                 output: Output, workers: int | None, overrides: Mapping[str, Any],
                 collector: Collector) -> None:
        self.client, self.model, self.patches = client, model, patches
        self.args = (output, workers, dict(overrides))
        self.collector = collector
        self.shared = _scattered(client, model)
        self.futures: dict[Any, range] = {}
        self.pending: Any = None
        #: times each chunk was sent again because the model it needs was lost with its
        #: workers
        self.resent: dict[range, int] = {}
        #: single variants whose worker died while others ran beside them: each runs again
        #: alone at the end (a task queued on a worker that another variant kills is counted
        #: as killed by Dask too), and fails only if it kills its worker alone
        self.suspects: list[range] = []
        self.alone: set[range] = set()
        #: times the model was scattered again, and that count when each chunk was last sent
        #: (a chunk cancelled on an older copy needs no new one)
        self.scatters = 0
        self.sent_with: dict[range, int] = {}

    def submit_all(self) -> None:
        """Every chunk, placed by :func:`_plan`."""
        chunks, where = _plan(len(self.patches), self.client.nthreads())
        self.sent_with = dict.fromkeys(chunks, self.scatters)
        if where is None:  # one graph: the scheduler queues the tasks and hands them out
            output, workers, overrides = self.args
            k = len(chunks)
            futures = self.client.map(run_chunk, [self.shared] * k,
                                      [[self.patches[i] for i in c] for c in chunks], chunks,
                                      [output] * k, [workers] * k, [dict(overrides)] * k,
                                      pure=False, retries=RETRIES)
            self.futures = dict(zip(futures, chunks, strict=True))
        else:
            self.futures = {self._submit(c, w): c for c, w in zip(chunks, where, strict=True)}

    def _submit(self, rows: range, worker: str | None = None) -> Any:
        """The task of the variants ``rows``, pinned loosely to ``worker`` if given."""
        output, workers, overrides = self.args
        return self.client.submit(run_chunk, self.shared, [self.patches[i] for i in rows],
                                  rows, output, workers, dict(overrides), pure=False,
                                  workers=None if worker is None else [worker],
                                  allow_other_workers=worker is not None, retries=RETRIES)

    def send(self, rows: range) -> None:
        again = self._submit(rows)
        self.futures[again] = rows
        self.sent_with[rows] = self.scatters
        self.pending.add(again)

    def failed(self, rows: range, exc: BaseException) -> bool:
        """Handle a chunk whose task failed; True when its variants are recorded as failed
        (False: they were sent again or set aside)."""
        stale = _cancelled(exc) and self.sent_with.get(rows) == self.scatters
        if self.shared.status != "finished" or stale:
            # every worker that held the model died: scatter again. A chunk cancelled by Dask
            # on the current copy says so too, and may arrive before the client has heard
            # that the model is lost (its future still "finished"): sent again on that stale
            # copy it would be cancelled again, until its retries were used up
            self.shared = _scatter_again(self.client, self.model)
            self.scatters += 1
        if _cancelled(exc) and self.resent.get(rows, 0) <= RETRIES:
            # cancelled by Dask for the lost model, not failed by its variants: sent again as
            # it was (to the restarted workers)
            self.resent[rows] = self.resent.get(rows, 0) + 1
            self.send(rows)
            return False
        if len(rows) > 1:
            # Dask's retries are used up: each variant of the chunk on its own task, so that
            # the healthy ones run and only the one that kills its worker fails
            for i in rows:
                self.send(range(i, i + 1))
            return False
        if rows not in self.alone:
            self.suspects.append(rows)
            return False
        self.collector.fail(rows.start, "worker", f"variant {rows.start}: its Dask worker "
                            "failed when it ran alone "
                            f"({type(exc).__name__}: {exc})"[:400])
        return True

    def collect(self, cancel: Any, done: Any) -> None:
        """Merge every chunk as it finishes (``done(i)`` per variant), then run the suspects
        one at a time."""
        from distributed import as_completed

        self.pending = as_completed(self.futures)
        while True:
            for fut in self.pending:
                rows = self.futures.pop(fut)
                if cancel is not None and cancel.is_set():
                    raise _Cancelled
                try:
                    part = fut.result()
                except Exception as exc:  # noqa: BLE001 - a worker lost (killed, out of memory)
                    if not self.failed(rows, exc):
                        continue
                    part = None
                if part is not None:
                    _merge(self.collector, part, rows)
                for i in rows:
                    done(i)
            if not self.suspects:
                break
            rows = self.suspects.pop(0)  # one at a time: nothing else runs beside it
            self.alone.add(rows)
            self.resent.pop(rows, None)
            self.send(rows)


def run_on_client(client: Any, model: Model, patches: list[dict[str, Any]], index: Any, *,
                  output: Output, store: Any, progress: Any, workers: int | None,
                  overrides: Mapping[str, Any], cancel: Any = None) -> Any:
    from oxyline.ensemble.local import _progress, run_settings

    Patcher(model).check_all(patches)  # unknown names fail here, before any task starts
    run_settings(model, output, overrides)  # so do unknown settings
    _check_sendable(output)
    collector = Collector(len(patches), output, model.vessel_names)
    writer = None
    if store is not None:
        from oxyline.ensemble.store import StoreWriter

        writer = StoreWriter(store, collector, patches, dataset_attrs(model, output), index)
    run = _ClientRun(client, model, patches, output, workers, overrides, collector)
    run.submit_all()
    tick, close = _progress(progress, len(patches))

    def done(i: int) -> None:
        if writer is not None:
            writer.write(i)
        tick()

    finished = True
    over = _watch(cancel, client, run.futures) if cancel is not None else None
    try:
        run.collect(cancel, done)
    except (KeyboardInterrupt, _Cancelled):
        finished = False
        client.cancel(list(run.futures))
    finally:
        if over is not None:
            over.set()
        close()
    return finish(model, patches, index, collector, output, writer, finished,
                  cancelled=cancel is not None and cancel.is_set())
