"""svZeroDSolver drop-in runner: :func:`simulate` runs an svZeroDSolver configuration with the
core and returns ``svzerod.simulate``'s DataFrame (public path :mod:`oxyline.svzerod`; the
conversion to a native model is :mod:`oxyline.io.svzerod.reader`)."""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import ModelError, ResourceError, core_errors
from oxyline.io.svzerod import closed_loop as svzerod_closed_loop
from oxyline.io.svzerod import heart as svzerod_heart
from oxyline.io.svzerod.reader import (
    FRAME_UNITS,
    METHODS,
    RunSettings,
    _convert,
    _Layout,
)
from oxyline.model import Model, _build
from oxyline.result import long_table_vessel_major

# ------------------------------------------------------------------------------------------
# running


def _table_spacings(native: Mapping[str, Any]) -> list[float]:
    out = []
    for bc in native["boundary_conditions"].values():
        pim = bc.get("intramyocardial_pressure")
        for t in (bc.get("time"), pim.get("time") if isinstance(pim, Mapping) else None):
            if t and len(t) > 1:
                out.append(min(b - a for a, b in itertools.pairwise(t)))
    return out


def simulate(config: Mapping[str, Any] | str | os.PathLike[str], *,
             method: str = "generalized-alpha", units: str | None = None,
             rk4_substeps: int | None = None) -> Any:
    """Run an svZeroDSolver configuration and return ``svzerod.simulate``'s DataFrame.

    The frame holds the file's own numbers, as svZeroDSolver's does; ``df.attrs["units"]``
    names each column's units and ``df.attrs["units_system"]`` the system (``units`` given
    here, else the file's ``units`` key, else cgs: see :func:`file_units`).

    ``method="generalized-alpha"`` (default) reproduces svZeroDSolver's integrator, step and
    Newton tolerance. ``method="rk4"`` uses oxyline's explicit RK4 with a stable sub-step
    inside each output step (outputs at the same times). Inductor flows a FLOW condition fixes
    (e.g. an R-L vessel fed by a FLOW condition) are made algebraic first; circuits still
    singular after that raise :class:`oxyline.ModelError`. ``rk4_substeps`` sets the RK4
    sub-steps per output step (default: half the stability limit, and the spacing of the time
    tables); a smaller sub-step resolves a steep valve's switch (docs/physics.md §1.8).

    ``output_variable_based`` gives svZeroDSolver's variable table (``name, time, y``: the
    flow and pressure of each of its nodes, then internal variables such as an RCR's
    ``pressure_c``); ``output_derivative`` adds the time derivatives (``d_*`` columns or
    ``ydot``) the core records: generalized-α's own ẏ, as svZeroDSolver reports it, or with
    RK4 the exact rate of the state at each output time, algebraic unknowns included (see
    docs/svzerod.md). The core runs the whole configuration in one call, svZeroDSolver's
    cycle-to-cycle rule included; this function reads the file and formats the rows.
    """
    import pandas as pd

    if method not in METHODS:
        raise ModelError(f"simulate: method must be one of {', '.join(METHODS)}, got {method!r}")
    native, s, layout = _convert(config, units)
    if rk4_substeps is not None:
        if method != "rk4" or int(rk4_substeps) < 1:
            raise ModelError(f"simulate: rk4_substeps={rk4_substeps!r} needs method='rk4' and "
                             "a positive integer")
        s = dataclasses.replace(s, rk4_substeps=int(rk4_substeps))
    # record every native vessel an output comes from (the hidden parts of a BloodVesselCRL
    # and of a resistive junction too); the drop-in runs in the file's own units, as
    # svZeroDSolver does (same numbers, same Newton tolerance): the equations do not depend
    # on them
    needed = {x for _, a, b in layout.vessels for x in (a, b)}
    needed |= {ref[0] for kind, _, ref in layout.internal if kind == "junction"}
    vessels = [dict(v, output=True) if v["name"] in needed else v for v in native["vessels"]]
    model = _build({**native, "vessels": vessels, "units": "SI"}, plausibility=s.units == "SI")
    recorded = {v["name"]: 4 * k for k, v in enumerate(x for x in vessels if x.get("output", True))}
    chambers = [v["name"] for v in native["vessels"] if "chamber" in v]
    elements = chambers or layout.spheres or any(k in ELEMENT_KINDS for k, _, _ in
                                                 layout.internal)
    if s.output_variable_based and elements:
        # the elements' variables are unknowns of the core no vessel column holds
        names, columns = _output_columns(layout, recorded, True, model.network, chambers)
        s = dataclasses.replace(s, all_unknowns=True)
    else:
        names, columns = _output_columns(layout, recorded, s.output_variable_based)
    shape = (len(names), 1 if s.output_variable_based else 4)
    _check_output_memory(s, shape)
    rules: dict[str, Any] = {"derived": columns.derived, "rates": s.output_derivative}
    if s.cycle_error is not None:
        ends = {name: (a, b) for name, a, b in layout.vessels}
        probe = model.network.unknown_layout()["vessel_unknowns"]
        # a cap's flow and pressure (svZeroDSolver's order), as unknowns of the core
        caps = [int(probe[recorded[ends[v][end == "out"]] + k])
                for v, end in s.caps for k in ((2, 0) if end == "in" else (3, 1))]
        rules["cycle_mean_stop"] = {"caps": caps, "tolerance": s.cycle_error,
                                    "max_extra": MAX_EXTRA_CYCLES}
    times, values, derivs = _run(model, native, s, method, columns, shape, rules)
    return _frame(pd, names, times, values, derivs, s)


