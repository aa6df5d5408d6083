"""Physical-bounds monitor of species transport (docs/physics.md §2.8).

Checked once per run on the recorded output (never per step or per cell of the integration):

* **Maximum principle.** For a species without sources (no prescribed ``flux`` wall; decay only
  lowers concentrations), every free concentration lies in [min, max] of its inlet, backflow,
  initial and wall values. A recorded value outside, beyond :data:`BOUNDS_RTOL` of that range,
  raises a :class:`PhysicalBoundsWarning` naming the vessel, the time and the value.
* **Mass balance.** The residual stored − (inflow − outflow − wall uptake − decay) accumulated
  over the recorded window beyond :data:`BALANCE_RTOL` of the window's throughput (network-wide)
  warns likewise.
* **``formulation: tl-quasisteady``** (the paper read literally, docs/physics.md §2.7) also
  reports when the run leaves the range where a quasi-steady line holds (see
  :func:`quasisteady_validity`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

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
    if kind == "fourier":
        t = np.linspace(0.0, float(w["period"]), 4097)
        om = 2.0 * math.pi / float(w["period"])
        v = np.full_like(t, float(w["mean"]))
        for k, a in enumerate(w.get("cos", []), start=1):
            v += a * np.cos(k * om * t)
        for k, b in enumerate(w.get("sin", []), start=1):
            v += b * np.sin(k * om * t)
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


def check_bounds(result: Any, name: str, spec: Mapping[str, Any]) -> str | None:
    """Why species ``name`` of ``result`` leaves its maximum-principle range (the worst
    recorded value), or None."""
    bounds = species_bounds(spec)
    sp = result.species[name]
    if bounds is None or len(result.time) == 0:
        return None
    lo, hi = bounds
    tol = BOUNDS_RTOL * max(abs(lo), abs(hi), hi - lo)
    scale, unit = (sp.po2_per_concentration, "mmHg") if sp.po2_per_concentration else (1.0,
                                                                                       "mol/m^3")
    worst: tuple[float, str, int, float] | None = None
    for key in ("concentration_in", "concentration_out"):
        if key in sp.vessel_variables:
            hit = _first_outside(getattr(sp, key), lo, hi, tol)
            if hit:
                ex = max(hit[2] - hi, lo - hit[2])
                if worst is None or ex > worst[0]:
                    worst = (ex, result.vessels[hit[1]], hit[0], hit[2])
    if "concentration" in sp.segment_variables and sp.segment_data.shape[1] > 0:
        hit = _first_outside(sp.segment("concentration"), lo, hi, tol)
        if hit:
            ex = max(hit[2] - hi, lo - hit[2])
            if worst is None or ex > worst[0]:
                worst = (ex, _segment_vessel(result, hit[1]), hit[0], hit[2])
    if worst is None:
        return None
    _, vessel, it, v = worst
    return (f"species '{name}': vessel '{vessel}' at t = {result.time[it]:.6g} s has "
            f"{v * scale:.6g} {unit}, outside the physical range [{lo * scale:.6g}, "
            f"{hi * scale:.6g}] {unit} of its inlet, initial and wall values (maximum "
            f"principle, tolerance {BOUNDS_RTOL:g} of the range)")


def check_balance(result: Any, name: str) -> str | None:
    """Why species ``name`` breaks its mass balance by more than BALANCE_RTOL, or None."""
    sp = result.species[name]
    if len(result.time) < 2:
        return None
    # over the recorded window: the cumulative amounts count from the run's start, which the
    # output may not include
    mb = {k: v - v[0] for k, v in sp.mass_balance.items()}
    throughput = max(abs(float(mb["inflow"][-1])), abs(float(mb["outflow"][-1])))
    rel = np.abs(mb["residual"]) / throughput if throughput > 0.0 else np.zeros(1)
    if not np.nanmax(rel) > BALANCE_RTOL:
        return None
    it = int(np.nanargmax(rel))
    return (f"species '{name}': the mass balance is off by {rel[it]:.3g} of the throughput "
            f"({mb['residual'][it]:.6g} mol since t = {result.time[0]:.6g} s) at "
            f"t = {result.time[it]:.6g} s (network-wide; tolerance {BALANCE_RTOL:g})")


def quasisteady_validity(result: Any) -> str | None:
    """Why a ``tl-quasisteady`` run is outside the range where the quasi-steady line holds, or
    None. Criteria, in order (docs/physics.md §2.7): (1) no flow reversal or near-zero flow
    (the literal form is singular at v = 0); (2) compliant storage: |Q_in − Q_out| of a vessel
    ≤ QS_STORAGE |Q| (the literal form has no storage term); (3) |R_i| = |dL_i/dt| ≤
    QS_TRANSIT_RATE (the segment transit time changes slowly)."""
    t = result.time
    if "flow_in" in result.vessel_variables and "flow_out" in result.vessel_variables:
        qi, qo = result.flow_in, result.flow_out
        sign = np.sign(np.mean(qi, axis=0))
        low = (qi * sign <= 0) | (qo * sign <= 0)
        if low.any():
            it, k = np.argwhere(low)[0]
            return (f"criterion 1 (forward flow): vessel '{result.vessels[k]}' has flow "
                    f"{qi[it, k]:.4g} → {qo[it, k]:.4g} m^3/s at t = {t[it]:.6g} s (reversal "
                    "or zero flow, where the literal transmission line is singular)")
        rel = np.abs(qi - qo) / np.maximum(np.abs(qi), np.abs(qo))
        if np.nanmax(rel) > QS_STORAGE:
            it, k = np.unravel_index(int(np.nanargmax(rel)), rel.shape)
            return (f"criterion 2 (no storage): vessel '{result.vessels[k]}' stores "
                    f"|Q_in − Q_out|/|Q| = {rel[it, k]:.3g} of its flow at t = {t[it]:.6g} s "
                    f"(> {QS_STORAGE:g}; the literal form neglects the compliant volume change)")
    ox = result.oxygen or next(iter(result.species), None)
    sp = result.species.get(ox) if ox else None
    if sp is not None and "tl_resistance" in sp.segment_variables and sp.segment_data.shape[1]:
        r = np.abs(sp.segment("tl_resistance"))
        if np.nanmax(r, initial=0.0) > QS_TRANSIT_RATE:
            it, k = np.unravel_index(int(np.nanargmax(r)), r.shape)
            return (f"criterion 3 (slow transit time): vessel '{_segment_vessel(result, k)}' "
                    f"has |R_i| = |dL_i/dt| = {r[it, k]:.3g} at t = {t[it]:.6g} s "
                    f"(> {QS_TRANSIT_RATE:g})")
    return None


def check_result(result: Any, transport: Mapping[str, Any] | None) -> None:
    """All checks of a run's recorded output against its canonical transport section; each
    finding is a :class:`PhysicalBoundsWarning` pointing at the caller of the caller (the
    user's ``simulate``)."""
    if not transport or not result.species:
        return
    found: list[str | None] = []
    for spec in transport.get("species", []):
        name = spec["name"]
        if name in result.species:
            found += [check_bounds(result, name, spec), check_balance(result, name)]
    if transport.get("formulation") == "tl-quasisteady":
        why = quasisteady_validity(result)
        if why:
            found.append(f"formulation tl-quasisteady (the paper read literally) is outside its "
                         f"validity range: {why}. Use the default conservative formulation "
                         "for predictions (docs/physics.md §2.7).")
    for msg in found:
        if msg:
            warnings.warn(msg, PhysicalBoundsWarning, stacklevel=3)
