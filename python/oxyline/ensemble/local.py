"""``simulate_ensemble`` on this machine: every variant on the core's rayon threads, the GIL
released; this thread converts and stores each variant as it finishes."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from oxyline import _core
from oxyline.ensemble.collect import ERROR_CHARS, Collector, Output
from oxyline.ensemble.patch import Patcher, Variant
from oxyline.errors import ModelError
from oxyline.model import Model
from oxyline.run import _result, _run_settings, _settings

#: the settings of ``_settings`` that the core's ``Ensemble.run`` takes as they are
SHARED = ("cycles", "method", "rho_infty", "dt", "until_periodic", "max_cycles",
          "output_all_cycles", "start", "newton_atol", "max_iterations", "segments",
          "transport", "variables", "vessels")


def run_settings(model: Model, output: Output, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The run settings of ``model`` (``simulate``'s) with ``overrides``. A summary needs no
    segment output: it is not recorded unless asked for (the vessel values do not change)."""
    if output == "summary" and "segments" not in overrides:
        overrides = {**overrides, "segments": False}
    return _settings(model, overrides)


def prepare(patcher: Patcher, patches: Sequence[Mapping[str, Any]], output: Output,
            overrides: Mapping[str, Any], collector: Collector, first: int = 0,
            ) -> tuple[list[Variant | None], list[dict[str, Any] | None]]:
    """Every variant and its settings; a variant whose values the model refuses is recorded
    as failed (None). Unknown names raise. ``first``: the number of the first variant in the
    whole ensemble (a chunk of it runs on a cluster worker)."""
    variants: list[Variant | None] = []
    settings: list[dict[str, Any] | None] = []
    for i, patch in enumerate(patches):
        k = first + i
        try:
            v = patcher.variant(patch, k)
            s = run_settings(v.model, output, overrides)
        except ModelError as e:
            if str(e).startswith(f"variant {k}: "):
                raise  # an unknown vessel, node or property: a mistake in the patches
            collector.fail(i, "model", f"variant {k}: {e}"[:ERROR_CHARS])
            variants.append(None)
            settings.append(None)
            continue
        variants.append(v)
        settings.append(s)
    return variants, settings


def run_local(model: Model, patches: Sequence[Mapping[str, Any]], collector: Collector, *,
              workers: int | None, output: Output, progress: Any,
              overrides: Mapping[str, Any],
              on_variant: Callable[[int], None] | None = None, first: int = 0) -> bool:
    """Run every variant into ``collector``; ``on_variant(i)`` after each one is recorded.
    Returns False if Ctrl-C stopped the ensemble. ``first``: see :func:`prepare`."""
    base_settings = run_settings(model, output, overrides)
    variants, settings = prepare(Patcher(model), patches, output, overrides, collector, first)
    runnable = [i for i, v in enumerate(variants) if v is not None]
    for i, v in enumerate(variants):
        if v is None and on_variant is not None:
            on_variant(i)
    tick, close = _progress(progress, len(patches))
    for _ in range(len(patches) - len(runnable)):
        tick()

    def done(j: int, raw: dict[str, Any] | None, layout: dict[str, Any] | None,
             kind: str | None, message: str | None) -> None:
        i = runnable[j]
        v, s = variants[i], settings[i]
        assert v is not None and s is not None
        collector.facts(i, s["period"], raw)
        if kind is not None:  # "interrupted": stopped by Ctrl-C while it ran
            collector.fail(i, kind, f"variant {first + i}: {message}"[:ERROR_CHARS])
        else:
            try:
                assert raw is not None and layout is not None
                result = _result(v.model, s, raw, _run_settings(s, raw), True, layout)
                collector.put(i, collector.outputs(result))
            except Exception as e:  # noqa: BLE001 - a user's output function fails its variant
                collector.fail(i, "output", f"variant {first + i}: {type(e).__name__}: {e}"
                               [:ERROR_CHARS])
        if on_variant is not None:
            on_variant(i)
        tick()

    core = {k: base_settings[k] for k in SHARED}
    ensemble = _core.Ensemble(json.dumps(model.canonical, separators=(",", ":")))
    try:
        return ensemble.run(
            [variants[i].patch_json for i in runnable],  # type: ignore[union-attr]
            [settings[i]["period"] for i in runnable],  # type: ignore[index]
            [settings[i]["output_every"] for i in runnable],  # type: ignore[index]
            on_done=done, workers=workers, **core)
    finally:
        close()


def _progress(enabled: Any, total: int) -> tuple[Callable[[], None], Callable[[], None]]:
    """(tick, close): one tick per finished variant; ``enabled`` may be a callback
    ``f(done, total)``."""
    count = [0]
    if callable(enabled):
        def tick() -> None:
            count[0] += 1
            enabled(count[0], total)
        return tick, lambda: None
    if not enabled:
        return (lambda: None), (lambda: None)
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return (lambda: None), (lambda: None)
    bar = tqdm(total=total, unit="variant", delay=1.0)
    return (lambda: bar.update(1)), bar.close