#: svZeroDSolver's block order of the internal variables in its variable table (after the
#: ChamberSphere vessels' wall variables; the chambers' ``Vc`` come last)
INTERNAL_ORDER = {"rcr": 1, "ClosedLoopRCR": 1, "ClosedLoopCoronary": 1, "CORONARY": 1,
                  "junction": 2, "heart": 3, "valve": 4}
#: the internal variables read from the core's element unknowns (the run records every one)
ELEMENT_KINDS = {"ClosedLoopCoronary", "CORONARY", "heart", "valve"}
#: the most cycles the cycle-to-cycle rule may add before the drop-in gives up
#: (svZeroDSolver itself has no cap and would run forever)
MAX_EXTRA_CYCLES = 2000


@dataclasses.dataclass
class Columns:
    """Output column j is recorded column ``idx[j]`` plus ``w`` times recorded column ``c``
    for each (j, c, w) in ``extra``; a negative ``idx[j]`` = −1 − k is the core's derived
    column k (``derived``: a tanh valve's ``valve_status``, a coronary's ``volume_im``,
    recorded after the columns; see ``oxyline_core::run::svzerod``)."""

    idx: np.ndarray
    extra: list[tuple[int, int, float]]
    derived: list[tuple[Any, ...]]


def _output_columns(layout: _Layout, recorded: Mapping[str, int], variable_based: bool,
                    network: Any = None, chambers: Sequence[str] = ()
                    ) -> tuple[list[str], Columns]:
    """The output names and columns. Recorded columns are each recorded vessel's pressure_in,
    pressure_out, flow_in, flow_out (at ``recorded[vessel] + 0 .. 3``); with ``network`` (the
    core network of a run recording every unknown) they are its unknowns instead, and the
    variable table has the elements' variables too (ChamberSphere walls, closed-loop
    coronary volumes, the heart block's variables, tanh valves' status, chambers' ``Vc``)."""
    ends = {name: (a, b) for name, a, b in layout.vessels}
    if not variable_based:
        shown = [n for n, _, _ in layout.vessels if n not in layout.not_vessels]
        idx = [recorded[ends[n][0]] + k if k in (0, 2) else recorded[ends[n][1]] + k
               for n in shown for k in range(4)]
        return shown, Columns(np.asarray(idx, dtype=np.intp), [], [])
    lay = None if network is None else network.unknown_layout()
    probe = None if lay is None else np.asarray(lay["vessel_unknowns"], dtype=np.intp)

    def col(vessel: str, k: int) -> int:
        c = recorded[vessel] + k
        return c if probe is None else int(probe[c])

    names: list[str] = []
    idx: list[int] = []
    extra: list[tuple[int, int, float]] = []
    derived: list[tuple[Any, ...]] = []
    node_of: dict[str, tuple[str, int, int]] = {}  # a condition's node: (vessel, p, q)
    for up, down in layout.connections:
        # a node's flow and pressure are those of the vessel end it joins
        v, p, q = (ends[down][0], 0, 2) if down in ends else (ends[up][1], 1, 3)
        node_of.setdefault(up, (v, p, q))
        node_of.setdefault(down, (v, p, q))
        names += [f"flow:{up}:{down}", f"pressure:{up}:{down}"]
        idx += [col(v, q), col(v, p)]
    element = {} if lay is None else dict(lay.get("element_unknowns", []))
    # a ChamberSphere is a vessel, svZeroDSolver's first blocks
    for name in (f"{var}:{s}" for s in layout.spheres for var in svzerod_heart.SPHERE_VARIABLES):
        names.append(name)
        idx.append(element[name])
    for kind, name, ref in sorted(layout.internal, key=lambda e: INTERNAL_ORDER[e[0]]):
        if kind in ELEMENT_KINDS and lay is None:
            raise ModelError(f"internal error: '{name}' needs every unknown recorded")
        if kind == "rcr":  # P_c = P - Rp Q at the Windkessel's node (Q along the vessel)
            v, p, q = node_of[name]
            names.append(f"pressure_c:{name}")
            idx.append(col(v, p))
            extra.append((len(idx) - 1, col(v, q), -float(ref)))
        elif kind == "junction":  # the resistive junction's centre: a port's hidden vessel end
            names.append(f"pressure_c:{name}")
            idx.append(col(ref[0], ref[1]))
        elif kind == "ClosedLoopRCR":  # P_c: the capacitor node, its Rp-C vessel's outlet
            names.append(f"P_c:{name}")
            idx.append(col(ref, 1))
        elif kind == "ClosedLoopCoronary":
            names.append(f"volume_im:{name}")
            idx.append(element[f"volume_im:{ref}"])
        elif kind == "CORONARY":
            # V_im = C_im (u − u(0)), u = P_c − P_im the compartment node's unknown: svZeroDSolver
            # measures V_im from the start (its P_Cim_0 after the steady start also holds a
            # leftover R_am C_a (Ṗ_in − R_a Q̇_in) of ẏ₀, −6.5e-10 mL in steadyFlow_R_coronary,
            # taken as 0 here)
            names.append(f"volume_im:{name}")
            u = network.unknown_names().index(
                f"pressure at boundary condition '{name}' intramyocardial compartment")
            derived.append(("from_start", u, float(ref)))
            idx.append(-len(derived))
        elif kind == "heart":
            heart_cols = _heart_columns(lay, name)
            names += [f"{var}:{name}" for var, _ in svzerod_closed_loop.VARIABLES]
            idx += heart_cols
        else:  # a tanh valve: svZeroDSolver's valve_status, followed by the core
            names.append(f"valve_status:{name}")
            derived.append(("valve_status", name))
            idx.append(-len(derived))
    if lay is not None:  # svZeroDSolver's chambers are its last blocks
        volume = dict(lay["chamber_volumes"])
        names += [f"Vc:{c}" for c in chambers]
        idx += [volume[c] for c in chambers]
    return names, Columns(np.asarray(idx, dtype=np.intp), extra, derived)


