"""Physical-bounds monitor of species transport (docs/physics.md §2.8).

Checked on the recorded output (never per step or per cell of the integration): once per
``simulate`` run, on every chunk that ``simulate_to_zarr`` streams (:class:`Monitor` keeps a
few numbers between chunks, not the output), and on every finished variant of
``simulate_ensemble`` (recorded in its ``warning`` variable). The checks:

* **Maximum principle.** For a species without sources (no prescribed ``flux`` wall; decay only
  lowers concentrations), every free concentration lies in [min, max] of its inlet, backflow,
  initial and wall values. A recorded value outside, beyond :data:`BOUNDS_RTOL` of that range,
  raises a :class:`PhysicalBoundsWarning` naming the vessel, the time and the value.
* **Mass balance.** The residual stored − (inflow − outflow − wall uptake − decay) accumulated
  over the recorded window beyond :data:`BALANCE_RTOL` of the window's throughput (network-wide)
  warns likewise.
* **``formulation: tl-quasisteady``** (the paper read literally, docs/physics.md §2.7) also
  reports when the run leaves the range where a quasi-steady line holds (its criteria in
  docs/physics.md §2.7; :meth:`Monitor.validity_message`).
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from oxyline import _core

#: Tolerance of the maximum-principle check, relative to the largest bound magnitude: the
#: conservative scheme is monotone (upwind fluxes; backward Euler is an M-matrix; RK4 runs far
#: below its positivity limit), so only round-off (~1e-15) and the Hill inversion (1e-12 mmHg)
#: move values past a bound.
BOUNDS_RTOL = 1e-6
#: Tolerance of the mass balance, relative to the throughput of the recorded window (the
#: larger of its in- and outflow): the conservative formulation keeps it to ~1e-14
#: (docs/physics.md §2.5).
BALANCE_RTOL = 1e-6
#: tl-quasisteady validity (docs/physics.md §2.7): the segment transit time L_i = −dx/v must
#: change slowly, |R_i| = |dL_i/dt| below this ...
QS_TRANSIT_RATE = 0.1
#: ... and a vessel's compliant storage flow |Q_in − Q_out| must be below this fraction of its
#: flow (the literal form has no storage term: c_i = J_i/Q_i is off by about that fraction).
QS_STORAGE = 1e-3


class PhysicalBoundsWarning(UserWarning):
    """A transport result left its physical bounds (maximum principle, mass balance) or the
    validity range of its formulation. The message names the species, the vessel, the time and
    the value."""


def _wave_range(w: Mapping[str, Any]) -> tuple[float, float]:
    kind = w.get("kind")
    if kind == "constant":
        v = float(w["value"])
        return v, v
    if kind == "table":
        v = np.asarray(w["value"], dtype=float)
        return float(v.min()), float(v.max())
    if kind == "fourier":  # sampled by the core's evaluator
        t = np.linspace(0.0, float(w["period"]), 4097)
        v = _core.waveform_values("transport inlet", json.dumps(dict(w)), t.tolist())
        # the sampled extremes are within ~1e-7 of the true ones: far inside the tolerance
        return float(v.min()), float(v.max())
    return math.nan, math.nan


def _wall_values(walls: Iterable[Mapping[str, Any]]) -> tuple[list[float], bool]:
    """Wall concentrations of the closures, and whether any wall is a prescribed source."""
    vals, source = [], False
    for w in walls:
        if w.get("model") == "flux":
            source = True
        for key in ("wall_concentration", "tissue_concentration"):
            if key in w:
                vals.append(float(w[key]))
    return vals, source


def species_bounds(sp: Mapping[str, Any]) -> tuple[float, float] | None:
    """[min, max] of a species' boundary, initial and wall values (the maximum-principle range),
    or None for a species with a prescribed source (a ``flux`` wall)."""
    walls = [sp.get("wall", {"model": "none"}), *sp.get("per_vessel", {}).values()]
    vals, source = _wall_values(walls)
    if source:
        return None
    for w in [sp["inlet"], *sp.get("inlets", {}).values(), *sp.get("backflow", {}).values()]:
        vals.extend(_wave_range(w))
    if "initial" in sp:
        vals.append(float(sp["initial"]))
    if sp.get("decay", 0.0) > 0.0:
        vals.append(0.0)  # decay pulls towards zero
    vals = [v for v in vals if math.isfinite(v)]
    return (min(vals), max(vals)) if vals else None


def _first_outside(values: np.ndarray, lo: float, hi: float, tol: float
                   ) -> tuple[int, int, float] | None:
    """(time index, column, value) of the worst value outside [lo − tol, hi + tol]."""
    # the extremes first (NaN ignored, no temporary): a 1e6-segment tree's column is ~0.2 GB,
    # and the excess below makes three temporaries of its size
    if values.size == 0 or (np.fmax.reduce(values, axis=None, initial=-np.inf) <= hi + tol
                            and np.fmin.reduce(values, axis=None, initial=np.inf) >= lo - tol):
        return None
    excess = np.maximum(values - (hi + tol), (lo - tol) - values)
    excess = np.where(np.isnan(excess), -np.inf, excess)
    if excess.size == 0 or not (excess > 0).any():
        return None
    t, k = np.unravel_index(int(np.argmax(excess)), excess.shape)
    return int(t), int(k), float(values[t, k])


def _segment_vessel(result: Any, k: int) -> str:
    """Name of the vessel of recorded segment column k."""
    edges = np.cumsum(result.segment_count)
    return result.vessels[int(np.searchsorted(edges, k, side="right"))]


def _worst_outside(result: Any, name: str, lo: float, hi: float, tol: float
                   ) -> tuple[float, str, float, float] | None:
    """(excess, vessel, time, value) of the recorded value of species ``name`` farthest
    outside [lo, hi] (beyond ``tol``), or None."""
    sp = result.species[name]
    worst: tuple[float, str, float, float] | None = None
    hits = [(getattr(sp, key), lambda k: result.vessels[k])
            for key in ("concentration_in", "concentration_out") if key in sp.vessel_variables]
    if "concentration" in sp.segment_variables and sp.segment_data.shape[1] > 0:
        hits.append((sp.segment("concentration"), lambda k: _segment_vessel(result, k)))
    for values, vessel in hits:
        hit = _first_outside(values, lo, hi, tol)
        if hit:
            ex = max(hit[2] - hi, lo - hit[2])
            if worst is None or ex > worst[0]:
                worst = (ex, vessel(hit[1]), float(result.time[hit[0]]), hit[2])
    return worst


def _bounds_message(name: str, sp: Any, lo: float, hi: float,
                    worst: tuple[float, str, float, float]) -> str:
    scale, unit = (sp.po2_per_concentration, "mmHg") if sp.po2_per_concentration else (1.0,
                                                                                       "mol/m^3")
    _, vessel, t, v = worst
    return (f"species '{name}': vessel '{vessel}' at t = {t:.6g} s has "
            f"{v * scale:.6g} {unit}, outside the physical range [{lo * scale:.6g}, "
            f"{hi * scale:.6g}] {unit} of its inlet, initial and wall values (maximum "
            f"principle, tolerance {BOUNDS_RTOL:g} of the range)")


class Monitor:
    """The checks of this module over a run's output given in consecutive pieces (a whole
    ``Result``, or the chunks that :func:`oxyline.simulate_to_zarr` streams), keeping only a
    few numbers per species and vessel between pieces, so that a streamed run is checked
    without holding its output. Fed the whole output at once it finds exactly what it finds
    fed the same rows in chunks. ``transport``: the model's canonical transport section."""

    def __init__(self, transport: Mapping[str, Any] | None) -> None:
        transport = transport or {}
        self.specs = {sp["name"]: sp for sp in transport.get("species", [])}
        self.bounds = {n: species_bounds(sp) for n, sp in self.specs.items()}
        self.quasisteady = transport.get("formulation") == "tl-quasisteady"
        self.worst: dict[str, tuple[float, str, float, float]] = {}
        self.units: dict[str, Any] = {}
        # mass balance: the first recorded row, the largest |Δresidual| (value, time), last row
        self.first: dict[str, dict[str, float]] = {}
        self.imbalance: dict[str, tuple[float, float, float]] = {}
        self.last: dict[str, dict[str, float]] = {}
        self.t0: float | None = None
        # tl-quasisteady: Σ Q_in per vessel, the first low-flow row per sign of the mean flow,
        # the largest storage ratio and |R_i|
        self.q_sum: np.ndarray | None = None
        self.low: dict[int, dict[int, tuple[float, float, float]]] = {}
        self.storage: tuple[float, str, float] | None = None
        self.transit: tuple[float, str, float] | None = None
        self.vessels: list[str] = []

    # -- feeding -----------------------------------------------------------------------------
    def update(self, result: Any) -> None:
        """Take the next rows of the run's output (a ``Result`` holding them)."""
        if len(result.time) == 0:
            return
        if self.t0 is None:
            self.t0 = float(result.time[0])
        self.vessels = list(result.vessels)
        for name in self.specs:
            if name in result.species:
                self._update_species(result, name)
        if self.quasisteady:
            self._update_validity(result)

    def _update_species(self, result: Any, name: str) -> None:
        sp = result.species[name]
        self.units[name] = sp
        b = self.bounds.get(name)
        if b is not None:
            lo, hi = b
            tol = BOUNDS_RTOL * max(abs(lo), abs(hi), hi - lo)
            w = _worst_outside(result, name, lo, hi, tol)
            if w is not None and (name not in self.worst or w[0] > self.worst[name][0]):
                self.worst[name] = w
        mb = sp.mass_balance
        if name not in self.first:
            self.first[name] = {k: float(v[0]) for k, v in mb.items()}
        dres = np.abs(np.asarray(mb["residual"]) - self.first[name]["residual"])
        if np.isfinite(dres).any():
            it = int(np.nanargmax(dres))
            if name not in self.imbalance or dres[it] > self.imbalance[name][0]:
                self.imbalance[name] = (float(dres[it]), float(result.time[it]),
                                        float(mb["residual"][it] - self.first[name]["residual"]))
        self.last[name] = {k: float(v[-1]) for k, v in mb.items()}

    def _update_validity(self, result: Any) -> None:
        t = result.time
        if "flow_in" in result.vessel_variables and "flow_out" in result.vessel_variables:
            qi, qo = np.asarray(result.flow_in), np.asarray(result.flow_out)
            s = qi.sum(axis=0)
            self.q_sum = s if self.q_sum is None else self.q_sum + s
            for sign in (1, -1, 0):  # the first low-flow row for each sign of the mean flow
                low = (qi * sign <= 0) | (qo * sign <= 0)
                for k in np.flatnonzero(low.any(axis=0)):
                    entry = self.low.setdefault(int(k), {})
                    if sign not in entry:
                        it = int(np.argmax(low[:, k]))
                        entry[sign] = (float(t[it]), float(qi[it, k]), float(qo[it, k]))
            rel = np.abs(qi - qo) / np.maximum(np.abs(qi), np.abs(qo))
            if np.isfinite(rel).any():
                it, k = np.unravel_index(int(np.nanargmax(rel)), rel.shape)
                if self.storage is None or rel[it, k] > self.storage[0]:
                    self.storage = (float(rel[it, k]), result.vessels[k], float(t[it]))
        ox = result.oxygen or next(iter(result.species), None)
        sp = result.species.get(ox) if ox else None
        if sp is not None and "tl_resistance" in sp.segment_variables \
                and sp.segment_data.shape[1]:
            r = np.abs(sp.segment("tl_resistance"))
            if np.isfinite(r).any():
                it, k = np.unravel_index(int(np.nanargmax(r)), r.shape)
                if self.transit is None or r[it, k] > self.transit[0]:
                    self.transit = (float(r[it, k]), _segment_vessel(result, k), float(t[it]))

    # -- findings ----------------------------------------------------------------------------
    def bounds_messages(self) -> dict[str, str]:
        out = {}
        for name, worst in self.worst.items():
            lo, hi = self.bounds[name]  # type: ignore[misc]
            out[name] = _bounds_message(name, self.units[name], lo, hi, worst)
        return out

    def balance_messages(self) -> dict[str, str]:
        """Over the recorded window: the cumulative amounts count from the run's start, which
        the output may not include."""
        out = {}
        for name, (dres, t, signed) in self.imbalance.items():
            first, last = self.first[name], self.last[name]
            throughput = max(abs(last["inflow"] - first["inflow"]),
                             abs(last["outflow"] - first["outflow"]))
            rel = dres / throughput if throughput > 0.0 else 0.0
            if rel > BALANCE_RTOL:
                out[name] = (f"species '{name}': the mass balance is off by {rel:.3g} of the "
                             f"throughput ({signed:.6g} mol since t = {self.t0:.6g} s) at "
                             f"t = {t:.6g} s (network-wide; tolerance {BALANCE_RTOL:g})")
        return out

    def validity_message(self) -> str | None:
        if self.q_sum is not None:
            hits = []
            for k, entry in self.low.items():
                if not np.isfinite(self.q_sum[k]):
                    continue
                hit = entry.get(int(np.sign(self.q_sum[k])))
                if hit is not None:
                    hits.append((hit[0], k, hit))
            if hits:
                _, k, (t, qi, qo) = min(hits)
                return (f"criterion 1 (forward flow): vessel '{self.vessels[k]}' has flow "
                        f"{qi:.4g} → {qo:.4g} m^3/s at t = {t:.6g} s (reversal or zero flow, "
                        "where the literal transmission line is singular)")
        if self.storage is not None and self.storage[0] > QS_STORAGE:
            rel, vessel, t = self.storage
            return (f"criterion 2 (no storage): vessel '{vessel}' stores |Q_in − Q_out|/|Q| = "
                    f"{rel:.3g} of its flow at t = {t:.6g} s (> {QS_STORAGE:g}; the literal "
                    "form neglects the compliant volume change)")
        if self.transit is not None and self.transit[0] > QS_TRANSIT_RATE:
            r, vessel, t = self.transit
            return (f"criterion 3 (slow transit time): vessel '{vessel}' has |R_i| = "
                    f"|dL_i/dt| = {r:.3g} at t = {t:.6g} s (> {QS_TRANSIT_RATE:g})")
        return None

    def messages(self) -> list[str]:
        """Every finding so far, in the order species by species (bounds, then balance),
        then the tl-quasisteady validity."""
        bounds, balance = self.bounds_messages(), self.balance_messages()
        found = [m for name in self.specs for m in (bounds.get(name), balance.get(name)) if m]
        if self.quasisteady:
            why = self.validity_message()
            if why:
                found.append(f"formulation tl-quasisteady (the paper read literally) is outside "
                             f"its validity range: {why}. Use the default conservative "
                             "formulation for predictions (docs/physics.md §2.7).")
        return found


def warn(messages: Iterable[str], stacklevel: int = 2) -> None:
    """Each message as a :class:`PhysicalBoundsWarning`."""
    for msg in messages:
        warnings.warn(msg, PhysicalBoundsWarning, stacklevel=stacklevel + 1)
