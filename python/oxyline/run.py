"""``oxyline.simulate``: resolve run settings, call the core with the GIL released, wrap the
arrays in a :class:`~oxyline.result.Result`."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import Any

from oxyline.errors import ModelError, SimulationInterrupted
from oxyline.loader import load_model
from oxyline.model import METHODS, Model, output_names, output_vessels
from oxyline.result import SEGMENT_VARIABLES, SPECIES_SEGMENT, Result, SpeciesResult

ProgressCallback = Callable[[float, float], None]


def _settings(model: Model, overrides: Mapping[str, Any]) -> dict[str, Any]:
    sim = dict(model.simulation)
    out = dict(sim.get("output", {}) or {})
    unknown = set(overrides) - {"cycles", "dt", "method", "output_every", "output_cycles",
                                "until_periodic", "max_cycles", "rho_infty", "start", "segments",
                                "progress", "newton_atol", "max_iterations", "transport",
                                "variables", "vessels"}
    if unknown:
        raise ModelError(f"simulate: unknown option(s) {', '.join(sorted(unknown))}")
    period = model.period or 1.0
    cycles = overrides.get("cycles", sim.get("cycles", 10))
    dt = overrides.get("dt", sim.get("dt", "auto"))
    method = overrides.get("method", sim.get("method", "auto"))
    every = overrides.get("output_every", out.get("every", period / 1000.0))
    out_cycles = overrides.get("output_cycles", out.get("cycles", "last"))
    if method not in METHODS:
        raise ModelError(f"simulation: method must be one of {sorted(METHODS)}, got {method!r}")
    if out_cycles not in ("last", "all"):
        raise ModelError(f"simulation output: cycles must be 'last' or 'all', got {out_cycles!r}")
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ModelError(f"simulation: cycles must be an integer >= 1, got {cycles!r}")
    if dt in (None, "auto"):
        dt = None
    elif isinstance(dt, bool) or not isinstance(dt, (int, float)) or not dt > 0:
        raise ModelError(f"simulation: dt must be 'auto' or a number > 0, got {dt!r}")
    return {
        "period": float(period),
        "cycles": int(cycles),
        "dt": None if dt is None else float(dt),
        "method": method,
        "output_every": float(every),
        "output_all_cycles": out_cycles == "all",
        "until_periodic": overrides.get("until_periodic", sim.get("until_periodic")),
        "max_cycles": int(overrides.get("max_cycles", sim.get("max_cycles", 100))),
        "rho_infty": float(overrides.get("rho_infty", sim.get("rho_infty", 0.5))),
        "start": overrides.get("start", sim.get("start", "steady")),
        "segments": bool(overrides.get("segments", out.get("segments", True))),
        "variables": output_names(overrides.get("variables", out.get("variables")), "variables"),
        "vessels": _vessels(model, overrides.get("vessels", out.get("vessels"))),
        "newton_atol": overrides.get("newton_atol"),
        "max_iterations": int(overrides.get("max_iterations", 30)),
        "transport": bool(overrides.get("transport", True)),
    }


def _vessels(model: Model, selection: Any) -> list[str] | None:
    """The output vessels: the model's default (every vessel but structured-tree ones) when
    none are selected, else the selection (``all`` really selects all)."""
    if selection is None:
        return model.default_output_vessels
    return output_vessels(selection)


def _selection(s: Mapping[str, Any]) -> dict[str, Any]:
    """The core's output-selection keywords of settings ``s``."""
    return {"variables": s["variables"], "vessels": s["vessels"], "segments": s["segments"]}


def _progress_bar(enabled: bool | ProgressCallback | None) -> tuple[Any, Any]:
    if callable(enabled):
        return enabled, None
    if not enabled:
        return None, None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None, None
    bar = tqdm(total=1.0, unit="s", delay=1.0, bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} s "
               "simulated [{elapsed}<{remaining}]")

    def update(t: float, t_end: float) -> None:
        bar.total = t_end
        bar.n = min(t, t_end)
        bar.refresh()

    return update, bar


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
    out: dict[str, SpeciesResult] = {}
    ox = model.transport.get("oxygen")
    for k, name in enumerate(tr["species"]):
        block = data[:, k * cols:(k + 1) * cols]
        vcols, scols = nv * kv, ns * ks
        out[name] = SpeciesResult(
            name=name,
            vessel_data=block[:, :vcols].reshape(nt, nv, kv),
            segment_data=block[:, vcols:vcols + scols].reshape(nt, ns, ks),
            balance_data=block[:, vcols + scols:],
            initial_stored=float(tr["initial_stored"][k]),
            po2_per_concentration=(1.0 / model.transport["solubility"]) if name == ox else None,
            vessel_variables=tuple(lay["vessel_variables"]),
            segment_variables=seg_vars,
        )
    return out


def _result(model: Model, s: Mapping[str, Any], raw: Mapping[str, Any],
            settings: dict[str, Any], complete: bool) -> Result:
    """A :class:`Result` of output rows in the core's layout (a whole run, or one chunk)."""
    layout = model.network.output_layout(**_selection(s))
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
    )


def _run_settings(s: Mapping[str, Any], raw: Mapping[str, Any] | None) -> dict[str, Any]:
    """The settings recorded with a result: the requested ones and, after the run, its facts."""
    settings = {k: s[k] for k in ("period", "cycles", "method", "output_every", "rho_infty",
                                  "until_periodic")}
    if raw is not None:
        settings.update(method=raw["method"], dt=raw["dt"], cycles_run=raw["cycles_run"],
                        periodic_error=raw["periodic_error"], rk4_dt_max=raw.get("rk4_dt_max"))
    return settings


