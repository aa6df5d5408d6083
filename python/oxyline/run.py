"""``oxyline.simulate``: resolve run settings, call the core with the GIL released, wrap the
arrays in a :class:`~oxyline.result.Result`."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import threading
import warnings
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from oxyline import _core
from oxyline import checkpoint as _checkpoint
from oxyline import memory as _memory
from oxyline.errors import (
    CheckpointError,
    ModelError,
    OutputError,
    OutputSizeWarning,
    PeriodicityWarning,
    ResourceError,
    SimulationCancelled,
    SimulationInterrupted,
    core_errors,
)
from oxyline.io.atomic import same_file
from oxyline.io.results import ZarrAppender, dataset, step_history
from oxyline.large_output import SummaryStream
from oxyline.loader import load_model
from oxyline.model import Model
from oxyline.monitor import Monitor
from oxyline.monitor import warn as _warn_bounds
from oxyline.options import output_names, output_vessels
from oxyline.result import (
    BALANCE,
    MAX_MODEL_JSON,
    SEGMENT_VARIABLES,
    SPECIES_SEGMENT,
    Result,
    SpeciesResult,
    TissueResult,
)
from oxyline.time_error import (
    FACTOR,
    FROM_LAST_CYCLE,
    FROM_LAST_CYCLE_EXPLICIT,
    FROM_WHOLE_RUN,
    SAME_STEPS,
    TimeErrorEstimate,
    accumulated,
    record_estimate,
)
from oxyline.time_error import (
    FILE_PREFIX as TIME_ERROR_PREFIX,
)

if TYPE_CHECKING:  # Unpack is typing's from Python 3.11
    from typing_extensions import Unpack

    from oxyline.options import SimulateOptions

ProgressCallback = Callable[[float, float], None]


#: the keywords of :func:`simulate` (the core's run-settings schema)
OPTIONS = frozenset(_core.OPTIONS)


def _settings(model: Model, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The run settings of ``model`` with ``overrides``, each checked like the model itself by
    the core's schema: a :class:`ModelError` names the setting, where it came from and the
    value (``progress`` too: a flag or a callback). The output selection is Python's."""
    return _resolve(model, overrides)[0]


def _resolve(model: Model, overrides: Mapping[str, Any]
             ) -> tuple[dict[str, Any], bool, bool, bool | str]:
    """:func:`_settings`, whether its ``rtol`` is the default one (neither ``rtol`` nor a
    fixed ``dt`` given: the default run is error-controlled), ``estimate_space_error`` (a
    refinement after the run, not a setting of the core's run) and ``estimate_time_error``
    (the core's second integration of the last cycle, asked by :func:`simulate`; ``"meet"``
    with ``meet_rtol``)."""
    s = _core.resolve_settings(model.simulation, dict(overrides), model.period)
    default = bool(s.pop("rtol_default"))
    space = bool(s.pop("estimate_space_error"))
    timed = bool(s.pop("estimate_time_error"))
    if s.pop("meet_rtol"):
        timed = "meet"  # (the estimate, then the runs it asks for: `_meet_rtol`)
    out = dict(model.simulation.get("output", {}) or {})
    s["variables"] = output_names(overrides.get("variables", out.get("variables")), "variables")
    # no selection: the model's default (every vessel but structured-tree ones); "all": all
    vessels = overrides.get("vessels", out.get("vessels"))
    s["vessels"] = model.default_output_vessels if vessels is None else output_vessels(vessels)
    return s, default, space, timed


#: Above this many segments an in-memory run without a ``variables`` selection records the
#: large-model default below instead of every variable (at ~1e6 segments every vessel
#: variable every 10 ms alone is 1.8 kB per segment, more than a 3 GB budget leaves after the
#: network and the run; benches/results.md, "Large-model default output").
LARGE_MODEL_SEGMENTS = 500_000
#: The large-model default: the vessel's inflow end (pressure_in; in a tree pressure_out is
#: the children's pressure_in), both flows, the outflow concentration and the wall flux.
LARGE_MODEL_VARIABLES = ("pressure_in", "flow_in", "flow_out")
LARGE_MODEL_SPECIES_VARIABLES = ("concentration_out", "wall_flux")
#: ... and, only when segment output is asked for explicitly, these segment variables.
LARGE_MODEL_SEGMENT_VARIABLES = ("segment_pressure_in", "segment_flow")
LARGE_MODEL_SPECIES_SEGMENT_VARIABLES = ("segment_concentration", "segment_wall_flux")


def _large_model_output(model: Model, s: dict[str, Any], overrides: Mapping[str, Any]) -> bool:
    """Apply the large-model default output to the settings ``s`` of an in-memory run of a
    model above :data:`LARGE_MODEL_SEGMENTS` that selects no ``variables`` (simulate keyword or
    model ``simulation: output:``): fewer vessel variables and, unless ``segments`` is given,
    no segment output, said in one :class:`OutputSizeWarning`. ``variables="all"`` keeps
    everything. Smaller models keep the complete default. True when the run is to be
    summarized (:mod:`oxyline.large_output`): neither ``segments`` nor ``vessels`` given, no
    tissue wall."""
    out = model.simulation.get("output") or {}
    if "variables" in overrides or "variables" in out:
        return False
    segments = int(model.network.summary()["segments"])
    if segments <= LARGE_MODEL_SEGMENTS:
        return False
    species = model.transport_spec is not None
    chosen = list(LARGE_MODEL_VARIABLES) + (list(LARGE_MODEL_SPECIES_VARIABLES) if species else [])
    if "segments" not in overrides and "segments" not in out:
        s["segments"] = False
    if s["segments"]:
        chosen += LARGE_MODEL_SEGMENT_VARIABLES
        chosen += LARGE_MODEL_SPECIES_SEGMENT_VARIABLES if species else ()
    s["variables"] = chosen
    lay = _output_layout(model, s).get("transport") or {}
    summarize = not s["segments"] and "vessels" not in overrides and "vessels" not in out \
        and not lay.get("tissue_columns")
    what = ("per-vessel mean, min and max (result.summary()) of " if summarize else "") \
        + ", ".join(chosen)
    inlets = " and the time series of the inlet vessels" if summarize else ""
    warnings.warn(f"{segments} segments (> {LARGE_MODEL_SEGMENTS}): recording only "
                  f"{what}{inlets}{'' if s['segments'] else ' (no segment output)'}; "
                  "variables='all' (and segments=True) records everything",
                  OutputSizeWarning, stacklevel=4)
    return summarize


