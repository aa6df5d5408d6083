"""The value route of an ensemble: patches of plain numbers (and inflow tables) as one row of
numbers per variant, which the core writes into its parsed base model on the worker thread
(``oxyline_core::ensemble::Targets``), instead of merged, converted and revalidated vessel and
condition dicts on the thread that feeds the workers.

A patch takes this route when it changes only

* the geometry of plain geometric vessels (``length``, ``radius``, ``radius_in``,
  ``radius_out``, ``wall_thickness``, ``youngs_modulus``; finite and > 0),
* the ``lumped`` ``resistance`` / ``capacitance`` of lumped vessels (finite, >= 0),
* the numbers of resistance and RCR conditions (finite, >= 0),
* the whole table of a flow or pressure condition (``time`` and ``flow``/``pressure``: plain
  numbers, strictly increasing times, at least two rows),
* and ``scale`` on top (the resistances and compliances it multiplies).

Every number is the one the core's patch (``oxyline_core::model::patch``) and the canonical
conversion would give (``factor * value``, ``factor * (value * f)`` or ``factor * (value /
f)``, in that order), computed with numpy's elementwise IEEE arithmetic for the whole ensemble
at once: the same bits. Anything else (other properties, a new condition type, a refused or
out-of-range value, a period that disagrees) takes the full patch path, which gives the
usual result or error.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.ensemble.scale import scale_terms
from oxyline.errors import ModelError
from oxyline.model import Model
from oxyline.units import factor

#: a geometric vessel's numbers: (property, unit quantity)
GEOMETRY = (("length", "length"), ("radius_in", "length"), ("radius_out", "length"),
            ("wall_thickness", "length"), ("youngs_modulus", "modulus"))
GEOMETRY_KEYS = frozenset(p for p, _ in GEOMETRY) | {"radius"}
LUMPED = ("resistance", "capacitance")
#: the numbers of a resistance or RCR condition
CONDITIONS = {"resistance": ("resistance",),
              "rcr": ("proximal_resistance", "capacitance", "distal_resistance")}
_REAL = (float, int)  # exact types: bool, str and numpy scalars take the full path


def _plain(x: Any) -> float | None:
    """``float(x)`` of a base number that ``scale`` reads (YAML 1.1 reads 5.0e5 as a string),
    or None where the full patch path must give the error."""
    if isinstance(x, bool) or not isinstance(x, (int, float, str)):
        return None
    try:
        v = float(x)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _factors_plain(scale: Any) -> bool:
    """Whether the factors of a ``scale`` section are finite numbers (a mapping of anything
    else takes the full path, which fails the variant naming the factor)."""
    if not isinstance(scale, Mapping):
        return True  # scale_terms names the mistake
    for key in ("resistance", "compliance"):
        f = scale.get(key, 1.0)
        if isinstance(f, bool) or not isinstance(f, (int, float)):
            return False
        if isinstance(f, float) and not math.isfinite(f):  # an int beyond any float: full path
            return False
        if isinstance(f, int) and not -2**1023 < f < 2**1023:
            return False
    return True


def _table(value: Any) -> np.ndarray | None:
    """A list/tuple/array of plain numbers as float64, or None."""
    if isinstance(value, np.ndarray):
        return value.astype(float) if value.ndim == 1 and value.dtype.kind in "fi" else None
    plain = isinstance(value, (list, tuple)) and all(type(x) in _REAL for x in value)
    return np.array(value, dtype=float) if plain else None


@dataclass
class Parsed:
    """What the value route reads of one patch: ``(target, value in the model's units)``
    pairs, tables ``(target, time, value in the model's units)`` and the checked scale terms
    (see :func:`~oxyline.ensemble.scale.scale_terms`) or None."""

    entries: list[tuple[int, float]]
    tables: list[tuple[int, np.ndarray, np.ndarray]]
    scale: tuple[set[int] | None, dict[str, float]] | None


@dataclass
class Row:
    """A variant on the value route: one SI value per target (NaN: the base value), its new
    tables in SI, and its period (that of the base model unless a table changes it)."""

    values: np.ndarray
    tables: list[tuple[int, np.ndarray, np.ndarray]] | None
    period: float | None


class ValueTable:
    """The targets of a base model (every number the value route may write; see
    ``oxyline_core::ensemble::Target``) and the numpy pass that turns the parsed patches of a
    whole ensemble into their rows."""

    def __init__(self, base: Model) -> None:
        src, canon = base.source, base.canonical
        units = str(src.get("units", "SI"))
        self.base = base
        self.targets: list[tuple[str, Any]] = []
        self.index: dict[tuple[str, Any], int] = {}
        self.vessel_index = {v["name"]: i for i, v in enumerate(src["vessels"])}
        self.n_vessels = len(src["vessels"])
        self.vessel_kind: list[str | None] = []
        rows: list[tuple[Any, float, str | None, bool, str | None, list[int]]] = []
        absent = object()

        def add(key: tuple[str, Any], base_value: Any, unit: float, scale: str | None,
                divide: bool, low: str | None, owners: list[int]) -> None:
            self.index[key] = len(self.targets)
            self.targets.append(key)
            rows.append((base_value, unit, scale, divide, low, owners))

        touching: dict[str, list[int]] = {}
        for i, (v, cv) in enumerate(zip(src["vessels"], canon["vessels"], strict=True)):
            for node in (str(v.get("from")), str(v.get("to"))):
                touching.setdefault(node, []).append(i)
            if "lumped" in cv and isinstance(v.get("lumped"), Mapping):
                self.vessel_kind.append("lumped")
                for prop, key in zip(LUMPED, ("resistance", "compliance"), strict=True):
                    add((f"lumped.{prop}", i), v["lumped"].get(prop, absent),
                        factor(units, prop), key, False, "nonneg", [i])
            elif "geometry" in cv and isinstance(v, Mapping):
                self.vessel_kind.append("geometry")
                for prop, q in GEOMETRY:
                    e = prop == "youngs_modulus"  # compliance ∝ 1/E: scale divides it
                    add((prop, i), v.get(prop, absent) if e else absent, factor(units, q),
                        "compliance" if e else None, e, "pos", [i])
            else:
                self.vessel_kind.append(None)
        self.condition_kind: dict[str, str] = {}
        for node, bc in src.get("boundary_conditions", {}).items():
            kind = str(bc.get("type", "")).lower() if isinstance(bc, Mapping) else ""
            cb = canon["boundary_conditions"].get(str(node))
            if kind in CONDITIONS and isinstance(cb, dict) and cb.get("type") == kind:
                self.condition_kind[node] = kind
                for prop in CONDITIONS[kind]:
                    key = "compliance" if prop == "capacitance" else "resistance"
                    q = "capacitance" if prop == "capacitance" else "resistance"
                    add((prop, node), bc.get(prop, absent), factor(units, q), key, False,
                        None, touching.get(node, []))
            elif kind in ("flow", "pressure") and isinstance(cb, dict) \
                    and isinstance(cb.get(kind), dict):
                self.condition_kind[node] = kind
                add(("table", node), absent, factor(units, kind), None, False, None, [])
        present = [r[0] is not absent for r in rows]
        numbers = [_plain(r[0]) if p else None for r, p in zip(rows, present, strict=True)]
        #: ``scale`` takes the value route only if every number it may read is plain
        self.usable = all(n is not None for n, p, r in zip(numbers, present, rows, strict=True)
                          if p and r[2] is not None)
        self.src = np.array([math.nan if n is None else n for n in numbers])
        self.present = np.array(present, dtype=bool)
        self.unit = np.array([r[1] for r in rows])
        self.scalable = np.array([r[2] is not None for r in rows], dtype=bool)
        self.compliance = np.array([r[2] == "compliance" for r in rows], dtype=bool)
        self.divide = np.array([r[3] for r in rows], dtype=bool)
        self.nonneg = np.array([r[4] == "nonneg" for r in rows], dtype=bool)
        pairs = [(t, i) for t, r in enumerate(rows) if r[2] is not None for i in r[5]]
        self._owner_target = np.array([t for t, _ in pairs], dtype=np.intp)
        self._owner_vessel = np.array([i for _, i in pairs], dtype=np.intp)
        self._periods: dict[str, list[tuple[float, str]]] | None = None
        self._settings: dict[float, Any] = {}

    # ------------------------------------------------------------------ one patch

    def parse(self, patch: Any, k: int) -> Parsed | None:
        """The value-route reading of ``patch`` (variant ``k``), or None if it needs the full
        path. Raises :class:`~oxyline.ModelError` only for a malformed ``scale``."""
        if not isinstance(patch, Mapping) \
                or not patch.keys() <= {"vessels", "boundary_conditions", "scale"}:
            return None
        entries: list[tuple[int, float]] = []
        tables: list[tuple[int, np.ndarray, np.ndarray]] = []
        vessels = patch.get("vessels", {})
        bcs = patch.get("boundary_conditions", {})
        if not isinstance(vessels, Mapping) or not isinstance(bcs, Mapping) \
                or not all(self._vessel(n, p, entries) for n, p in vessels.items()) \
                or not all(self._condition(n, p, entries, tables) for n, p in bcs.items()):
            return None
        scale = None
        if "scale" in patch:
            if not self.usable or not _factors_plain(patch["scale"]):
                return None  # the full path names a factor that is not a number
            scale = scale_terms(patch["scale"], self.vessel_index, k)
        return Parsed(entries, tables, scale)

    def _vessel(self, name: Any, props: Any, entries: list[tuple[int, float]]) -> bool:
        i = self.vessel_index.get(name)
        if i is None or not isinstance(props, Mapping):
            return False
        kind = self.vessel_kind[i]
        if kind == "geometry":
            if not props.keys() <= GEOMETRY_KEYS:
                return False
            if "radius" in props:
                if "radius_in" in props or "radius_out" in props:
                    return False
                props = {**props, "radius_in": props["radius"], "radius_out": props["radius"]}
            for key, x in props.items():
                if key != "radius":
                    # 0 < x < inf is False for NaN: sign and finiteness in one comparison
                    if type(x) not in _REAL or not 0 < x < math.inf:
                        return False
                    entries.append((self.index[(key, i)], x))
            return True
        if kind == "lumped" and props.keys() == {"lumped"} \
                and isinstance(props["lumped"], Mapping) \
                and props["lumped"].keys() <= set(LUMPED):
            for key, x in props["lumped"].items():
                if type(x) not in _REAL or not 0 <= x < math.inf:
                    return False
                entries.append((self.index[(f"lumped.{key}", i)], x))
            return True
        return False

    def _condition(self, node: Any, props: Any, entries: list[tuple[int, float]],
                   tables: list[tuple[int, np.ndarray, np.ndarray]]) -> bool:
        kind = self.condition_kind.get(node)
        if kind is None or not isinstance(props, Mapping):
            return False
        if kind in CONDITIONS:
            if not props.keys() <= set(CONDITIONS[kind]):
                return False
            for key, x in props.items():
                # a negative value takes the full path, whose error names the patch path
                if type(x) not in _REAL or not 0 <= x < math.inf:
                    return False
                entries.append((self.index[(key, node)], x))
            return True
        if props.keys() != {"time", kind}:
            return False
        t, v = _table(props["time"]), _table(props[kind])
        if t is None or v is None or len(t) != len(v) or len(t) < 2 \
                or not (np.isfinite(t).all() and np.isfinite(v).all()
                        and (np.diff(t) > 0).all()):
            return False
        tables.append((self.index[("table", node)], t, v))
        return True

    # ------------------------------------------------------------------ the ensemble

    def rows(self, parsed: Sequence[Parsed]) -> list[Row | None]:
        """The rows of many parsed patches in one numpy pass (None: the full path)."""
        n, nt = len(parsed), len(self.targets)
        x = np.full((n, nt), math.nan)  # explicit values, in the model's units
        r = [j for j, p in enumerate(parsed) for _ in p.entries]
        c = [t for p in parsed for t, _ in p.entries]
        x[r, c] = [v for p in parsed for _, v in p.entries]
        f = self._factors(parsed, nt)
        explicit = ~np.isnan(x)
        src = np.where(explicit, x, self.src)
        on = ~np.isnan(f) & (explicit | self.present) & self.scalable
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            scaled = np.where(on, np.where(self.divide, src / f, src * f), src)
            out = np.where(on | explicit, self.unit * scaled, math.nan)
            bad = (on & (~np.isfinite(scaled) | (self.nonneg & ~(scaled >= 0))
                         | (self.divide & ~(scaled > 0))) | ((on | explicit) & ~np.isfinite(out)))
        ok = ~bad.any(axis=1)
        result: list[Row | None] = []
        for j, p in enumerate(parsed):
            tables = [(t, time, self.unit[t] * v) for t, time, v in p.tables] or None
            period = self.period(p.tables) if tables else self.base.period
            fine = ok[j] and period is not False
            result.append(Row(out[j], tables, period) if fine else None)  # type: ignore[arg-type]
        return result

    def _factors(self, parsed: Sequence[Parsed], nt: int) -> np.ndarray:
        """The scale factor of every (variant, target), NaN where none applies."""
        f = np.full((len(parsed), nt), math.nan)
        for row, p in enumerate(parsed):
            if p.scale is None:
                continue
            selected, factors = p.scale
            res, comp = factors.get("resistance", math.nan), factors.get("compliance", math.nan)
            f[row] = np.where(self.compliance, comp, res)
            hit = np.zeros(nt, dtype=bool)
            if selected is None:
                hit[self._owner_target] = True
            else:
                chosen = np.zeros(self.n_vessels, dtype=bool)
                chosen[list(selected)] = True
                hit[self._owner_target[chosen[self._owner_vessel]]] = True
            f[row, ~hit] = math.nan
        return f

    def period(self, tables: Sequence[tuple[int, np.ndarray, np.ndarray]]) -> float | bool:
        """The period of a variant whose ``tables`` replace waveforms, as a model load finds
        it (the ``period`` key, else the first waveform's; every waveform must agree), or
        False where the full path must decide (a mismatch, which fails the variant; a model
        with species, whose transport section depends on the period)."""
        if self._periods is None:
            units = str(self.base.source.get("units", "SI"))
            self._periods = {node: _core.read_conditions({node: bc}, units)[1] for node, bc in
                             self.base.source.get("boundary_conditions", {}).items()}
        new = {self.targets[t][1]: float(time[-1] - time[0]) for t, time, _ in tables}
        periods = [pe for node, ps in self._periods.items()
                   for pe in ([(new[node], node)] if node in new else ps)]
        try:  # the core's rule: the model's period, else the first waveform's; all agree
            period = _core.check_periods(self.base.source, periods)
        except ModelError:  # a mismatch: the full path fails the variant with its message
            return False
        if period != self.base.period and self.base.transport_spec is not None:
            return False
        return period if period is not None else False

    def model_with_period(self, period: float | None) -> Model:
        """The base model with another period, for its run settings (``simulate``'s)."""
        if period == self.base.period:
            return self.base
        hit = self._settings.get(period)  # type: ignore[arg-type]
        if hit is None:
            hit = self._settings[period] = copy.copy(self.base)  # type: ignore[index]
            hit.period = period
        return hit
