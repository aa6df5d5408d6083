"""Simulation results: zero-copy numpy views of the arrays written by the Rust core, with
xarray/pandas conversions."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.io import results

# the column schema is the core's (oxyline_core::output): no column name is written here
VESSEL_VARIABLES: tuple[str, ...] = tuple(_core.VESSEL_VARIABLES)
SEGMENT_VARIABLES: tuple[str, ...] = tuple(_core.SEGMENT_VARIABLES)
UNITS = {
    "pressure_in": "Pa", "pressure_out": "Pa", "flow_in": "m^3/s", "flow_out": "m^3/s",
    "segment_pressure_in": "Pa", "segment_pressure_out": "Pa", "segment_flow": "m^3/s",
    "time": "s", "segment_position": "m",
}


@dataclass
class VesselResult:
    """Waveforms of one vessel (SI units); segment arrays have shape (time, segment).

    >>> import oxyline
    >>> v = oxyline.simulate("bifurcation", cycles=1).vessel("parent")
    >>> v.name, v.flow_in.shape == v.time.shape, v.segment_flow.shape[1]
    ('parent', True, 10)
    """

    name: str
    time: np.ndarray
    # None when the output selection left the variable out
    pressure_in: np.ndarray | None
    pressure_out: np.ndarray | None
    flow_in: np.ndarray | None
    flow_out: np.ndarray | None
    segment_pressure_in: np.ndarray | None = None
    segment_pressure_out: np.ndarray | None = None
    segment_flow: np.ndarray | None = None
    segment_position: np.ndarray | None = None


SPECIES_VESSEL: tuple[str, ...] = tuple(_core.SPECIES_VESSEL_VARIABLES)
#: species segment variables as SpeciesResult attributes (the schema's names without the
#: ``segment_`` prefix that selects them in ``output.variables``)
SPECIES_SEGMENT: tuple[str, ...] = tuple(n.removeprefix("segment_")
                                         for n in _core.SPECIES_SEGMENT_VARIABLES)
BALANCE: tuple[str, ...] = tuple(_core.BALANCE_VARIABLES)
#: tissue-wall variables (docs/physics.md §3.7): per vessel, per segment, wall balance
TISSUE_VESSEL: tuple[str, ...] = tuple(getattr(_core, "TISSUE_VESSEL_VARIABLES", ()))
TISSUE_SEGMENT: tuple[str, ...] = tuple(getattr(_core, "TISSUE_SEGMENT_VARIABLES", ()))
TISSUE_BALANCE: tuple[str, ...] = tuple(getattr(_core, "TISSUE_BALANCE_VARIABLES", ()))


def _not_selected(name: str) -> AttributeError:
    return AttributeError(f"'{name}' is not in this result's output selection "
                          "(simulation output: variables)")


def _column(block: str, name: str) -> property:
    """A read-only attribute: the output variable ``name`` of every output vessel (``block``
    ``"_vessel_var"``) or segment (``"_segment_var"``), shape (time, vessel or segment)."""
    return property(lambda self: getattr(self, block)(name),
                    doc=f"``{name}``, shape (time, vessel or segment).")


@dataclass
class TissueResult:
    """Wall/tissue compartment of one species (docs/physics.md §3.7), for every output vessel
    and segment of the network: ``vessel_data`` (time, vessel, 4) and ``segment_data`` (time,
    segment, 4) hold the innermost, outermost and minimum wall value as the lumen-equivalent
    free concentration (mol/m^3; × 1/solubility = PO2 for oxygen) and the hypoxic volume
    fraction; ``balance_data`` (time, 4) the wall amount and the cumulative lumen → wall,
    consumed and outer-inflow amounts (mol)."""

    vessels: list[str]
    segment_count: list[int]
    vessel_data: np.ndarray
    segment_data: np.ndarray
    balance_data: np.ndarray

    def vessel(self, key: str) -> np.ndarray:
        """(time, vessel) array of a TISSUE_VESSEL variable."""
        return self.vessel_data[:, :, TISSUE_VESSEL.index(key)]

    def segment(self, key: str) -> np.ndarray:
        """(time, segment) array of a TISSUE_SEGMENT variable (with or without ``segment_``)."""
        return self.segment_data[:, :, TISSUE_SEGMENT.index(
            key if key.startswith("segment_") else f"segment_{key}")]

    @property
    def mass_balance(self) -> dict[str, np.ndarray]:
        """The wall's balance over the recorded rows (mol, changes since the first row):
        ``stored``, ``influx`` (from the lumen), ``consumed``, ``outer_inflow`` and
        ``residual`` = stored − (influx − consumed + outer_inflow)."""
        b = self.balance_data
        b = b - b[:1]
        out = {k.removeprefix("wall_"): b[:, i] for i, k in enumerate(TISSUE_BALANCE)}
        out["residual"] = out["stored"] - (out["influx"] - out["consumed"] + out["outer_inflow"])
        return out


@dataclass
class SpeciesResult:
    """Transport outputs of one species (SI). Concentrations are the free (dissolved) values,
    fluxes carry the total (free + bound) amount; ``concentration_in``/``_out`` are the values at
    the vessel's end faces (the upwind value carried into the cell of its first segment, the
    value leaving the cell of its last: docs/oxygen.md "Vessel ends"), ``flux_in``/``flux_out``
    Q·C there with Q = ``flow_in``/``flow_out``, ``wall_flux`` the uptake of the vessel's segments (mol/s, positive out of the blood).
    Segment ``tl_resistance``/``tl_inductance`` are the paper's R_i = dL_i/dt (dimensionless)
    and L_i = −dx/v (s), NaN where |v| < the velocity threshold."""

    name: str
    vessel_data: np.ndarray  # (time, vessel, selected vessel variables; all 5 by default)
    segment_data: np.ndarray  # (time, segment, selected segment variables; all 5 by default)
    balance_data: np.ndarray  # (time, 5): stored, inflow, outflow, wall, decay (cumulative)
    initial_stored: float
    #: mmHg per mol/m^3 (1/solubility) for oxygen, else None
    po2_per_concentration: float | None = None
    #: the recorded variables (the last axis of vessel_data / segment_data)
    vessel_variables: tuple[str, ...] = SPECIES_VESSEL
    segment_variables: tuple[str, ...] = SPECIES_SEGMENT
    #: the wall/tissue compartment's outputs (None without a tissue wall)
    tissue: TissueResult | None = None

    def __getattr__(self, key: str) -> np.ndarray:
        d = self.__dict__
        if key in SPECIES_VESSEL:
            if key not in d.get("vessel_variables", SPECIES_VESSEL):
                raise _not_selected(key)
            return self.vessel_data[:, :, d["vessel_variables"].index(key)]
        if key in SPECIES_SEGMENT:
            if key not in d.get("segment_variables", SPECIES_SEGMENT):
                raise _not_selected(f"segment_{key}")
            return self.segment_data[:, :, d["segment_variables"].index(key)]
        raise AttributeError(key)

    def segment(self, key: str) -> np.ndarray:
        """A segment variable by its schema name without ``segment_`` (``wall_flux`` here is
        the segments' wall flux, where the attribute ``wall_flux`` is the vessels')."""
        if key not in self.segment_variables:
            raise _not_selected(f"segment_{key}")
        return self.segment_data[:, :, self.segment_variables.index(key)]

    @property
    def mass_balance(self) -> dict[str, np.ndarray]:
        """Cumulative amounts since t = 0 (mol) at every output time: ``inflow``, ``outflow``,
        ``wall_uptake``, ``decay``, ``stored`` (change of the amount in the network) and
        ``residual`` = stored − (inflow − outflow − wall_uptake − decay)."""
        b = self.balance_data
        out = {k: b[:, i] for i, k in enumerate(BALANCE)}
        out["stored"] = out["stored"] - self.initial_stored
        out["residual"] = out["stored"] - (out["inflow"] - out["outflow"] - out["wall_uptake"]
                                           - out["decay"])
        return out


#: the largest model description (JSON characters) a result file keeps in its attributes:
#: a NetCDF attribute is one HDF5 object-header message, at most 64 KiB
MAX_MODEL_JSON = 60_000


@dataclass
class Result:
    """Output of :func:`oxyline.simulate`.

    ``data`` is the (time, column) array produced by the core; the attributes below are views
    into it (no copies). Times start at 0 for the last-cycle output.

    >>> import oxyline
    >>> res = oxyline.simulate("bifurcation", cycles=1)
    >>> res.model_name, res.vessels
    ('bifurcation', ['parent', 'daughter1', 'daughter2'])
    >>> res.pressure_in.shape == (res.time.size, 3)
    True
    >>> float(res.summary().loc["parent", "flow_in_mean"]) > 0
    True
    """

    model_name: str
    vessels: list[str]
    time: np.ndarray
    data: np.ndarray
    segment_count: list[int]
    segment_position: np.ndarray
    settings: dict[str, Any] = field(default_factory=dict)
    complete: bool = True
    #: species transport outputs by species name (empty for flow-only models)
    species: dict[str, SpeciesResult] = field(default_factory=dict)
    #: name of the oxygen species, if the model has an ``oxygen`` section
    oxygen: str | None = None
    #: the recorded flow variables (an output selection records fewer; all by default)
    vessel_variables: tuple[str, ...] = VESSEL_VARIABLES
    segment_variables: tuple[str, ...] = SEGMENT_VARIABLES
    #: blood volume (m^3) of every chamber over time: each ``chamber`` vessel, and a
    #: ``heart_pulmonary`` block's four chambers as ``<vessel>:right_atrium`` …
    #: ``<vessel>:left_ventricle`` (empty without chambers)
    chamber_volume: dict[str, np.ndarray] = field(default_factory=dict)
    #: 1 while a valve is open, 0 while closed, over time: each ``valve`` vessel (open while
    #: the pressure behind exceeds the pressure in front) and a heart block's four valves
    #: ``<vessel>:tricuspid|pulmonary|mitral|aortic`` (its on/off rule: open also while the
    #: flow is positive; docs/physics.md §1.10)
    valve_status: dict[str, np.ndarray] = field(default_factory=dict)
    #: the valves' status changes an error-controlled run located (docs/physics.md §10.5):
    #: (run time in s from the run's start, valve name as in ``valve_status``, True for an
    #: opening), in time order; empty for a fixed step
    valve_events: list[tuple[float, str, bool]] = field(default_factory=list)
    #: an error-controlled run's step-size history (docs/solvers.md, "Step-size history"):
    #: the accepted steps of its last cycle, each step's start as time into that cycle (s,
    #: 0 … period, as :attr:`time` of a last-cycle output) and its size (s); empty for a fixed
    #: step. A file (NetCDF, Zarr) keeps them as the variable ``step_size`` over its own
    #: dimension ``step_time`` (:meth:`to_xarray` leaves them out: its dims are the output's).
    step_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    step_sizes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: with ``simulate(..., estimate_time_error=True)``: every vessel's accumulated
    #: time-integration error (docs/solvers.md, "The accumulated error") as a
    #: ``pandas.DataFrame`` (index ``vessel``; columns ``flow``, ``pressure``,
    #: ``pulse_pressure`` and, with oxygen, ``po2``: each against the vessel's own scale, as
    #: :class:`oxyline.TimeErrorEstimate.per_vessel`); None otherwise. NetCDF/Zarr files
    #: keep it as the variables ``time_error_<kind>`` over ``vessel`` (:meth:`to_xarray`
    #: leaves them out), read back by :func:`oxyline.open_result`.
    time_error: Any = None
    #: the model it was run from, as JSON in the native schema (SI), so that a result file
    #: rebuilds its model (``oxyline plot`` needs no ``--model``); None above
    #: :data:`MAX_MODEL_JSON` characters (a whole tree), where only the name is kept
    model_json: str | None = None
    #: a large model's default run (oxyline.large_output): the per-vessel table of
    #: :meth:`summary` of every vessel, reduced during the run; the time series above are then
    #: the inlet vessels' only. None otherwise (:meth:`summary` computes from the output)
    vessel_summary: Any = None

    def __repr__(self) -> str:
        """One line of facts, not the arrays (a notebook echoes a result whole)."""
        t = self.time
        span = f"{t[0]:g}-{t[-1]:g} s" if len(t) else "empty"
        species = f", species={list(self.species)}" if self.species else ""
        state = "" if self.complete else ", complete=False"
        return (f"<oxyline.Result model={self.model_name!r}: {len(self.vessels)} vessels, "
                f"{sum(self.segment_count)} segments, {len(t)} times ({span}){species}{state}>")

    @property
    def error_estimate(self) -> dict[str, float]:
        """An error-controlled run's (the default without ``dt``, or ``rtol``) largest
        estimated error per kind of unknown over the run (``pressure``, ``flow``, and
        ``volume``/``species`` where present),
        relative to atol/rtol + |y| (docs/physics.md §10): at most ``rtol`` where the step
        control met its tolerance. Empty for a fixed-step run. With
        ``simulate(..., estimate_space_error=True)`` also ``space``: the largest relative
        change of the inlet impedance over the forcing's significant harmonics under one
        doubling of every vessel's segments (docs/solvers.md, "Space"). Stored in the file
        attributes as ``solver_error_estimate_<kind>``.

        With ``simulate(..., estimate_time_error=True)`` the kinds are instead the
        *accumulated* error the output carries, the worst vessel's against its own scale
        (``flow``, ``pressure``, ``pulse_pressure``, ``po2``; that vessel in
        ``settings["time_error_vessel_<kind>"]``, every vessel's in :attr:`time_error`),
        and the step control's local estimates are :attr:`local_error_estimate`
        (docs/solvers.md, "The accumulated error")."""
        pre = "error_estimate_"
        return {k.removeprefix(pre): float(v) for k, v in self.settings.items()
                if k.startswith(pre)}

    @property
    def local_error_estimate(self) -> dict[str, float]:
        """The step control's largest *local* error estimate per kind of unknown (relative to
        atol/rtol + |y|, at most ``rtol`` where it met its tolerance): what
        :attr:`error_estimate` holds unless the run estimated its accumulated error
        (``estimate_time_error=True``). Empty for a fixed-step run.

        >>> import oxyline
        >>> res = oxyline.simulate("bifurcation", cycles=1, rtol=1e-2)
        >>> res.local_error_estimate["flow"] <= 1e-2
        True
        """
        pre = "local_error_estimate_"
        if any(k.startswith(pre) for k in self.settings):
            return {k.removeprefix(pre): float(v) for k, v in self.settings.items()
                    if k.startswith(pre)}
        return {k: v for k, v in self.error_estimate.items() if k != "space"}

    def __getattr__(self, key: str) -> Any:
        # species variables: {name}_concentration_in, {name}_flux_out, wall_{name}_flux,
        # segment_{name}_concentration, ..., {name}_mass_balance; oxygen adds po2_in/po2_out,
        # segment_po2 (mmHg) and tl_resistance/tl_inductance.
        if key in VESSEL_VARIABLES or key in SEGMENT_VARIABLES:  # a property left out
            raise _not_selected(key)
        species = self.__dict__.get("species") or {}
        if not species:
            raise AttributeError(key)
        ox = self.__dict__.get("oxygen")
        if ox is not None and ox in species:
            sp = species[ox]
            scale = sp.po2_per_concentration or float("nan")
            if key == "po2_in":
                return sp.concentration_in * scale
            if key == "po2_out":
                return sp.concentration_out * scale
            if key == "segment_po2":
                return sp.concentration * scale
        if key in ("tl_resistance", "tl_inductance"):
            return getattr(next(iter(species.values())), key)
        if "wall_" in key or "hypoxic" in key:  # tissue-wall variables (species_variables)
            tissue = self._tissue_variables()
            if key in tissue:
                return tissue[key][1]
        if key == "mass_balance":
            return {n: s.mass_balance for n, s in species.items()}
        for name, sp in species.items():
            if key.startswith(f"segment_wall_{name}_") and key.endswith("flux"):
                return sp.segment("wall_flux")
            if key == f"wall_{name}_flux":
                return sp.wall_flux
            if key == f"{name}_mass_balance":
                return sp.mass_balance
            if key.startswith(f"segment_{name}_"):
                rest = key[len(f"segment_{name}_"):]
                if rest in ("concentration", "flux"):
                    return getattr(sp, rest)
            if key.startswith(f"{name}_"):
                rest = key[len(name) + 1:]
                if rest in ("concentration_in", "concentration_out", "flux_in", "flux_out"):
                    return getattr(sp, rest)
        raise AttributeError(key)

    def species_variables(self) -> dict[str, tuple[str, np.ndarray, str]]:
        """Every species output as name -> (dimension kind 'vessel'|'segment'|'time', array,
        units)."""
        out: dict[str, tuple[str, np.ndarray, str]] = {}
        for name, sp in self.species.items():
            vv, sv = sp.vessel_variables, sp.segment_variables
            for v, u in (("concentration_in", "mol/m^3"), ("concentration_out", "mol/m^3"),
                         ("flux_in", "mol/s"), ("flux_out", "mol/s")):
                if v in vv:
                    out[f"{name}_{v}"] = ("vessel", getattr(sp, v), u)
            if "wall_flux" in vv:
                out[f"wall_{name}_flux"] = ("vessel", sp.wall_flux, "mol/s")
            if "concentration" in sv:
                out[f"segment_{name}_concentration"] = ("segment", sp.concentration, "mol/m^3")
            if "flux" in sv:
                out[f"segment_{name}_flux"] = ("segment", sp.flux, "mol/s")
            if "wall_flux" in sv:
                out[f"segment_wall_{name}_flux"] = ("segment", sp.segment("wall_flux"), "mol/s")
            for k, arr in sp.mass_balance.items():
                out[f"{name}_mass_{k}"] = ("time", arr, "mol")
            if name == self.oxygen:
                if "concentration_in" in vv:
                    out["po2_in"] = ("vessel", self.po2_in, "mmHg")
                if "concentration_out" in vv:
                    out["po2_out"] = ("vessel", self.po2_out, "mmHg")
                if "concentration" in sv:
                    out["segment_po2"] = ("segment", self.segment_po2, "mmHg")
        out.update(self._tissue_variables())
        if self.species:
            sv = next(iter(self.species.values())).segment_variables
            # R_i = dL_i/dt of L_i = -dx/v (s) is dimensionless (docs/physics.md §5)
            for k, unit in (("tl_resistance", "1"), ("tl_inductance", "s")):
                if k in sv:
                    out[k] = ("segment", getattr(self, k), unit)
        return out

    def _tissue_variables(self) -> dict[str, tuple[str, np.ndarray, str]]:
        """Tissue-wall outputs (docs/physics.md §3.7) of every species with a tissue wall:
        ``{name}_wall_concentration_inner|outer|min`` and ``{name}_hypoxic_fraction`` per vessel
        (``segment_`` prefixed per segment), ``{name}_wall_mass_*`` per time; oxygen adds
        ``wall_po2_inner|outer|min``, ``hypoxic_fraction`` (and the ``segment_`` ones) in mmHg."""
        out: dict[str, tuple[str, np.ndarray, str]] = {}
        for name, sp in self.species.items():
            tr = sp.tissue
            if tr is None or any(v not in tr.vessels for v in self.vessels):
                continue
            idx = [tr.vessels.index(v) for v in self.vessels]
            # (a selection without flow segment variables lists no segment counts)
            seg_ok = (tr.vessels == self.vessels and tr.segment_data.shape[1] > 0
                      and list(self.segment_count) in ([], list(tr.segment_count)))
            scale = sp.po2_per_concentration if name == self.oxygen else None
            for kind, keys, data in (("vessel", TISSUE_VESSEL, tr.vessel_data[:, idx]),
                                     ("segment", TISSUE_SEGMENT, tr.segment_data)):
                if kind == "segment" and not seg_ok:
                    continue
                pre = "segment_" if kind == "segment" else ""
                for i, k in enumerate(keys):
                    base = k.removeprefix("segment_")
                    frac = base == "hypoxic_fraction"
                    out[f"{pre}{name}_{base}"] = (kind, data[:, :, i], "1" if frac else "mol/m^3")
                    if scale is not None:
                        po2 = base.replace("concentration", "po2")
                        out[f"{pre}{po2}"] = (kind, data[:, :, i] if frac else data[:, :, i]
                                              * scale, "1" if frac else "mmHg")
            for k, arr in tr.mass_balance.items():
                out[f"{name}_wall_mass_{k}"] = ("time", arr, "mol")
        return out

    def __reduce__(self) -> tuple[Any, tuple[dict[str, Any]]]:
        """Pickle the fields only: the vessel and segment blocks are views of ``data`` and are
        rebuilt on loading (pickled as they are, each view would be a second copy of it)."""
        return _unpickle_result, ({f.name: getattr(self, f.name) for f in fields(self)},)

    def __post_init__(self) -> None:
        nv = len(self.vessels)
        self._kv, self._ks = len(self.vessel_variables), max(1, len(self.segment_variables))
        self._vessel_block = self.data[:, : self._kv * nv]
        self._segment_block = self.data[:, self._kv * nv :]
        # built at the first look-up (`_index`, `_seg_start`)
        self._vessel_index: dict[str, int] | None = None
        self._segment_starts: np.ndarray | None = None

    def _vessel_var(self, name: str) -> np.ndarray:
        if name not in self.vessel_variables:
            raise _not_selected(name)
        return self._vessel_block[:, self.vessel_variables.index(name)::self._kv]

    def _segment_var(self, name: str) -> np.ndarray:
        if name not in self.segment_variables:
            raise _not_selected(name)
        return self._segment_block[:, self.segment_variables.index(name)::self._ks]

    # vessel-level arrays, shape (time, vessel); segment-level, shape (time, segment)
    pressure_in = _column("_vessel_var", "pressure_in")
    pressure_out = _column("_vessel_var", "pressure_out")
    flow_in = _column("_vessel_var", "flow_in")
    flow_out = _column("_vessel_var", "flow_out")
    segment_pressure_in = _column("_segment_var", "segment_pressure_in")
    segment_pressure_out = _column("_segment_var", "segment_pressure_out")
    segment_flow = _column("_segment_var", "segment_flow")

    @property
    def _index(self) -> dict[str, int]:
        """Vessel name -> column. Built at the first look-up: a large run's summary makes a
        result of every chunk of rows (262 k names at 1e6 segments) and looks none up."""
        if self._vessel_index is None:
            self._vessel_index = {name: i for i, name in enumerate(self.vessels)}
        return self._vessel_index

    @property
    def _seg_start(self) -> np.ndarray:
        """Each vessel's first segment column (and the end), built at the first use."""
        if self._segment_starts is None:
            self._segment_starts = np.concatenate([[0], np.cumsum(self.segment_count)]) \
                .astype(int) if self.segment_count else np.zeros(1, dtype=int)
        return self._segment_starts

    @property
    def has_segments(self) -> bool:
        return self._segment_block.shape[1] > 0

    def vessel(self, name: str) -> VesselResult:
        """All arrays of one vessel."""
        if name not in self._index:
            raise KeyError(f"vessel '{name}' has no output (vessels: {', '.join(self.vessels[:10])}"
                           f"{', ...' if len(self.vessels) > 10 else ''})")
        i = self._index[name]
        ends = {k: (self._vessel_var(k)[:, i] if k in self.vessel_variables else None)
                for k in VESSEL_VARIABLES}
        out = VesselResult(name, self.time, **ends)
        if self.has_segments:
            a, b = self._seg_start[i], self._seg_start[i + 1]
            for k in self.segment_variables:
                setattr(out, k, self._segment_var(k)[:, a:b])
            out.segment_position = self.segment_position[a:b]
        return out

    def to_xarray(self, *, coordinates: bool = True) -> Any:
        """xarray Dataset with dims ``time``, ``vessel`` (and ``segment``), SI units in attrs.
        :func:`oxyline.open_result` is its inverse (also for the files written from it).
        ``coordinates=False``: without the vessel and segment coordinates (the rows of a
        streamed chunk, whose store has them: ten million segments' names are not built
        again for every chunk)."""
        import xarray as xr

        coords: dict[str, Any] = {"time": ("time", self.time, {"units": "s"})}
        if coordinates:
            coords["vessel"] = ("vessel", np.array(self.vessels, dtype=object))
        data_vars: dict[str, Any] = {
            name: (("time", "vessel"), getattr(self, name), {"units": UNITS[name]})
            for name in self.vessel_variables
        }
        if self.segment_count:  # flow or species segment variables (their coordinates)
            if coordinates:
                coords.update(self._segment_coordinates())
            for name in self.segment_variables:
                data_vars[name] = (("time", "segment"), getattr(self, name), {"units": UNITS[name]})
        n_segments = int(sum(self.segment_count))
        seg_ok = n_segments > 0 and all(
            sp.segment_data.shape[1] == n_segments for sp in self.species.values())
        for name, (kind, arr, unit) in self.species_variables().items():
            if kind == "vessel":
                data_vars[name] = (("time", "vessel"), arr, {"units": unit})
            elif kind == "time":
                data_vars[name] = (("time",), arr, {"units": unit})
            elif seg_ok:
                data_vars[name] = (("time", "segment"), arr, {"units": unit})
        if self.oxygen is not None and self.oxygen in self.species:
            # the exact mmHg-per-concentration factor, so that oxyline.open_result rebuilds
            # po2_* bit for bit (a ratio of the stored arrays would only approximate it)
            scale = self.species[self.oxygen].po2_per_concentration
            for name in ("po2_in", "po2_out", "segment_po2"):
                if name in data_vars and scale is not None:
                    data_vars[name][2]["po2_per_concentration"] = float(scale)
        if self.chamber_volume:
            coords["chamber"] = ("chamber", np.array(list(self.chamber_volume), dtype=object))
            data_vars["chamber_volume"] = (
                ("time", "chamber"), np.column_stack(list(self.chamber_volume.values())),
                {"units": "m^3"})
        if self.valve_status:
            coords["valve"] = ("valve", np.array(list(self.valve_status), dtype=object))
            data_vars["valve_status"] = (
                ("time", "valve"), np.column_stack(list(self.valve_status.values())),
                {"units": "1", "description": "1 open, 0 closed"})
        attrs: dict[str, Any] = {"model": self.model_name, "oxyline_version": _core.__version__,
                                 "complete": int(self.complete)}
        if self.model_json is not None:
            attrs["model_json"] = self.model_json
        if (tuple(self.vessel_variables), tuple(self.segment_variables)) != (
                VESSEL_VARIABLES, SEGMENT_VARIABLES):
            # an output selection: what oxyline.open_result must find (all of them otherwise)
            attrs["output_variables"] = [*self.vessel_variables, *self.segment_variables]
        if self.species:
            # species order (a Zarr store lists its variables alphabetically) and which one is
            # oxygen: what oxyline.open_result needs to rebuild ``species`` and ``oxygen``
            attrs["species"] = list(self.species)
            if self.oxygen is not None:
                attrs["oxygen_species"] = self.oxygen
        # (a flag is stored as 0/1: NetCDF attributes have no boolean type)
        attrs.update({f"solver_{k}": (int(v) if isinstance(v, bool) else v
                                      if isinstance(v, (int, float, str)) else str(v))
                      for k, v in self.settings.items() if v is not None})
        return xr.Dataset(data_vars, coords=coords, attrs=attrs)

    def _segment_coordinates(self) -> dict[str, Any]:
        """Each segment's vessel name, index in its vessel and position (m)."""
        seg_vessel = np.repeat(np.array(self.vessels, dtype=object), self.segment_count)
        counts = np.asarray(self.segment_count, dtype=np.int64)
        # each segment's index in its vessel, without an arange per vessel (2 M at 1e7)
        seg_index = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
        return {"segment_vessel": ("segment", seg_vessel),
                "segment_index": ("segment", seg_index),
                "segment_position": ("segment", self.segment_position, {"units": "m"})}

    # files and summaries (implemented in oxyline.io.results)
    def to_netcdf(self, path: str | os.PathLike[str]) -> Path:
        """Write NetCDF-4 (h5netcdf): dims time, vessel, segment; units, model name, solver
        settings and oxyline version in attrs. See :func:`oxyline.io.results.to_netcdf`."""
        return results.to_netcdf(self, path)

    def to_zarr(self, path: str | os.PathLike[str], time_chunk: int = 1024,
                overwrite: bool = False) -> Path:
        """Write a Zarr store chunked along time (written after the run; needs ``zarr``); an
        existing store is replaced only with ``overwrite=True``.
        See :func:`oxyline.io.results.to_zarr`."""
        return results.to_zarr(self, path, time_chunk=time_chunk, overwrite=overwrite)

    def summary(self) -> Any:
        """pandas DataFrame per vessel: mean/min/max of every per-vessel variable (SI)."""
        return results.summary(self)

    def to_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`summary` as CSV (TSV for .tsv)."""
        return results.to_csv(self, path)

    def to_parquet(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`summary` as Parquet (needs pyarrow)."""
        return results.to_parquet(self, path)

    def to_pandas(self, units: bool = False) -> Any:
        """Long table with svZeroDSolver's columns: name, time, flow_in, flow_out, pressure_in,
        pressure_out, in SI units, which ``df.attrs["units"]`` names per column. With
        ``units=True`` the column names carry them too (``"pressure_in [Pa]"``), so the units
        survive a CSV file. Needs all four vessel variables in the output selection.

        >>> import oxyline
        >>> df = oxyline.simulate("bifurcation", cycles=1).to_pandas(units=True)
        >>> list(df.columns[:3])
        ['name', 'time [s]', 'flow_in [m^3/s]']
        """
        if tuple(self.vessel_variables) != VESSEL_VARIABLES:
            missing = [v for v in VESSEL_VARIABLES if v not in self.vessel_variables]
            raise _not_selected(", ".join(missing))
        df = long_table(self.vessels, self.time, self._vessel_block)
        unit_of = {c: UNITS[c] for c in LONG_COLUMNS if c in UNITS}
        if units:
            df.columns = [f"{c} [{unit_of[c]}]" if c in unit_of else c for c in df.columns]
            unit_of = {f"{c} [{u}]": u for c, u in unit_of.items()}
        df.attrs["units"] = unit_of
        return df

    def heart_table(self) -> Any:
        """pandas DataFrame indexed by time with one column per chamber volume
        (``Vc:<chamber>``, m^3) and per valve status (``valve_status:<valve>``, 1 open, 0
        closed), svZeroDSolver's variable names; empty without chambers and valves."""
        import pandas as pd

        cols = {f"Vc:{k}": v for k, v in self.chamber_volume.items()}
        cols.update({f"valve_status:{k}": v for k, v in self.valve_status.items()})
        return pd.DataFrame(cols, index=pd.Index(self.time, name="time"))