def _run(model: Model, s: Mapping[str, Any], progress: Any, **core: Any) -> dict[str, Any]:
    """The core's raw output of a run with settings ``s``, with a progress bar if asked for."""
    callback, bar = _progress_bar(progress)
    try:
        return model.network.simulate(progress=callback, **s, **core)
    finally:
        if bar is not None:
            bar.close()


def _raise_run_error(raw: Mapping[str, Any], partial: Any) -> None:
    """Re-raise the error of a run that stopped early, with the partial output attached."""
    if "error" not in raw:
        return
    err = raw["error"]
    if raw["error_kind"] == "interrupted" and isinstance(err, KeyboardInterrupt):
        raise SimulationInterrupted(
            f"run interrupted after {raw['cycles_run']} complete cycle(s); "
            "the partial result is in exc.result", partial) from None
    err.result = partial
    raise err


def simulate(model: Model | str | os.PathLike[str] | Mapping[str, Any], **overrides: Any) -> Result:
    """Run a network and return its pressure and flow waveforms.

    ``overrides`` replace the model's ``simulation`` settings: ``cycles``, ``dt`` (s or
    ``"auto"``), ``method`` (``"auto"``, ``"rk4"``, ``"generalized-alpha"``), ``output_every``
    (s), ``output_cycles`` (``"last"``/``"all"``), ``until_periodic`` (relative tolerance),
    ``max_cycles``, ``rho_infty``, ``start`` (``"steady"``, ``"zero"``), ``segments`` (bool),
    ``progress`` (bool or callback ``f(t, t_end)``).

    >>> import oxyline
    >>> res = oxyline.simulate("bifurcation", cycles=2)
    >>> res.flow_in.shape[1]
    3
    """
    model = load_model(model)
    s = _settings(model, overrides)
    raw = _run(model, s, overrides.get("progress"))
    result = _result(model, s, raw, _run_settings(s, raw), complete="error" not in raw)
    _raise_run_error(raw, result)
    return result


def simulate_to_zarr(model: Model | str | os.PathLike[str] | Mapping[str, Any],
                     path: str | os.PathLike[str], *, time_chunk: int = 1024,
                     **overrides: Any) -> Any:
    """Run a network, writing its output to a Zarr store *during* the run, and return the store
    opened lazily as an ``xarray.Dataset``.

    The store holds exactly what ``simulate(model, **overrides).to_zarr(path)`` writes (same
    variables, dims, coordinates, units and attributes, Zarr format 2), but the core hands its
    output over every ``time_chunk`` rows, each chunk is appended along ``time`` at once, and
    neither the core nor Python keep more than one chunk: memory stays bounded however many
    cycles are output (``output_cycles="all"``). The store is created before the run starts
    and is a valid store after every chunk; its attribute ``complete`` is 1 once the run has
    finished. If the run stops early (Ctrl-C, a solver failure), the rows computed until then
    are written and the exception is raised with the opened store as ``exc.result``
    (:class:`~oxyline.SimulationInterrupted` for Ctrl-C). Needs ``zarr`` and ``xarray``.

    >>> import oxyline, tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     ds = oxyline.simulate_to_zarr("bifurcation", os.path.join(d, "run.zarr"),
    ...                                   cycles=2, output_cycles="all", time_chunk=256)
    ...     print(ds.sizes["time"], ds.attrs["complete"])
    2001 1
    """
    import xarray as xr

    from oxyline.io.results import ZarrAppender, dataset

    if isinstance(time_chunk, bool) or not isinstance(time_chunk, int) or time_chunk < 1:
        raise ModelError(f"simulate_to_zarr: time_chunk must be an integer >= 1, got {time_chunk!r}")
    model = load_model(model)
    s = _settings(model, overrides)
    empty = _empty_rows(model, s)
    store = ZarrAppender(path, dataset(_result(model, s, empty, _run_settings(s, None), False)),
                         time_chunk)

    def write(rows: dict[str, Any]) -> None:
        store.append(dataset(_result(model, s, rows, {}, False)))

    try:
        raw = _run(model, s, overrides.get("progress"), chunk_sink=write, chunk_rows=time_chunk)
    except Exception:
        store.remove()  # refused before the first step (e.g. an unstable dt): no output at all
        raise
    store.finish(dataset(_result(model, s, empty, _run_settings(s, raw), "error" not in raw)).attrs)
    opened = xr.open_zarr(store.path)
    _raise_run_error(raw, opened)
    return opened


def _empty_rows(model: Model, s: Mapping[str, Any]) -> dict[str, Any]:
    """Zero output rows in the core's layout: the template of a store's variables."""
    import numpy as np

    lay = model.network.output_layout(**_selection(s))
    raw: dict[str, Any] = {"times": np.zeros(0), "data": np.zeros((0, lay["n_columns"]))}
    tl = lay.get("transport") if s["transport"] else None
    if tl is not None:
        n = len(tl["species"])
        raw["transport"] = {"species": list(tl["species"]),
                            "data": np.zeros((0, n * tl["columns_per_species"])),
                            "initial_stored": [0.0] * n}
    return raw
