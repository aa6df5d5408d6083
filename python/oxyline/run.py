"""``oxyline.simulate``: resolve run settings, call the core with the GIL released, wrap the
arrays in a :class:`~oxyline.result.Result`."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import Any

from oxyline.errors import ModelError, SimulationInterrupted
from oxyline.model import METHODS, Model, load_model
from oxyline.result import Result, SpeciesResult

ProgressCallback = Callable[[float, float], None]


def _settings(model: Model, overrides: Mapping[str, Any]) -> dict[str, Any]:
    sim = dict(model.simulation)
    out = dict(sim.get("output", {}) or {})
    unknown = set(overrides) - {"cycles", "dt", "method", "output_every", "output_cycles",
                                "until_periodic", "max_cycles", "rho_infty", "start", "segments",
                                "progress", "newton_atol", "max_iterations", "transport"}
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
        "newton_atol": overrides.get("newton_atol"),
        "max_iterations": int(overrides.get("max_iterations", 30)),
        "transport": bool(overrides.get("transport", True)),
    }


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


def _species_results(model: Model, raw: Mapping[str, Any]) -> dict[str, SpeciesResult]:
    tr = raw.get("transport")
    if tr is None:
        return {}
    lay = model.network.transport_layout()
    nv = len(lay["segment_count"])
    ns = int(sum(lay["segment_count"]))
    cols = lay["columns_per_species"]
    data = tr["data"]
    nt = data.shape[0]
    out: dict[str, SpeciesResult] = {}
    ox = model.transport.get("oxygen")
    for k, name in enumerate(tr["species"]):
        block = data[:, k * cols:(k + 1) * cols]
        vcols, scols = nv * lay["vessel_columns"], ns * lay["segment_columns"]
        out[name] = SpeciesResult(
            name=name,
            vessel_data=block[:, :vcols].reshape(nt, nv, lay["vessel_columns"]),
            segment_data=block[:, vcols:vcols + scols].reshape(nt, ns, lay["segment_columns"]),
            balance_data=block[:, vcols + scols:],
            initial_stored=float(tr["initial_stored"][k]),
            po2_per_concentration=(1.0 / model.transport["solubility"]) if name == ox else None,
        )
    return out


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
    callback, bar = _progress_bar(overrides.get("progress"))
    try:
        raw = model.network.simulate(progress=callback, **s)
    finally:
        if bar is not None:
            bar.close()
    layout = model.network.layout()
    seg_count = list(layout["segment_count"]) if s["segments"] else []
    settings = {k: s[k] for k in ("period", "cycles", "method", "output_every", "rho_infty",
                                  "until_periodic")}
    settings.update(method=raw["method"], dt=raw["dt"], cycles_run=raw["cycles_run"],
                    periodic_error=raw["periodic_error"], rk4_dt_max=raw.get("rk4_dt_max"))
    result = Result(
        model_name=model.name, vessels=list(layout["vessels"]), time=raw["times"],
        data=raw["data"], segment_count=seg_count,
        segment_position=layout["segment_position"] if s["segments"] else layout["segment_position"][:0],
        settings=settings, complete="error" not in raw,
        species=_species_results(model, raw), oxygen=model.transport.get("oxygen"),
    )
    if "error" in raw:
        err = raw["error"]
        if raw["error_kind"] == "interrupted" and isinstance(err, KeyboardInterrupt):
            raise SimulationInterrupted(
                f"run interrupted after {raw['cycles_run']} complete cycle(s); "
                "the partial result is in exc.result", result) from None
        err.result = result
        raise err
    return result