def _unpickle_result(state: dict[str, Any]) -> Result:
    return Result(**state)


LONG_COLUMNS = ("name", "time", "flow_in", "flow_out", "pressure_in", "pressure_out")


def long_table(vessels: list[str], time: np.ndarray, block: np.ndarray) -> Any:
    """svZeroDSolver's long table (rows grouped by vessel, in ``vessels`` order) from a
    (time, 4 x vessel) block laid out as the core writes it: pressure_in, pressure_out, flow_in,
    flow_out per vessel.

    The block is transposed once, vessel by vessel as 32-byte records, into one (row, 4) array
    that becomes the DataFrame's float block without further copies, and the name column is a
    ``take`` of the vessel names (no per-row string validation). At 10^4 vessels x 1000 times
    this is about 3x faster, and needs half the transient memory, of building the columns
    separately and letting pandas consolidate them.
    """
    nt, nv = len(time), len(vessels)
    if block.shape != (nt, 4 * nv):
        raise ValueError(f"block has shape {block.shape}, expected {(nt, 4 * nv)}")
    rec = np.dtype((np.void, 32))
    if block.dtype != np.float64 or block.strides[1] != 8 or block.strides[0] % 8:
        block = np.ascontiguousarray(block, dtype=np.float64)
    values = np.ascontiguousarray(block.view(rec).T).view(np.float64).reshape(nv * nt, 4)
    return long_table_vessel_major(vessels, time, values)