def _output_layout(model: Model, s: Mapping[str, Any]) -> dict[str, Any]:
    """``model.network.output_layout`` of the selection of settings ``s`` (a fresh top-level
    dict: callers pop and set keys). The core resolves a selection against every vessel's
    name (~2 s per million vessels): a run asks for the same layout up to five times (the
    large-model default, the output's size, the summary stream, the result), so the last
    selection's layout is kept on the model. The layout lists the output vessels only (a
    structured tree's vessels are not output by default), so it is small beside the model."""
    sel = {k: s[k] for k in ("variables", "vessels", "segments")}  # the core's keywords
    key = tuple((k, tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in sel.items())
    network = model.network
    cached = model.__dict__.get("_layout_cache")
    if cached is None or cached[0] is not network or cached[1] != key:
        cached = (network, key, network.output_layout(**sel))
        model.__dict__["_layout_cache"] = cached
    layout = dict(cached[2])
    if isinstance(layout.get("transport"), dict):
        layout["transport"] = dict(layout["transport"])
    return layout


class _CycleProgress:
    """Progress in cardiac cycles, never backwards, counting N for a run of N cycles. A
    transport model whose closures need the cycle-mean flow runs a flow-only pass over the
    same cycles first, then the coupled pass from t = 0 again (docs/physics.md §3.1): the
    flow-only pass is shown in the bar's description and the count is the coupled pass's (it
    used to add both and count 2N). A run ``until_periodic`` has no known end: it shows the
    cycles done and its stopping rule instead of a percentage that would stop at a few
    percent of ``max_cycles``."""

    def __init__(self, bar: Any, period: float, open_ended: bool, passes: int = 1) -> None:
        self.bar, self.period, self.open_ended = bar, period, open_ended
        self.pass_left = passes - 1  # passes before the one that is counted
        self.last = 0.0

    def __call__(self, t: float, t_end: float) -> None:
        if t < self.last and self.pass_left > 0:  # the counted pass starts from 0 again
            self.pass_left -= 1
            self.bar.set_description("run", refresh=False)
        self.last = t
        if self.pass_left > 0:
            self.bar.set_description(f"run (flow-only pass {min(t, t_end) / self.period:.1f}/"
                                     f"{t_end / self.period:.4g} cycles first)", refresh=False)
            self.bar.refresh()
            return
        if not self.open_ended:
            self.bar.total = round(t_end / self.period, 2)
        self.bar.n = max(self.bar.n, round(min(t, t_end) / self.period, 2))
        self.bar.refresh()

    def finish(self, cycles_run: int) -> None:
        """The count at the end of the run (the core reports every few hundred steps)."""
        self.bar.set_description("run", refresh=False)
        self.bar.n = round(float(cycles_run), 2)
        if not self.open_ended:
            self.bar.total = self.bar.n
        self.bar.refresh()


def tqdm_class() -> Any:
    """The progress bar class: tqdm's notebook widget in Jupyter when ipywidgets is installed,
    its text bar otherwise (``tqdm.auto`` in a notebook without ipywidgets warns "IProgress not
    found" on every run); None without tqdm."""
    import sys

    try:
        from tqdm.std import tqdm
    except ImportError:
        return None
    if "ipykernel" in sys.modules:
        try:
            import ipywidgets  # noqa: F401
            from tqdm.notebook import tqdm as notebook_tqdm
        except ImportError:
            return tqdm
        return notebook_tqdm
    return tqdm


def _progress_bar(enabled: bool | ProgressCallback | None,
                  s: Mapping[str, Any] | None = None, passes: int = 1) -> tuple[Any, Any]:
    if callable(enabled):
        return enabled, None
    if not enabled:
        return None, None
    tqdm = tqdm_class()
    if tqdm is None:
        return None, None
    period = float(s["period"]) if s else 1.0
    until = s.get("until_periodic") if s else None
    if until is not None:
        fmt = ("{desc}: {n:.2f} cycles simulated [{elapsed}, {rate_fmt}] until the "
               f"cycle-to-cycle change < {until:g} (at least {s['cycles']}, at most "
               f"{s['max_cycles']} cycles)")
    else:
        fmt = ("{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} cycles simulated "
               "[{elapsed}<{remaining}]")
    bar = tqdm(total=None if until is not None else 1.0, unit="cycle", delay=1.0, desc="run",
               bar_format=fmt)
    return _CycleProgress(bar, period, until is not None, passes), bar


def _species_results(model: Model, raw: Mapping[str, Any], layout: Mapping[str, Any],
                     empty_segments: bool) -> dict[str, SpeciesResult]:
    """Species results of output rows; ``empty_segments``: no segment output at all, every
    variable (the segment arrays exist and are empty)."""
    tr = raw.get("transport")
    lay = layout.get("transport")
    if tr is None or lay is None:
        return {}
    nv = len(layout["vessels"])
    ns = int(sum(lay["segment_count"]))
    kv, ks = len(lay["vessel_variables"]), len(lay["segment_variables"])
    cols = lay["columns_per_species"]
    seg_vars = tuple(n.removeprefix("segment_") for n in lay["segment_variables"])
    if empty_segments:
        seg_vars, ks = SPECIES_SEGMENT, len(SPECIES_SEGMENT)
    data = tr["data"]
    nt = data.shape[0]
    if nt == 0:  # a run stopped before its first row: no rows, but the columns of the layout
        data = data.reshape(0, len(tr["species"]) * cols)
    out: dict[str, SpeciesResult] = {}
    ox = model.transport.get("oxygen")
    for k, name in enumerate(tr["species"]):
        vessel, segment, balance, tail = _blocks(data[:, k * cols:(k + 1) * cols], nv, kv, ns,
                                                 ks, len(BALANCE))
        out[name] = SpeciesResult(
            name=name, vessel_data=vessel, segment_data=segment, balance_data=balance,
            tissue=_tissue_views(tail, lay), initial_stored=float(tr["initial_stored"][k]),
            po2_per_concentration=(1.0 / model.transport["solubility"]) if name == ox else None,
            vessel_variables=tuple(lay["vessel_variables"]), segment_variables=seg_vars)
    return out


def _blocks(columns: np.ndarray, nv: int, kv: int, ns: int, ks: int, nb: int | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Views of a (time, column) block laid out as the core writes a species' (or its tissue
    wall's) columns: (time, vessel, kv), (time, segment, ks), the next ``nb`` columns (the
    balance; all the rest when None) and the columns after them."""
    nt, a, b = columns.shape[0], nv * kv, nv * kv + ns * ks
    c = columns.shape[1] if nb is None else b + nb
    return (columns[:, :a].reshape(nt, nv, kv), columns[:, a:b].reshape(nt, ns, ks),
            columns[:, b:c], columns[:, c:])


def _tissue_views(tail: np.ndarray, lay: Mapping[str, Any]) -> TissueResult | None:
    """The tissue-wall columns of one species block (views), or None without a tissue wall
    (or for a species without one: its columns are NaN)."""
    if not lay.get("tissue_columns") or np.isnan(tail[:, -4:]).all():
        return None
    # four variables per vessel and per segment (TISSUE_VESSEL, TISSUE_SEGMENT)
    vessel, segment, balance, _ = _blocks(tail, len(lay["tissue_vessels"]), 4,
                                          int(sum(lay["tissue_segment_count"])), 4)
    return TissueResult(vessels=list(lay["tissue_vessels"]),
                        segment_count=list(lay["tissue_segment_count"]),
                        vessel_data=vessel, segment_data=segment, balance_data=balance)


def _result(model: Model, s: Mapping[str, Any], raw: Mapping[str, Any],
            settings: dict[str, Any], complete: bool,
            layout: dict[str, Any] | None = None) -> Result:
    """A :class:`Result` of output rows in the core's layout (a whole run, or one chunk);
    ``layout``: the run's output layout if not the model network's (an ensemble variant)."""
    if layout is None:
        layout = _output_layout(model, s)
    if not s["transport"]:
        layout.pop("transport", None)
    empty_segments = not s["segments"] and s["variables"] is None
    if empty_segments:
        # no segments, every variable: the segment arrays exist and are empty, as they were
        # before output selection
        layout["segment_variables"] = list(SEGMENT_VARIABLES)
    return Result(
        model_name=model.name, vessels=list(layout["vessels"]), time=raw["times"],
        data=raw["data"], segment_count=list(layout["segment_count"]),
        segment_position=layout["segment_position"],
        settings=settings, complete=complete,
        species=_species_results(model, raw, layout, empty_segments), oxygen=model.transport.get("oxygen"),
        vessel_variables=tuple(layout["vessel_variables"]),
        segment_variables=tuple(layout["segment_variables"]),
        model_json=_model_json(model),
        # the heart outputs the core returned beside the columns (run with ``heart``)
        chamber_volume=dict(raw.get("chamber_volume", {})),
        valve_status=dict(raw.get("valve_status", {})),
    )


def _model_json(model: Model) -> str | None:
    """The model's native description (SI) as compact JSON for the result, or None when it is
    longer than :data:`~oxyline.result.MAX_MODEL_JSON` characters or not JSON (numpy arrays
    are written as lists). A model of more vessels than that may hold (> 50 characters a
    vessel) is not read: a large model's ``source`` is unpacked anew on each read
    (:data:`oxyline.model.PACKED_SOURCE_SEGMENTS`)."""
    names = model._names
    if names is not None and len(names) > MAX_MODEL_JSON // 50:
        return None
    source = model.source
    if not source or len(source.get("vessels", ())) > MAX_MODEL_JSON // 50:
        return None
    try:
        text = json.dumps(source, separators=(",", ":"), default=_checkpoint.json_default)
    except (TypeError, ValueError):
        return None
    return text if len(text) <= MAX_MODEL_JSON else None


def segmentation_facts(model: Model) -> dict[str, Any]:
    """How the model's vessels were cut (recorded with a result, printed by the CLI):
    ``segments_total``, ``segments_auto`` (those of vessels cut by the ``auto`` rule, the
    default where a vessel states no ``segments`` and the model no ``max_length``),
    ``segmentation`` ("auto", "explicit" or "auto+explicit") and the rule's
    ``segmentation_rtol`` (None when no vessel is cut by it)."""
    return _core.segmentation_facts(model.network.summary())


def _run_settings(s: Mapping[str, Any], raw: Mapping[str, Any] | None,
                  valves: bool = False) -> dict[str, Any]:
    """The settings recorded with a result (the core's schema, ``oxyline_core::run::facts``):
    the requested ones and how the steps were chosen (``step_control``, also the NetCDF
    attribute ``solver_step_control``) and, after the run (``raw``), its facts; ``valves``: the
    circuit has valves, whose switches an error-controlled run locates as events."""
    return _core.run_facts(s, raw, valves)


def _warn_not_periodic(name: str, s: Mapping[str, Any], complete: bool) -> None:
    """Say so when a run ``until_periodic`` ended at ``max_cycles`` above its tolerance
    (settings ``s`` of the result)."""
    if s.get("periodic_reached", True) or not complete:
        return
    warnings.warn(f"{name}: not periodic after {s['cycles_run']} cycles "
                  f"(max_cycles): the cycle-to-cycle change {s['periodic_error']:.2e} is above "
                  f"until_periodic = {s['until_periodic']:g}; raise max_cycles or start "
                  "closer to the periodic state (start='periodic')", PeriodicityWarning,
                  stacklevel=4)


# The cancel events of the runs in progress (any thread): Ctrl-C sets them all (see
# `_cancel_runs_on_ctrl_c`). A list, not a set: one event may be shared by several runs.
_ACTIVE: list[Any] = []
_ACTIVE_LOCK = threading.Lock()


def _cancel_runs_on_ctrl_c() -> None:
    """From the main thread, once: wrap Python's default SIGINT handler so that Ctrl-C also
    sets the cancel event of every run in progress, so runs in worker threads (which never
    see the KeyboardInterrupt) stop too, each with its partial result. The main thread gets
    its KeyboardInterrupt as before. A handler of the user's own is left alone."""
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return

    def cancel_runs_then_interrupt(signum: int, frame: Any) -> None:
        with _ACTIVE_LOCK:
            events = list(_ACTIVE)
        for event in events:
            event.set()
        signal.default_int_handler(signum, frame)

    signal.signal(signal.SIGINT, cancel_runs_then_interrupt)


@contextlib.contextmanager
def cancellable(cancel: Any = None) -> Iterator[Any]:
    """The cancel event of a run (``cancel``, or a new ``threading.Event``), registered for
    Ctrl-C while the block runs: the main thread's SIGINT sets it, so a run in a worker thread
    stops too."""
    event = threading.Event() if cancel is None else cancel
    _cancel_runs_on_ctrl_c()
    with _ACTIVE_LOCK:
        _ACTIVE.append(event)
    try:
        yield event
    finally:
        with _ACTIVE_LOCK:
            _ACTIVE.remove(event)


def _run(model: Model, s: Mapping[str, Any], progress: Any, cancel: Any = None,
         **core: Any) -> dict[str, Any]:
    """The core's raw output of a run with settings ``s``, with a progress bar if asked for.
    The run stops with :class:`SimulationCancelled` once ``cancel`` (a ``threading.Event``)
    is set; it is checked with the progress, every few hundred steps and at most every 0.1 s
    (at once after a progress callback that set it)."""
    callback, bar = _progress_bar(progress, s, model.network.passes()
                                  if progress and not callable(progress) else 1)
    try:
        with cancellable(cancel) as event:

            def check(t: float, t_end: float) -> None:
                if callback is not None:
                    callback(t, t_end)
                if event.is_set():
                    raise SimulationCancelled("run cancelled")

            with core_errors(f"simulate '{model.name}'"):
                raw = model.network.simulate(progress=check, **s, **core)
        if isinstance(callback, _CycleProgress) and "error" not in raw:
            callback.finish(int(raw["cycles_run"]))
        return raw
    finally:
        if bar is not None:
            bar.close()


def _raise_run_error(raw: Mapping[str, Any], partial: Any) -> None:
    """Re-raise the error of a run that stopped early, with the partial output attached."""
    if "error" not in raw:
        return
    err = raw["error"]
    if raw["error_kind"] == "interrupted" and isinstance(err, KeyboardInterrupt):
        # Ctrl-C, a cancel event, SIGTERM (the CLI): the same class, with the partial result
        cls = type(err) if isinstance(err, SimulationInterrupted) else SimulationInterrupted
        what = str(err) if isinstance(err, SimulationInterrupted) else "run interrupted"
        if raw.get("max_buffered_rows", 1) == 0:  # no row: stopped in the step estimate or
            # the mean-flow pass
            raise cls(f"{what} before its first output row (in the step estimate or the "
                      "flow-only pass that measures the mean flows); exc.result is the "
                      "result with no rows (complete=False)", partial) from None
        raise cls(f"{what} after {raw['cycles_run']} complete cycle(s); the partial result is "
                  "in exc.result", partial) from None
    err.result = partial
    raise err


def simulate(model: Model | str | os.PathLike[str] | Mapping[str, Any],
             **overrides: Unpack[SimulateOptions]) -> Result:
    """Run a network and return its pressure and flow waveforms.

    ``overrides`` replace the model's ``simulation`` settings: ``cycles``, ``dt`` (s or
    ``"auto"``), ``method`` (``"auto"``, ``"rk4"``, ``"generalized-alpha"``, ``"dopri5"``), ``output_every``
    (s), ``output_cycles`` (``"last"``/``"all"``), ``until_periodic`` (relative tolerance),
    ``max_cycles``, ``rho_infty``, ``start`` (``"steady"``, ``"periodic"``,
    ``"zero"``; default ``"periodic"`` for an error-controlled run to periodicity, else
    ``"steady"``: docs/physics.md §10 "The default start"), ``segments`` (bool),
    ``progress`` (bool or callback ``f(t, t_end)``), ``threads`` (default: every core; ``1``
    serial; large trees split their elimination over them, with the same bits for any number).

    Error control (docs/physics.md §10), the default without ``dt``: ``rtol`` (0 < rtol < 1,
    default 1e-3) runs generalized-α (or, with ``method`` ``"auto"``/``"dopri5"``, the explicit
    pair where it is cheaper) with a variable step whose estimated error of every unknown stays
    within ``atol + rtol·|y|``
    (``atol``: a mapping ``{"pressure": Pa, "flow": m^3/s, "volume": m^3, "species":
    mol/m^3}``, absolute as given; by default 1 Pa, 1e-9, 1e-9, 1e-6 for each kind's largest
    unknown and scaled by its share for the others, so every unknown meets rtol of its own
    scale: docs/solvers.md, "What is controlled"), output from the dense output at every
    ``output_every`` (which then never changes the solution); ``result.error_estimate`` gives
    the largest estimate per kind. A given ``dt`` is a fixed step (as is ``method="rk4"``,
    and a checkpointed run without ``dt``); ``result.settings["step_control"]`` says which.
    ``estimate_space_error=True`` adds ``result.error_estimate["space"]``: the largest
    relative change of the input impedance at the flow or pressure inlets over the forcing's
    significant harmonics when every vessel's segments are doubled (docs/solvers.md,
    "Space"), with either integrator.

    Cycles: without ``until_periodic`` (keyword or the model's ``simulation`` section) a run
    takes exactly ``cycles``; with it, ``cycles`` is the least and ``max_cycles`` (default
    max(cycles, 100)) the most, and a run that reaches ``max_cycles`` above its tolerance
    warns (:class:`~oxyline.PeriodicityWarning`) and records
    ``settings["periodic_reached"] = False``. A keyword wins over the model file, so
    ``cycles=N, until_periodic=None`` runs exactly N cycles of a model that asks for
    periodicity.

    Run control: ``max_memory`` (bytes or e.g. ``"8 GB"``; default 80 % of the available
    memory, see :mod:`oxyline.memory`): an output estimated above it is refused with
    :class:`~oxyline.ResourceError` before the run. ``checkpoint`` (a file) and
    ``checkpoint_every`` (seconds of wall time, or ``"N cycles"``; default 300 s): the run's
    state is written there at cycle ends, and :func:`oxyline.resume` continues it with
    bit-identical results (see :mod:`oxyline.checkpoint`). ``cancel`` (a
    ``threading.Event``): setting it, e.g. from another thread, stops the run with
    :class:`~oxyline.SimulationCancelled` carrying the partial result in ``exc.result``, as
    Ctrl-C does with :class:`~oxyline.SimulationInterrupted`. Ctrl-C also cancels the runs in
    progress in other threads.

    >>> import oxyline
    >>> res = oxyline.simulate("bifurcation", cycles=2)
    >>> res.flow_in.shape[1]
    3
    """
    _refuse_checkpoint_on_input(model, overrides.get("checkpoint"))
    return _simulate(load_model(model), overrides)


def _refuse_checkpoint_on_input(model: Any, checkpoint: Any) -> None:
    """A checkpoint file that is the model file itself would overwrite the model."""
    if isinstance(model, (str, os.PathLike)) and isinstance(checkpoint, (str, os.PathLike)) \
            and os.path.exists(model) and same_file(model, checkpoint):
        raise ModelError(f"simulate: checkpoint {os.fspath(checkpoint)!r} is the model file "
                         "itself; it would be overwritten: give another file")


def _simulate(model: Model, overrides: Mapping[str, Any], resume: Any = None,
              resume_path: Any = None, store: dict[str, Any] | None = None) -> Any:
    """`simulate` of a loaded model; ``resume``: the core state of a checkpoint. ``store``
    (``simulate_to_zarr``): the Zarr store's keywords; the rows go there as the core hands
    them over, and the store, opened, is returned."""
    s, default, space, timed = _resolve(model, overrides)
    if timed == "meet" and store is not None:
        raise ModelError("simulate_to_zarr: meet_rtol runs the model again until its estimate "
                         "meets rtol: use simulate(..., meet_rtol=True) and result.to_zarr")
    if timed == "meet":
        return _meet_rtol(model, overrides, s["rtol"])
    if default and s["atol"] is None and (overrides.get("checkpoint") is not None
                                          or resume is not None):
        # a checkpoint does not carry the error control's state (step history, peaks): the
        # automatic fixed step instead; an rtol or atol given is left to the core to refuse
        s["rtol"] = None
    summarize = store is None and _large_model_output(model, s, overrides)
    monitor = Monitor(model.transport_spec)
    heart = _heart_outputs(model, s)
    core = {**_checkpoints(model, overrides), **({"heart": True} if heart else {})}
    if resume is not None:
        core["resume"] = resume
    if timed:  # the core runs the last cycle again at rtol/FACTOR after the run
        _check_time_error(s, summarize, core)
        if store is not None and heart.get("valves"):
            raise ModelError("simulate_to_zarr: estimate_time_error of a circuit with valves "
                             f"({', '.join(heart['valves'])}) runs the whole run "
                             "again in memory: use simulate(..., estimate_time_error=True) "
                             "and result.to_zarr")
        core["finer_last_cycle"] = FACTOR
    sink: Any = None
    s_out = s  # the selection of the rows kept
    if store is not None:
        store = {**store, **_stream_plan(model, s, store["time_chunk"], bool(timed))}
        _check_output_size(model, s, overrides, where=store["path"], held=store["held"])
        sink = _ZarrSink(model, s, monitor, store, keep_last_cycle=bool(timed))
        core.update(chunk_sink=sink.add, chunk_rows=store["time_chunk"],
                    keep_current_cycle=store["keep_current_cycle"])
    elif summarize and not core:  # (a checkpointed run keeps its rows: resume rebuilds them)
        layout = _output_layout(model, s)
        if not s["transport"]:
            layout.pop("transport", None)
        # (the layout resolved once: the kept rows' selection replaces it in the model's cache)
        sink = SummaryStream(model, layout,
                             lambda rows: _result(model, s, rows, {}, False, layout=dict(layout)))
        core.update(chunk_sink=sink.add, chunk_rows=sink.rows)
        s_out = {**s, "vessels": sink.inlets}  # the time series kept
    if store is None:
        _check_output_size(model, s_out, overrides, sink.bytes() if sink is not None else 0.0)
    try:
        raw = _run(model, s, overrides.get("progress"), _cancel(overrides), **core)
    except BaseException as exc:
        if store is not None:  # refused before the first step (e.g. an unstable dt)
            sink.store.remove()
        if resume_path is not None and isinstance(exc, ModelError) \
                and str(exc).startswith("checkpoint:"):
            raise CheckpointError(f"{resume_path}: {str(exc).removeprefix('checkpoint: ')}") \
                from None
        raise
    settings = {**_run_settings(s, raw, bool(heart.get("valves"))),
                **segmentation_facts(model)}
    if store is not None:  # the final attributes: of a result of no rows
        final = _result(model, s, sink.template(), settings, "error" not in raw)
        if timed and "error" not in raw:
            _fill_time_error_streamed(model, s, raw, final, sink.last_cycle())
        out = sink.close(raw, final, space)
    else:
        if sink is not None:  # the summary stream's kept rows
            raw = sink.raw(raw)
        final = out = _in_memory(model, s_out, raw, settings, sink)
        if timed:
            _fill_time_error(model, s_out, raw, final, overrides)
        if space:
            _add_space_error(model, final)
        if final.species:
            monitor.update(final)
    _warn_not_periodic(model.name, final.settings, final.complete)
    # physical bounds and mass balance of the recorded species output (warnings only)
    _warn_bounds(monitor.messages(), stacklevel=3)
    return out


def _in_memory(model: Model, s: Mapping[str, Any], raw: dict[str, Any],
               settings: dict[str, Any], summary: Any) -> Result:
    """The result of a run's rows ``raw`` (``summary``: the summary stream of a summarized
    run, else None), with the run's valve events and step history; the run's error raised
    with it attached."""
    result = _result(model, s, raw, settings, "error" not in raw)
    if summary is not None:
        result.vessel_summary = summary.summary(model.name)
    result.valve_events = [(float(t), str(v), bool(o)) for t, v, o in raw.get("valve_events", ())]
    if "last_cycle_steps" in raw:  # error control: the last cycle's accepted steps
        result.step_times, result.step_sizes = step_history(raw["last_cycle_steps"])
    _raise_run_error(raw, result)
    return result


def _add_space_error(model: Model, result: Result) -> None:
    """One refinement of every vessel: the inlet impedance's change, as
    ``error_estimate["space"]`` (:func:`oxyline.convergence.inlet_space_error`)."""
    from oxyline.convergence import inlet_space_error

    try:
        result.settings["error_estimate_space"] = inlet_space_error(model)
    except KeyboardInterrupt:  # the run is whole: keep it, without the estimate
        raise SimulationInterrupted("interrupted during the spatial error estimate, after "
                                    "the run; exc.result is the whole run's result "
                                    "(without error_estimate space)", result) from None


def _heart_outputs(model: Model, s: Mapping[str, Any]) -> dict[str, list[str]]:
    """The model's chambers and valves (``{"chambers": [...], "valves": [...]}``, empty when
    it has neither): a run of them asks the core for their volumes and statuses (``heart``),
    which it returns beside the selected columns as ``chamber_volume`` and ``valve_status``."""
    lay = _output_layout(model, s)
    return {k: list(lay[k]) for k in ("chambers", "valves") if lay[k]}


#: most runs ``meet_rtol`` takes (the run at rtol, then the tighter ones its estimates ask)
MEET_RTOL_RUNS = 3

#: the share of rtol the next run of ``meet_rtol`` aims at (the ratio of achieved error to
#: rtol drifts by up to ~1.4x between rtol 1e-2 and 1e-4 on adan56; a run still above rtol is
#: followed by another)
MEET_RTOL_SAFETY = 0.7


def _meet_rtol(model: Model, overrides: Mapping[str, Any], target: float | None) -> Result:
    """``simulate(..., meet_rtol=True)``: the run at ``rtol`` with its accumulated-error
    estimate, then, while the worst vessel's estimate of any kind is above ``rtol``, the run at
    the tolerance that estimate asks (:meth:`oxyline.TimeErrorEstimate.rtol_to_meet`'s rule),
    at most :data:`MEET_RTOL_RUNS` runs. The result is the last run's, its estimate included;
    ``settings["meet_rtol"]`` is the target, ``meet_rtol_runs`` and ``meet_rtol_steps`` what
    it took (every run's steps and second integrations), ``meet_rtol_history`` each run's rtol
    and worst estimate."""
    if target is None:
        raise ModelError("simulate: meet_rtol needs error control (rtol, no dt)")
    kw = {**overrides, "meet_rtol": False, "estimate_time_error": True}
    rtol, steps, history = target, 0, []
    for runs in range(1, MEET_RTOL_RUNS + 1):
        result = _simulate(model, {**kw, "rtol": rtol})
        s = result.settings
        steps += int(s["steps"]) + int(s["rejected_steps"]) + int(s["time_error_steps"])
        worst = max(v for k, v in result.error_estimate.items() if k != "space")
        history.append(f"rtol {rtol:.3g}: worst {worst:.3g}")
        if worst <= target or runs == MEET_RTOL_RUNS:
            break
        # the achieved error nearly proportional to rtol (oxyline.time_error; a power law
        # through the last two runs was measured worse: the worst kind changes with rtol)
        rtol = min(rtol, MEET_RTOL_SAFETY * rtol * target / worst)
    s.update(meet_rtol=target, meet_rtol_runs=runs, meet_rtol_steps=steps,
             meet_rtol_history="; ".join(history))
    return result


def _check_time_error(s: Mapping[str, Any], summarize: bool, core: Mapping[str, Any]) -> None:
    """``estimate_time_error`` is refused for a fixed step (no tolerance to tighten; checkpoints
    need one), and for a large model's reduced default output (give ``variables``)."""
    if s["rtol"] is None or "resume" in core or "checkpoint_sink" in core:
        raise ModelError("simulate: estimate_time_error needs error control (rtol, no dt, no "
                         "checkpoint): a fixed step has no tolerance to tighten; "
                         "oxyline.convergence measures a fixed step's error")
    if summarize:
        raise ModelError("simulate: estimate_time_error compares the output of every vessel: "
                         "give variables (e.g. ['pressure_in', 'flow_in']) for this large model")


def _fill_time_error(model: Model, s: Mapping[str, Any], raw: dict[str, Any], result: Result,
                     overrides: Mapping[str, Any]) -> None:
    """``result``'s accumulated-error estimate (:func:`oxyline.time_error.record_estimate`):
    from the core's second integration of the last cycle, or, where the core did not make one
    (the explicit pair, valves), from a second whole run at rtol/FACTOR."""
    finer = raw.get("finer_last_cycle")
    explicit = result.settings.get("method") == "dopri5"
    if finer is not None:  # (the explicit pair's with its step ceiling lowered too)
        coarse, fine = _last_cycle_results(model, s, raw, finer)
        source = FROM_LAST_CYCLE_EXPLICIT if explicit else FROM_LAST_CYCLE
        steps = int(finer["steps"]) + int(finer["rejected_steps"])
    else:
        coarse, fine = result, _again_finer(model, result, s["rtol"] / FACTOR, overrides)
        source = FROM_WHOLE_RUN
        if explicit and fine.settings["steps"] == result.settings["steps"]:
            source += SAME_STEPS  # (a tighter rtol did not change the pair's steps)
        steps = int(fine.settings["steps"]) + int(fine.settings["rejected_steps"])
    record_estimate(result, accumulated(coarse, fine), source.format(factor=FACTOR), steps)


def _fill_time_error_streamed(model: Model, s: Mapping[str, Any], raw: Mapping[str, Any],
                              final: Result, last: dict[str, Any] | None) -> None:
    """``simulate_to_zarr``'s accumulated-error estimate, into ``final`` (whose attributes the
    store gets): the core's second integration of the last cycle against the last cycle's rows
    the sink kept (``last``), as :func:`_fill_time_error` does in memory."""
    finer = raw.get("finer_last_cycle")
    if finer is None or last is None or len(last["times"]) < len(finer["times"]):
        raise ModelError("simulate_to_zarr: estimate_time_error found no second integration "
                         "of the last cycle to compare (e.g. a run of fewer output rows than "
                         "a cycle): use simulate(..., estimate_time_error=True)")
    rows = {**raw, "times": last["times"], "data": last["data"]}
    if raw.get("transport") is not None and "species" in last:
        rows["transport"] = {**raw["transport"], "data": last["species"]}
    coarse, fine = _last_cycle_results(model, s, rows, finer)
    explicit = final.settings.get("method") == "dopri5"
    source = FROM_LAST_CYCLE_EXPLICIT if explicit else FROM_LAST_CYCLE
    steps = int(finer["steps"]) + int(finer["rejected_steps"])
    record_estimate(final, accumulated(coarse, fine), source.format(factor=FACTOR), steps)


def _again_finer(model: Model, coarse: Result, rtol: float, overrides: Mapping[str, Any]
                 ) -> Result:
    """The run of ``coarse`` (with ``overrides``) again at the tighter ``rtol``: the same
    cycles from the same start, without a progress bar or estimates of its own."""
    kw = {k: v for k, v in overrides.items()
          if k not in ("estimate_time_error", "meet_rtol", "rtol")}
    # (the same start too: without until_periodic the default start would be another)
    kw.update(progress=False, cycles=int(coarse.settings["cycles_run"]), until_periodic=None,
              start=coarse.settings["start"], estimate_space_error=False)
    return simulate(model, rtol=rtol, **kw)


def estimate_time_error(
    model: Model | str | os.PathLike[str] | Mapping[str, Any],
    rtol: float = 1e-3,
    factor: float = FACTOR,
    **overrides: Any,
) -> TimeErrorEstimate:
    """Run ``model`` at ``rtol`` (error control, ``overrides`` as for
    :func:`oxyline.simulate`, no ``dt``) and again at ``rtol/factor``, and estimate the first
    run's error per vessel against each vessel's own scale (:mod:`oxyline.time_error`).

    >>> import oxyline
    >>> est = oxyline.estimate_time_error("bifurcation", rtol=1e-2, cycles=2)
    >>> sorted(est.worst)
    ['flow', 'pressure', 'pulse_pressure']
    """
    if not (isinstance(factor, (int, float)) and factor > 1 and np.isfinite(factor)):
        raise ModelError(f"estimate_time_error: factor must be a number > 1, got {factor!r}")
    if overrides.get("dt") not in (None, "auto"):
        raise ModelError(
            f"estimate_time_error: dt = {overrides['dt']!r} is a fixed step; "
            "the estimate is of an error-controlled run (no dt)"
        )
    m = load_model(model)
    kw = {"progress": False, **overrides, "dt": "auto"}
    coarse = simulate(m, rtol=rtol, **kw)
    finer = _again_finer(m, coarse, rtol / factor, kw)  # exactly the first's cycles
    if coarse.time.shape != finer.time.shape or not np.allclose(coarse.time, finer.time):
        raise ModelError("estimate_time_error: the two runs recorded different output times")
    return TimeErrorEstimate(rtol=rtol, factor=float(factor), result=coarse, finer=finer,
                             per_vessel=accumulated(coarse, finer, factor))


def _last_cycle_results(model: Model, s: Mapping[str, Any], raw: Mapping[str, Any],
                        finer: Mapping[str, Any]) -> tuple[Result, Result]:
    """The run's rows at the output times of the core's second integration of the last cycle
    (``finer``), and that integration's rows, as two results of the same layout."""
    n = len(finer["times"])
    ncol = raw["data"].shape[1]  # (the finer rows keep svZeroDSolver's derived columns)

    def rows(times: np.ndarray, data: np.ndarray, species: Any) -> dict[str, Any]:
        out: dict[str, Any] = {"times": times, "data": data}
        if raw.get("transport") is not None:
            out["transport"] = {**raw["transport"], "data": species}
        return out

    tr = raw.get("transport")
    run = rows(raw["times"][-n:], raw["data"][-n:],
               None if tr is None else tr["data"][-n:])
    again = rows(np.asarray(finer["times"]), np.asarray(finer["data"])[:, :ncol],
                 finer.get("transport"))
    return (_result(model, s, run, {}, True), _result(model, s, again, {}, True))


def resume(path: str | os.PathLike[str], **overrides: Any) -> Result:
    """Continue the run of checkpoint ``path`` (written by ``simulate(..., checkpoint=...)``)
    to its end, and return its whole result: bit-identical to the result of the run that
    wrote it, had that run not been stopped.

    The run keeps the checkpoint's model and settings; only ``progress``, ``cancel``,
    ``max_memory``, ``checkpoint`` and ``checkpoint_every`` may be given (by default it goes on
    checkpointing into ``path`` as often as before). :class:`~oxyline.CheckpointError` if the
    file is not a checkpoint this version reads.

    >>> import os, tempfile, threading, oxyline
    >>> stop = threading.Event()
    >>> with tempfile.TemporaryDirectory() as d:
    ...     ck = os.path.join(d, "run.ckpt")
    ...     try:  # stopped once the checkpoint of cycle 1 is written
    ...         oxyline.simulate("bifurcation", cycles=3, checkpoint=ck,
    ...                          checkpoint_every="1 cycle", cancel=stop,
    ...                          progress=lambda t, t_end: os.path.exists(ck) and stop.set())
    ...     except oxyline.SimulationCancelled as stopped:
    ...         partial = stopped.result
    ...     res = oxyline.resume(ck)
    >>> partial.complete, res.complete, res.settings["cycles_run"]
    (False, True, 3)
    """
    meta, state = _checkpoint.read(path)
    _core.check_resumed(list(overrides))  # only the run control may change
    try:
        model = load_model(meta["model"])
    except ModelError as exc:
        raise CheckpointError(f"{path}: its model does not load: {exc}") from None
    try:  # every stored setting checked before the run, named as a field of the file
        _settings(model, meta["settings"])
    except ModelError as exc:
        raise CheckpointError(f"{path}: field 'settings': {exc}") from None
    control = {"checkpoint": os.fspath(path), "checkpoint_every": meta.get("checkpoint_every")}
    if "checkpoint" in overrides and overrides["checkpoint"] is None:  # no more checkpoints
        control = {}
    return _simulate(model, {**meta["settings"], **control, **overrides}, resume=state,
                     resume_path=path)


def _cancel(overrides: Mapping[str, Any]) -> Any:
    cancel = overrides.get("cancel")
    if cancel is not None and not callable(getattr(cancel, "is_set", None)):
        raise ModelError(f"simulate: cancel must be a threading.Event (anything with is_set()), "
                         f"got {cancel!r}")
    return cancel


def _checkpoints(model: Model, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The core's checkpoint keywords: a sink writing the file, and how often."""
    path = overrides.get("checkpoint")
    every = overrides.get("checkpoint_every")
    if path is not None and not isinstance(path, (str, os.PathLike)):
        raise ModelError(f"simulate: checkpoint must be a file path, got {path!r}")
    core = _core.checkpoint_interval(every, path is not None)  # (the core's schema)
    if path is None:
        return {}
    _checkpoint.check_writable(path)
    meta = {"model": model.to_dict(), "settings": _checkpoint.stored_settings(overrides),
            "checkpoint_every": every, "oxyline": str(_core.__version__)}

    def save(state: dict[str, Any]) -> None:
        _checkpoint.write(path, meta, state)

    return {"checkpoint_sink": save, **core}


def _check_output_size(model: Model, s: Mapping[str, Any], overrides: Mapping[str, Any],
                       reduced: float = 0.0, where: Any = None, held: float = 0.0) -> None:
    """Refuse an output the memory allowed cannot hold (:class:`ResourceError` with the
    estimate and the settings to change), and announce a large one
    (:class:`OutputSizeWarning`), before the run starts. ``reduced``: the bytes of a
    summarized run's reductions and chunk in flight, beside the rows it keeps (``s``).
    ``where``: the path of a streamed store (its size on disk is announced), whose memory is
    the rows it holds at once, ``held`` bytes (:func:`_stream_plan`)."""
    need, rows, cols = _output_size(model, s)
    need += reduced
    size = f"the output ({rows} rows x {cols} columns)"
    todo = ("output fewer rows (output_every, output_cycles='last', fewer cycles) or columns "
            "(variables, vessels, segments=False), stream it to disk with simulate_to_zarr, "
            "or raise max_memory")
    if where is not None:
        if need > _memory.WARN_BYTES:
            warnings.warn(f"{where}: {size} takes about {_memory.human(need)} on disk (before "
                          "compression)", OutputSizeWarning, stacklevel=4)
        need, size = held, f"the streamed output's rows held at once ({cols} columns)"
        todo = ("give a smaller time_chunk or fewer columns (variables, vessels, "
                "segments=False), or raise max_memory")
    key = f"{'simulate' if 'max_memory' in overrides else 'simulation'}: max_memory"
    limit = _memory.limit(overrides.get("max_memory", model.simulation.get("max_memory")), key)
    if limit is not None and need > limit:
        raise ResourceError(
            f"simulate: {size} needs about {_memory.human(need)} of memory (estimate), above "
            f"max_memory = {_memory.human(limit)}; {todo}")
    if limit is not None and "max_memory" in overrides:
        # a max_memory given to this run bounds the whole run: the model's state too (the
        # model was assembled under its own file's limit)
        state = _memory.run_estimate(model.network, s)
        if state + need > limit:
            raise ResourceError(
                f"simulate: the run needs about {_memory.human(state + need)} of memory "
                f"(estimate: the model's state {_memory.human(state)}, its output "
                f"{_memory.human(need)}), above max_memory = {_memory.human(limit)}; output "
                "fewer rows or columns, a coarser segmentation, or raise max_memory")
    if need > _memory.WARN_BYTES and where is None:
        warnings.warn(f"{size} takes about {_memory.human(need)} in memory, and as much when "
                      "written to a file", OutputSizeWarning, stacklevel=4)


def _output_size(model: Model, s: Mapping[str, Any]) -> tuple[float, int, int]:
    layout = _output_layout_sized(model, s)
    cycles = s["max_cycles"] if s["until_periodic"] is not None else s["cycles"]
    return _memory.output_estimate(layout, s["period"], s["output_every"], cycles,
                                   s["output_all_cycles"])


#: vessels or segments per chunk of a streamed store (a row of a chunk: 512 KiB of float64)
SEGMENT_CHUNK = 65536


def _stream_plan(model: Model, s: Mapping[str, Any], time_chunk: int | None,
                 timed: bool = False) -> dict[str, Any]:
    """How a streamed store's run holds its rows: ``time_chunk`` (given, else the most rows
    whose copies in flight stay within ``memory.STREAM_BUDGET``: :func:`memory.stream_rows`;
    at most the output's rows),
    ``keep_current_cycle`` (last-cycle output: the cycles before the last are recorded, so
    that a run stopped early stores its partial cycle, only while a cycle's rows fit the
    budget; a run until periodic keeps them anyway, not knowing its last cycle) and ``held``,
    the bytes of rows it holds at once (:func:`memory.stream_estimate`; with ``timed``, the
    accumulated-error estimate, also the last cycle's rows twice: the sink's kept copy, with a
    chunk more, and the core's second integration of that cycle)."""
    _, cycle_rows, cols = _memory.output_estimate(_output_layout_sized(model, s), s["period"],
                                                  s["output_every"], 1, False)
    _, rows, _ = _output_size(model, s)
    # never more rows than the output has: zarr writes (and holds while encoding) every chunk
    # whole, padded to its rows (1024 rows of a 101-row run at 1.05 M segments: 8.5 GB peak)
    chunk = min(rows, time_chunk if time_chunk is not None else _memory.stream_rows(cols))
    open_ended = s["until_periodic"] is not None
    keep, kept = True, 0
    if not s["output_all_cycles"] and (open_ended or s["cycles"] > 1):  # cycles before the last
        cycle = 8.0 * _memory.table_rows(cycle_rows, chunk) * cols
        keep = open_ended or cycle <= _memory.STREAM_BUDGET
        kept = cycle_rows if keep else 0
    held = _memory.stream_estimate(chunk, cols, kept, rows)
    if timed:
        held += 8.0 * (2 * cycle_rows + chunk) * cols
    return {"time_chunk": chunk, "keep_current_cycle": keep, "held": held}


def _output_layout_sized(model: Model, s: Mapping[str, Any]) -> dict[str, Any]:
    layout = _output_layout(model, s)
    if not s["transport"]:
        layout.pop("transport", None)
    return layout


def simulate_to_zarr(model: Model | str | os.PathLike[str] | Mapping[str, Any],
                     path: str | os.PathLike[str], *, time_chunk: int | None = None,
                     segment_chunk: int = SEGMENT_CHUNK, overwrite: bool = False,
                     **overrides: Unpack[SimulateOptions]) -> Any:
    """Run a network, writing its output to a Zarr store *during* the run, and return the store
    opened lazily as an ``xarray.Dataset``.

    The store holds exactly what ``simulate(model, **overrides).to_zarr(path)`` writes (same
    variables, dims, coordinates, units and attributes, Zarr format 2), but the core hands its
    output over every ``time_chunk`` rows, each chunk is appended along ``time`` at once, and
    neither the core nor Python keep more than one chunk: memory stays bounded however many
    cycles are output (``output_cycles="all"``). Without ``time_chunk``, the rows per chunk
    are the most (up to 1024; above 64 a power of two) whose copies in flight, three of 8
    bytes per stored column, stay within ``oxyline.memory.STREAM_BUDGET`` (256 MiB): at ten
    million stored columns, 1 row. Every array is also chunked along ``vessel``
    and ``segment``, ``segment_chunk`` vessels or segments per chunk (default 65 536), so a
    lazy read of one region (``xr.open_zarr(path, chunks={})``) reads only its chunks
    (:func:`oxyline.io.regions.region_sum` sums a segment variable by region, chunk by
    chunk). The rows held at once are counted in the memory check before the run
    (``max_memory``: :class:`~oxyline.ResourceError`). The store is created before the run starts
    and is a valid store after every chunk; its attribute ``complete`` is 1 once the run has
    finished. If the run stops early (Ctrl-C, a solver failure), the rows computed until then
    are written and the exception is raised with the opened store as ``exc.result``
    (:class:`~oxyline.SimulationInterrupted` for Ctrl-C). A chunk that cannot be written (disk
    full) stops the run with :class:`~oxyline.OutputError`, whose ``result`` is the store with
    the rows written before it. An existing store at ``path`` is replaced only with
    ``overwrite=True``. ``estimate_time_error=True`` records the run's accumulated-error
    estimate in the store as :func:`simulate` gives it (the attributes
    ``solver_error_estimate_<kind>``, ``solver_time_error_*`` and the variables
    ``time_error_<kind>`` over ``vessel``): the last cycle's rows are kept as they pass (one
    cycle and one chunk more held) and compared with the core's second integration of that
    cycle; a circuit with valves (whose estimate runs the whole run again in memory) and
    ``meet_rtol`` are refused with :class:`~oxyline.ModelError`. Needs ``zarr`` and ``xarray``.

    >>> import oxyline, tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     ds = oxyline.simulate_to_zarr("bifurcation", os.path.join(d, "run.zarr"),
    ...                                   cycles=2, output_cycles="all", time_chunk=256)
    ...     print(ds.sizes["time"], ds.attrs["complete"])
    2001 1
    """
    for name, value in (("time_chunk", time_chunk), ("segment_chunk", segment_chunk)):
        if value is None and name == "time_chunk":
            continue  # chosen from the memory budget
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ModelError(f"simulate_to_zarr: {name} must be an integer >= 1, got {value!r}")
    model = load_model(model)
    if "checkpoint" in overrides or "checkpoint_every" in overrides:
        raise ModelError("simulate_to_zarr: checkpoints are not supported with a streamed "
                         "store; use simulate(..., checkpoint=...)")
    return _simulate(model, overrides, store={"path": path, "time_chunk": time_chunk,
                                              "space_chunk": segment_chunk,
                                              "overwrite": overwrite})


class _ZarrSink:
    """The chunk sink of ``simulate_to_zarr``: the store (created with the variables of a
    result of no rows before the run), each chunk appended as a result of its rows, the bounds
    monitor fed each chunk as it passes (docs/physics.md §2.8)."""

    def __init__(self, model: Model, s: Mapping[str, Any], monitor: Monitor,
                 store: Mapping[str, Any], keep_last_cycle: bool = False) -> None:
        self.model, self.s = model, s
        #: the rows of the last cycle and one chunk more, kept as they pass when the run's
        #: accumulated error is estimated (its last cycle against the core's second integration
        #: of it); 0: none kept
        self.tail_rows = (int(np.ceil(s["period"] / s["output_every"])) + 2
                          if keep_last_cycle else 0)
        self.tail: list[dict[str, Any]] = []
        # zero rows in the core's layout, with the chambers' and valves' outputs
        lay = _output_layout(model, s)
        self._empty: dict[str, Any] = {
            "times": np.zeros(0), "data": np.zeros((0, lay["n_columns"])),
            "chamber_volume": {name: np.zeros(0) for name in lay["chambers"]},
            "valve_status": {name: np.zeros(0, dtype=np.int8) for name in lay["valves"]}}
        tl = lay.get("transport") if s["transport"] else None
        if tl is not None:
            n = len(tl["species"])
            self._empty["transport"] = {"species": list(tl["species"]), "initial_stored": [0.0] * n,
                                        "data": np.zeros((0, n * tl["columns_per_species"]))}
        head = _result(model, s, self.template(),
                       _run_settings(s, None, bool(lay["valves"])), False)
        self.store = ZarrAppender(store["path"], dataset(head), store["time_chunk"],
                                  overwrite=store["overwrite"], space_chunk=store["space_chunk"])
        self.monitor = monitor

    def template(self) -> dict[str, Any]:
        """Zero rows in the core's layout (a fresh dict)."""
        return dict(self._empty)

    def add(self, rows: dict[str, Any]) -> None:
        if self.tail_rows:
            self._keep(rows)
        chunk = _result(self.model, self.s, rows, {}, False)
        self.monitor.update(chunk)
        self.store.append(chunk.to_xarray(coordinates=False))

    def _keep(self, rows: Mapping[str, Any]) -> None:
        """Keep ``rows`` (the core's columns), dropping the oldest kept chunk while the others
        still hold a cycle's rows."""
        tr = rows.get("transport")
        self.tail.append({"times": np.array(rows["times"]),
                          "data": np.array(rows["data"]),
                          "species": None if tr is None else np.array(tr["data"])})
        held = sum(len(c["times"]) for c in self.tail)
        while held - len(self.tail[0]["times"]) >= self.tail_rows:
            held -= len(self.tail.pop(0)["times"])

    def last_cycle(self) -> dict[str, Any] | None:
        """The kept rows as a run's rows (``times``, ``data``, the species' ``data``), None
        when none were kept."""
        if not self.tail:
            return None
        out: dict[str, Any] = {k: np.concatenate([c[k] for c in self.tail])
                               for k in ("times", "data")}
        if self.tail[0]["species"] is not None:
            out["species"] = np.concatenate([c["species"] for c in self.tail])
        return out

    def close(self, raw: dict[str, Any], final: Result, space: bool) -> Any:
        """Write the final attributes (``final``'s, with the spatial error estimate when
        asked), open the store, and raise the run's error with the store attached."""
        if space and "error" not in raw:
            _add_space_error(self.model, final)
        # (the attributes only: the store has the coordinates, ten million at that size)
        ds = dataset(final, coordinates=False)
        # (the per-vessel accumulated-error table, when estimated: its variables over vessel)
        table = {k: v for k, v in ds.data_vars.items() if k.startswith(TIME_ERROR_PREFIX)}
        raw, opened = _close_store(self.store, raw, ds.attrs, table)
        _raise_run_error(raw, opened)
        return opened


def _close_store(store: Any, raw: dict[str, Any], attrs: dict[str, Any],
                 variables: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], Any]:
    """Write the run's final attributes and open the store: (the run's outcome, with an
    ``OutputError`` when the attributes cannot be written, and the opened store, None when a
    failing disk left it unreadable after an error)."""
    import xarray as xr

    # the store is read back before another writer may have it: one starting right after
    # this run's last write would otherwise overwrite it before it is opened
    try:
        store.finish(attrs, raw.get("last_cycle_steps"), release=False, variables=variables)
    except (OSError, RuntimeError, ValueError) as exc:  # e.g. the disk just filled up
        if "error" not in raw:
            raw = {**raw, "error": OutputError(f"{store.path}: cannot write the run's final "
                                               f"attributes: {exc}; the store keeps every row "
                                               "(attribute complete = 0)"),
                   "error_kind": "output"}
    try:
        opened = xr.open_zarr(store.path)
    except Exception:  # a store the failing disk left unreadable: the error says what happened
        if "error" not in raw:
            raise
        opened = None
    finally:
        store.release()
    return raw, opened


# installed when oxyline is imported (normally in the main thread): a run started in a worker
# thread cannot install it itself (signal handlers belong to the main thread)
_cancel_runs_on_ctrl_c()
