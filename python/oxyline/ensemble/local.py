"""``simulate_ensemble`` on this machine: every variant on the core's rayon threads, the GIL
released; this thread converts and stores each variant as it finishes."""

from __future__ import annotations

import contextlib
import gc
import itertools
import json
import weakref
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

from oxyline import _core
from oxyline import memory as _memory
from oxyline.ensemble.collect import (
    ERROR_CHARS,
    Collector,
    Output,
    StatsBatch,
    heart_summary,
    stats_summary,
)
from oxyline.ensemble.patch import Patcher, Variant, patch_paths, traced
from oxyline.errors import ModelError, ResourceError, SimulationCancelled, core_errors
from oxyline.model import Model
from oxyline.monitor import Monitor
from oxyline.run import _heart_outputs, _result, _run_settings, _settings, cancellable, tqdm_class


def run_settings(model: Model, output: Output, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The run settings of ``model`` (``simulate``'s) with ``overrides``. A summary needs no
    segment output: it is not recorded unless asked for (the vessel values do not change)."""
    if output == "summary" and "segments" not in overrides:
        overrides = {**overrides, "segments": False}
    per_run = {"checkpoint", "checkpoint_every"} & set(overrides)
    if per_run:  # options of one simulate() run, not of an ensemble
        raise ModelError(f"simulate_ensemble: {', '.join(sorted(per_run))} is not an ensemble "
                         "option (Ctrl-C or cancel= stops an ensemble with the finished "
                         "variants)")
    return _settings(model, overrides)


class Feed:
    """The variants of one ``run_local`` call, prepared one at a time as the core's workers
    need them (:meth:`next`, called on this thread while the others run): the patched
    elements converted to canonical form, and the run settings. A variant whose values the
    model refuses is recorded as failed and skipped. ``numbers``: the number of each variant
    in the whole ensemble (a chunk of it runs on a cluster worker: every T-th variant)."""

    def __init__(self, patcher: Patcher, patches: Sequence[Mapping[str, Any]], output: Output,
                 overrides: Mapping[str, Any], collector: Collector, numbers: range,
                 on_skip: Callable[[int], None]) -> None:
        model = patcher.base
        self.patcher = patcher
        patcher.check_all(patches, numbers)  # unknown names raise before anything runs
        self.patches, self.output, self.overrides = patches, output, overrides
        #: the run settings of the variants that keep the base model's (most of them)
        self.base_settings = run_settings(model, output, overrides)
        self.collector, self.numbers, self.on_skip = collector, numbers, on_skip
        self.prepared: dict[int, tuple[Variant, dict[str, Any]]] = {}
        self._next = 0
        #: the memory a variant may take (max_memory, else the default share of the free):
        #: the core checks each variant's model against it as it assembles it
        self.memory_limit = _memory.limit(overrides.get("max_memory",
                                                        model.simulation.get("max_memory")),
                                          "simulate_ensemble: max_memory")

    def next(self) -> tuple[int, str | None, float, float, Any, Any] | None:
        while self._next < len(self.patches):
            i = self._next
            self._next += 1
            k = self.numbers[i]
            try:
                v = self.patcher.variant(self.patches[i], k)
                s = (self.base_settings if v.model is self.patcher.base else
                     run_settings(v.model, self.output, self.overrides))
            except ModelError as e:  # a ResourceError too
                # the patch's names were checked before the run (they raise); a value the
                # patch or the model refuses, or the memory it needs, fails only this variant
                kind = "resource" if isinstance(e, ResourceError) else "model"
                self.collector.fail(i, kind, traced(k, None, e)[:ERROR_CHARS])
                self.on_skip(i)
                continue
            self.prepared[i] = (v, s)
            return i, v.patch_json, s["period"], s["output_every"], v.vessels, v.outlets
        return None


class Base:
    """What every variant of one base model shares: its :class:`Patcher` and the core's
    parsed :class:`oxyline._core.Ensemble`."""

    def __init__(self, model: Model) -> None:
        self.patcher = Patcher(model)
        self.ensemble = _core.Ensemble(json.dumps(model.canonical, separators=(",", ":")))


#: the :class:`Base` of the models this process has seen as a cluster worker, by id(model)
_BASES: dict[int, tuple[Any, Base]] = {}


def cached_base(model: Model) -> Base:
    """The :class:`Base` of ``model``, built once per process for as long as the model lives.
    Only for models nobody changes in place: the copy a cluster worker holds of the model that
    was scattered to it (every task of the ensemble gets that same object)."""
    key = id(model)
    hit = _BASES.get(key)
    if hit is not None and hit[0]() is model:
        return hit[1]
    base = Base(model)
    # the callback holds the dict itself: a model that lives to the worker's shutdown is
    # released after the module's globals are gone
    _BASES[key] = (weakref.ref(model, lambda _, bases=_BASES: bases.pop(key, None)), base)
    return base


def run_local(model: Model, patches: Sequence[Mapping[str, Any]], collector: Collector, *,
              workers: int | None, output: Output, progress: Any,
              overrides: Mapping[str, Any],
              on_variant: Callable[[int], None] | None = None, first: int | range = 0,
              base: Base | None = None, cancel: Any = None,
              variant_timeout: float | None = None) -> bool:
    """Run every variant into ``collector``; ``on_variant(i)`` after each one is recorded.
    Returns False if Ctrl-C stopped the ensemble. ``first``: the number of the first variant
    in the whole ensemble, or the numbers of all of them (see :class:`Feed`). ``base``: the
    model's :class:`Base` if already built."""
    numbers = first if isinstance(first, range) else range(first, first + len(patches))
    base = base or Base(model)
    tick, close = _progress(progress, len(patches))

    def recorded(i: int) -> None:
        if on_variant is not None:
            on_variant(i)
        tick()

    feed = Feed(base.patcher, patches, output, overrides, collector, numbers, recorded)
    base_settings = feed.base_settings
    # chamber volumes and valve status, as in simulate(): the core returns them beside the
    # output columns (a patch changes values, not the model's structure)
    heart = _heart_outputs(model, base_settings)
    collector.heart = {"chamber": heart.get("chambers", []), "valve": heart.get("valves", [])}
    # summaries go to the collector in one pass at the end, unless a store writes each
    # variant as it finishes (it reads the collector's row) or it has heart outputs
    batch = StatsBatch(collector) if output == "summary" and on_variant is None \
        and not heart else None

    def done(i: int, raw: dict[str, Any] | None, layout: dict[str, Any] | None,
             kind: str | None, message: str | None) -> None:
        v, s = feed.prepared.pop(i)
        collector.facts(i, s["period"], raw)
        if kind is not None:  # "interrupted": stopped by Ctrl-C while it ran
            # a value the core refuses as it assembles the variant: traced to the patch
            paths = patch_paths(feed.patches[i]) if kind == "model" else None
            collector.fail(i, kind, traced(numbers[i], paths, str(message))[:ERROR_CHARS])
        else:
            try:
                assert raw is not None and layout is not None
                if batch is not None and batch.add(i, raw, layout):
                    recorded(i)
                    return
                _record(collector, i, output, v.model, s, raw, layout)
            except Exception as e:  # noqa: BLE001 - a user's output function fails its variant
                collector.fail(i, "output", f"variant {numbers[i]}: {type(e).__name__}: {e}"
                               [:ERROR_CHARS])
        recorded(i)

    # the settings of ``_settings`` that the core's ``Ensemble.run`` shares with
    # ``Network.simulate`` (each variant's period and output_every go with the variant)
    core = {k: base_settings[k] for k in _core.RUN_SETTINGS}
    ensemble = base.ensemble
    # Ctrl-C in the main thread sets every active run's event (oxyline.run): an ensemble in a
    # worker thread stops too; `poll` raises once it is set (checked ~10 times a second)
    try:
        with cancellable(cancel) as event, _old_objects_frozen(), \
                core_errors("simulate_ensemble"):

            def poll() -> None:
                if event.is_set():
                    raise SimulationCancelled("ensemble cancelled")

            # a summary's statistics are computed on the worker threads (see summary_values)
            return ensemble.run(feed.next, on_done=done, workers=workers,
                                summary=output == "summary", heart=bool(heart), poll=poll,
                                variant_timeout=variant_timeout,
                                max_memory=feed.memory_limit, **core)
    finally:
        if batch is not None:
            batch.flush()
        close()


def _record(collector: Collector, i: int, output: Output, model: Model,
            s: dict[str, Any], raw: dict[str, Any], layout: dict[str, Any]) -> None:
    """Put the outputs of finished variant ``i`` (its run ``raw``) into ``collector``."""
    # a summary without species is read from the core's column statistics; the bounds
    # monitor only concerns species, so it needs the Result only then
    values = stats_summary(raw, layout) if output == "summary" else None
    if values is None:
        result = _result(model, s, raw, _run_settings(s, raw), True, layout)
        values = collector.outputs(result, raw.get("column_stats"))
        collector.warn(i, bounds_findings(model, result))
    if output == "summary" and "chamber_volume" in raw:
        values = {**values, **heart_summary(raw["chamber_volume"], raw["valve_status"],
                                            raw["times"])}
    collector.put(i, values)


def bounds_findings(model: Model, result: Any) -> list[str]:
    """The physical-bounds monitor's findings in a variant's recorded species output
    (docs/physics.md §2.8): what ``simulate`` of the patched model would warn."""
    if not result.species:
        return []
    monitor = Monitor(model.transport_spec)
    monitor.update(result)
    return monitor.messages()


@contextlib.contextmanager
def _old_objects_frozen() -> Iterator[None]:
    """Keep the objects that exist before the run (the model, every patch: a population's
    patches are millions of small containers) out of the cyclic garbage collector's passes
    while this thread prepares and collects variants; the objects of each variant are still
    collected as usual. Left alone when the program freezes objects itself."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _progress(enabled: Any, total: int) -> tuple[Callable[[], None], Callable[[], None]]:
    """(tick, close): one tick per finished variant; ``enabled`` may be a callback
    ``f(done, total)``."""
    if callable(enabled):
        done = itertools.count(1)
        return (lambda: enabled(next(done), total)), (lambda: None)
    # the text bar in a notebook without ipywidgets (no TqdmWarning)
    tqdm = tqdm_class() if enabled else None
    if tqdm is None:
        return (lambda: None), (lambda: None)
    bar = tqdm(total=total, unit="variant", delay=1.0)
    return (lambda: bar.update(1)), bar.close