def _heart_columns(lay: Mapping[str, Any], heart: str) -> list[int]:
    """The unknowns of the heart block's variables (svzerod_closed_loop.VARIABLES)."""
    volume = dict(lay["chamber_volumes"])
    valve = {n: u for n, u, _ in lay["valves"]}
    return [int(volume[f"{heart}:{where}"]) if isinstance(where, str)
            else int(valve[f"{heart}:{where[0]}"][where[1]])
            for _, where in svzerod_closed_loop.VARIABLES]


def _apply(data: np.ndarray, columns: Columns, rates: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """The output columns (and, with ``rates``, their derivatives) of the core's rows
    [recorded | derived | (their rates)]."""
    nd = len(columns.derived)
    width = (data.shape[1] - 2 * nd) // 2 if rates else data.shape[1] - nd
    idx = np.where(columns.idx < 0, width - 1 - columns.idx, columns.idx)

    def pick(block: np.ndarray) -> np.ndarray:
        out = block[:, idx]
        for j, c, w in columns.extra:
            out[:, j] += w * block[:, c]
        return out

    if not rates:
        return pick(data), None
    return pick(data[:, :width + nd]), pick(data[:, width + nd:])


#: the most RK4 steps the drop-in takes before refusing a stiff model (about a minute of a
#: small circuit's steps)
RK4_MAX_STEPS = 5e7


def _core_kwargs(model: Model, native: Mapping[str, Any], s: RunSettings, method: str
                 ) -> tuple[dict[str, Any], int]:
    """The core's run settings for svZeroDSolver's, and the RK4 sub-steps per output step."""
    kw: dict[str, Any] = {
        "period": s.period, "cycles": s.cycles, "method": method, "rho_infty": s.rho_infty,
        "start": "svzerod-steady" if s.steady_initial else "svzerod-zero",
        "newton_atol": s.absolute_tolerance, "max_iterations": s.max_iterations,
        "output_all_cycles": s.output_all_cycles, "segments": False,
    }
    if s.all_unknowns:
        kw["all_unknowns"] = True
    if method == "generalized-alpha":
        kw["dt"] = s.dt
        return kw, 1
    # sub-steps per output step: stable (half the RK4 limit) and resolving the time tables
    dt_max, element, _ = model.network.rk4_stability_limit()
    h = min([0.5 * dt_max] + _table_spacings(native))
    sub = max(1, math.ceil(s.dt / h * (1.0 - 1e-12)))
    if s.rk4_substeps is not None:
        if s.rk4_substeps < sub and s.dt / s.rk4_substeps > 0.5 * dt_max:
            raise ModelError(
                f"rk4_substeps={s.rk4_substeps}: the sub-step {s.dt / s.rk4_substeps:.3g} s "
                f"exceeds half the RK4 stability limit {dt_max:.3g} s (set by {element})")
        sub = s.rk4_substeps
    else:
        sub *= _switch_refinement(model, kw, s, sub)
    steps = sub * (s.points_per_cycle - 1) * s.cycles
    if steps > RK4_MAX_STEPS:
        # e.g. a closed valve behind a chamber's outlet inductor: R_max/L is a nanosecond
        # time constant (docs/physics.md §1.8), which only an implicit step passes over
        raise ModelError(
            f"rk4 cannot integrate this model in reasonable time: its stability limit "
            f"{dt_max:.3g} s (set by {element}) needs {steps:.3g} steps, more than "
            f"{RK4_MAX_STEPS:.0e}; use method='generalized-alpha'")
    kw["dt"] = s.dt / sub
    return kw, sub


#: the accuracy the RK4 step of a model with valves or chambers is refined to: the estimated
#: error of the first cycles, scaled by each unknown's range (the core's
#: ``rk4_step_refinement``, docs/physics.md §1.8)
RK4_SWITCH_TOL = 1e-2
#: the most the RK4 step is divided by for that accuracy
RK4_MAX_REFINEMENT = 64


def _switch_refinement(model: Model, kw: Mapping[str, Any], s: RunSettings, sub: int) -> int:
    """The factor by which the core's step-doubling criterion divides the RK4 sub-step (1
    without valves or chambers), at most ``RK4_MAX_REFINEMENT`` and within ``RK4_MAX_STEPS``;
    the trial runs (the run's first cycles, up to 2e4 steps) cost up to 2 ``max_factor`` times
    as many steps."""
    budget = RK4_MAX_STEPS / (sub * (s.points_per_cycle - 1) * s.cycles)
    max_factor = 1
    while 2 * max_factor <= min(RK4_MAX_REFINEMENT, budget):
        max_factor *= 2
    if max_factor == 1:
        return 1
    settings = {k: v for k, v in kw.items() if k not in ("period", "all_unknowns")}
    factor, _, _ = model.network.rk4_step_refinement(
        period=s.period, output_every=s.dt, tol=RK4_SWITCH_TOL, max_factor=max_factor,
        dt=s.dt / sub, **settings)
    return int(factor)


#: bytes per output value while the table is built: the core's rows, the values array, the
#: step indices and times, and the DataFrame's long format (measured ~40 B per value)
OUTPUT_BYTES_PER_VALUE = 48


def _check_output_memory(s: RunSettings, shape: tuple[int, int]) -> None:
    """Refuse an output table the memory allowed cannot hold (ResourceError naming the
    settings that size it), before anything of it is allocated."""
    from oxyline import memory as _memory

    steps = (s.points_per_cycle - 1) * (s.cycles if s.output_all_cycles else 1)
    rows = steps // s.output_interval + 1
    need = float(rows) * shape[0] * shape[1] * OUTPUT_BYTES_PER_VALUE
    limit = _memory.default_limit()
    if limit is not None and need > limit:
        raise ResourceError(
            f"simulation_parameters: the output ({rows} times x {shape[0] * shape[1]} values) "
            f"needs about {_memory.human(need)} of memory (estimate), above the "
            f"{_memory.human(limit)} allowed; lower number_of_time_pts_per_cardiac_cycle or "
            "number_of_cardiac_cycles (with output_all_cycles), or raise output_interval")


def _simulate(model: Model, kw: Mapping[str, Any], rules: Mapping[str, Any],
              **stream: Any) -> Mapping[str, Any]:
    """One core run of the drop-in; its error raised."""
    with core_errors("svZeroDSolver run"):
        raw = model.network.simulate(**kw, svzerod=dict(rules), **stream)
    if "error" in raw:
        raise raw["error"]
    return raw


def _run(model: Model, native: Mapping[str, Any], s: RunSettings, method: str,
         columns: Columns, shape: tuple[int, int], rules: Mapping[str, Any]
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One core run: (times, (output, time, width) values, derivatives or None) at
    svZeroDSolver's output rows, ``shape`` = (outputs, width: 4 quantities of a vessel or 1
    variable)."""
    if "cycle_mean_stop" in rules:
        return _run_cycle_error(model, native, s, method, columns, shape, rules)
    k = s.output_interval
    # the global step indices svZeroDSolver outputs, from the first one
    steps = s.points_per_cycle - 1
    first = 0 if s.output_all_cycles else steps * (s.cycles - 1)
    wanted = np.arange(first, steps * s.cycles + 1, k)
    # the core records every `stride`-th global step (and the start of the last cycle)
    if method == "generalized-alpha" and (s.output_all_cycles or first % k == 0):
        stride = k
    else:
        stride = 1
    kw, _ = _core_kwargs(model, native, s, method)
    kw["output_every"] = s.dt * stride if method == "generalized-alpha" else s.dt
    rates = bool(rules["rates"])
    # The core streams its rows in small chunks, each written straight into the output-major
    # (output, time, width) block that becomes the DataFrame's float block: the run never
    # holds a second, time-major copy of the output (the largest allocation at 10^4 vessels).
    values = np.empty((shape[0], wanted.size, shape[1]))
    derivs = np.empty_like(values) if rates else None
    core_times: list[np.ndarray] = []
    count = {"core": 0, "out": 0}

    def take(chunk: Mapping[str, Any]) -> None:
        t = np.asarray(chunk["times"])
        data = np.asarray(chunk["data"]).reshape(len(t), -1)
        first_row = count["core"]
        count["core"] += len(t)
        if stride == 1:  # every core row recorded: keep svZeroDSolver's every k-th
            keep = (first_row + np.arange(len(t))) % k == 0
            t, data = t[keep], data[keep]
        o, n = count["out"], len(t)
        if o + n > wanted.size:
            raise ModelError(f"internal error: more than {wanted.size} output rows from the core")
        y, yd = _apply(data, columns, rates)
        values[:, o:o + n, :] = y.reshape(n, *shape).transpose(1, 0, 2)
        if derivs is not None and yd is not None:
            derivs[:, o:o + n, :] = yd.reshape(n, *shape).transpose(1, 0, 2)
        core_times.append(t)
        count["out"] = o + n

    chunk_rows = max(1, (1 << 20) // max(1, shape[0] * shape[1]))  # ~8 MB per chunk
    _simulate(model, kw, rules, chunk_sink=take, chunk_rows=chunk_rows,
              keep_current_cycle=False)
    if count["out"] != wanted.size:
        raise ModelError(f"internal error: {count['out']} output rows from the core, "
                         f"expected {wanted.size}")
    times = s.dt * wanted.astype(float)
    if not s.output_all_cycles:
        times = times - s.dt * float(first)
    got = np.concatenate(core_times) if core_times else np.empty(0)
    if np.max(np.abs(got - times), initial=0.0) > 1e-9 * s.period * max(1, s.cycles):
        raise ModelError("internal error: output times of the core do not match svZeroDSolver's")
    return times, values, derivs


def _blocks(a: np.ndarray, rows: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(time, output x width) rows -> (output, time, width)."""
    return np.ascontiguousarray(a[rows].reshape(len(rows), *shape).transpose(1, 0, 2))


def _run_cycle_error(model: Model, native: Mapping[str, Any], s: RunSettings, method: str,
                     columns: Columns, shape: tuple[int, int], rules: Mapping[str, Any]
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """svZeroDSolver's extra cycles without RCR: the core runs until its cycle-to-cycle rule
    holds, recording every output step; the rows svZeroDSolver outputs are picked from
    them (the core's ``svzerod_output_rows``)."""
    steps = s.points_per_cycle - 1
    kw, _ = _core_kwargs(model, native, s, method)
    kw.update(output_all_cycles=True, output_every=s.dt)
    raw = _simulate(model, kw, rules)
    t = np.asarray(raw["times"])
    extra = int(raw["cycles_run"]) - s.cycles
    if len(t) != steps * (s.cycles + extra) + 1:
        raise ModelError(f"internal error: {len(t)} rows from the core")
    y, yd = _apply(np.asarray(raw["data"]).reshape(len(t), -1), columns, bool(rules["rates"]))
    rows, times = _core.svzerod_output_rows(s.cycles, steps, extra, s.output_interval,
                                            s.output_all_cycles)
    return s.dt * times, _blocks(y, rows, shape), None if yd is None else _blocks(yd, rows, shape)


def _frame(pd: Any, names: list[str], times: np.ndarray, values: np.ndarray,
           derivs: np.ndarray | None, s: RunSettings) -> Any:
    """svzerod.simulate's frame from (output, time, width) values (and derivatives)."""
    nv, nt = len(names), len(times)
    if s.output_variable_based:
        cols = {"y": values[:, :, 0]}
        if derivs is not None:
            cols["ydot"] = derivs[:, :, 0]
    else:
        if derivs is None and not s.output_mean_only:
            frame = long_table_vessel_major(names, times, values.reshape(nv * nt, 4))
            return _with_units(frame, s)
        # values hold pressure_in, pressure_out, flow_in, flow_out; svzerod's column order
        order = {"flow_in": 2, "flow_out": 3, "pressure_in": 0, "pressure_out": 1}
        cols = {c: values[:, :, k] for c, k in order.items()}
        if derivs is not None:
            cols.update({f"d_{c}": derivs[:, :, k] for c, k in order.items()})
    if s.output_mean_only:
        data = {"name": names, "time": np.full(nv, np.nan)}
        data.update({c: v.mean(axis=1) for c, v in cols.items()})
    else:
        data = {"name": np.repeat(np.array(names, dtype=object), nt),
                "time": np.tile(times, nv)}
        data.update({c: v.reshape(nv * nt) for c, v in cols.items()})
    return _with_units(pd.DataFrame(data), s)


def _with_units(frame: Any, s: RunSettings) -> Any:
    units = dict(FRAME_UNITS[s.units])
    if s.output_variable_based:
        units = {"time": "s"}
    elif s.output_derivative:
        units.update({f"d_{c}": f"{u}/s" for c, u in FRAME_UNITS[s.units].items() if c != "time"})
    frame.attrs["units"] = units
    frame.attrs["units_system"] = s.units
    return frame


__all__ = ["simulate"]