def long_table_vessel_major(vessels: list[str], time: np.ndarray, values: np.ndarray) -> Any:
    """svZeroDSolver's long table from a C-contiguous (vessel × time, 4) array of pressure_in,
    pressure_out, flow_in, flow_out; the array becomes the DataFrame's float block (no copy
    with pandas >= 3)."""
    import pandas as pd

    nt, nv = len(time), len(vessels)
    if values.shape != (nv * nt, 4) or not values.flags.c_contiguous:
        raise ValueError(f"values must be C-contiguous with shape {(nv * nt, 4)}")
    # pandas' default dtype for strings, as svZeroDSolver's own frame: str under pandas >= 3
    # (a StringArray, or an ArrowStringArray with pyarrow), object under pandas 2
    names = pd.Series(np.array(vessels, dtype=object)).array
    name_col = names.take(np.repeat(np.arange(nv), nt))
    if not isinstance(name_col.dtype, pd.StringDtype):  # object: a plain numpy block
        name_col = name_col.to_numpy()
    time_col = np.tile(np.asarray(time, dtype=np.float64), nv)
    columns = pd.Index(LONG_COLUMNS)
    try:
        from pandas.api.internals import create_dataframe_from_blocks
    except ImportError:  # pandas < 3: build from the columns (one more copy)
        create_dataframe_from_blocks = None
    if create_dataframe_from_blocks is not None:
        name_block = name_col if not isinstance(name_col, np.ndarray) else name_col[None, :]
        return create_dataframe_from_blocks(
            [(name_block, np.array([0])), (time_col[None, :], np.array([1])),
             # values columns are pressure_in, pressure_out, flow_in, flow_out
             (values.T, np.array([4, 5, 2, 3]))],
            index=pd.RangeIndex(nv * nt), columns=columns)
    return pd.DataFrame({"name": name_col, "time": time_col, "flow_in": values[:, 2],
                         "flow_out": values[:, 3], "pressure_in": values[:, 0],
                         "pressure_out": values[:, 1]}, columns=columns)
