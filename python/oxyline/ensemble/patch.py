"""Variant patches: what one member of an ensemble changes in the base model.

A patch is a dict in the native model format, deep-merged into the model::

    {"vessels": {"CCA": {"radius": 3.1e-3}},              # vessels by name
     "boundary_conditions": {"ica_out": {"resistance": 2e9}},   # conditions by node
     "blood": {"viscosity": 4e-3}, "oxygen": {"wall": {"k": 5e-6}},
     "period": 0.8,
     "scale": {"resistance": 1.2, "compliance": 0.8, "vessels": ["CCA", "ICA"] | "all"}}

Values are in the model's units. A waveform property (``time``, ``flow``, ``pressure``,
``value``, ``fourier``) replaces the condition's whole waveform; ``radius`` replaces
``radius_in``/``radius_out`` and the other way round; a new ``type`` replaces the whole
condition, a new ``oxygen.wall.model`` the whole wall. ``scale`` multiplies, after the explicit values: ``resistance`` scales the
resistance of lumped vessels and of the resistance and RCR conditions at the ends of the
selected vessels, ``compliance`` the capacitance of lumped vessels and RCR conditions and
divides the Young's modulus of the geometric vessels (their compliance is proportional to
1/E). A DataFrame row with dotted-path columns (``vessels.CCA.radius``) is the same patch.

An unknown vessel, node, section or property raises :class:`~oxyline.ModelError` naming the
variant and the path; a value the model refuses (a negative radius) fails only its variant.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.ensemble.scale import mapping as _mapping
from oxyline.ensemble.scale import scale_terms as _scale_terms
from oxyline.ensemble.scale import unknown as _unknown
from oxyline.ensemble.scale import where as _where
from oxyline.ensemble.values import ValueTable
from oxyline.errors import ModelError
from oxyline.model import (
    BC_KEYS,
    LUMPED_KEYS,
    VESSEL_KEYS,
    Model,
    _copy,
    _plain_outlet,
    _unassembled,
)

SECTIONS = ("vessels", "boundary_conditions", "blood", "oxygen", "transport", "period", "scale")
VESSEL_PROPERTIES = VESSEL_KEYS - {"name", "from", "to"}
BLOOD_KEYS = {"density", "viscosity"}
#: properties that hold one number: a mapping there is a dotted path gone too deep
#: (``vessels.aorta.radius.x``), refused with the path before anything runs
SCALAR_KEYS = {
    "vessels": {"length", "radius", "radius_in", "radius_out", "wall_thickness",
                "youngs_modulus", "poisson_ratio", "segments"},
    "lumped": LUMPED_KEYS,
    "blood": BLOOD_KEYS,
    "boundary_conditions": {"resistance", "proximal_resistance", "distal_resistance",
                            "capacitance"},
}
#: the keys of a condition's waveform: patching one replaces the whole waveform
WAVEFORM_KEYS = {"time", "flow", "pressure", "value", "fourier", "interpolation", "steady"}
RESISTANCES = {"resistance": ("resistance",), "rcr": ("proximal_resistance", "distal_resistance")}


def _scalars(props: Mapping[str, Any], kind: str, k: int, path: str) -> None:
    """Refuse a mapping where ``kind`` holds one number (a dotted path one level too deep)."""
    for key in SCALAR_KEYS[kind] & props.keys():
        if isinstance(props[key], Mapping):
            raise ModelError(f"{_where(k, f'{path}.{key}')}: expected a number, got the "
                             f"mapping {props[key]!r} (a dotted path ends at the property)")


def _check_transport(source: Mapping[str, Any], section: str, patch: Mapping[str, Any],
                     k: int) -> None:
    """Unknown keys of an ``oxygen`` or ``transport`` patch (and of its ``oxygen.wall``)
    raise here, naming the variant and the path, as unknown vessel properties do; the
    values are checked when the variant's model is built (a bad one fails the variant)."""
    from oxyline.transport import OXYGEN_KEYS, TRANSPORT_KEYS, WALL_KEYS

    allowed = OXYGEN_KEYS if section == "oxygen" else TRANSPORT_KEYS
    for key in patch:
        if key not in allowed:
            raise _unknown(k, f"{section}.{key}", f"{section} property", allowed)
    wall = patch.get("wall") if section == "oxygen" else None
    if isinstance(wall, Mapping):
        model = wall.get("model", _wall_model(source[section].get("wall")))
        for key in wall:
            if str(model) in WALL_KEYS and key not in WALL_KEYS[str(model)]:
                raise _unknown(k, f"oxygen.wall.{key}", f"property of a {model} wall",
                               WALL_KEYS[str(model)])


def _wall_model(wall: Any) -> str:
    """The closure of an ``oxygen.wall`` entry (a mapping with ``model``, or its name)."""
    return str(wall.get("model", "") if isinstance(wall, Mapping) else wall)


def _merge(base: Any, patch: Any) -> Any:
    """``patch`` deep-merged into ``base`` (new containers; mappings merge, anything else
    replaces)."""
    if not isinstance(base, Mapping) or not isinstance(patch, Mapping):
        return _copy(patch)
    out = dict(base)
    for key, value in patch.items():
        out[key] = _merge(base.get(key), value) if isinstance(value, Mapping) else _copy(value)
    return out


def _patch_vessel(vessel: Mapping[str, Any], props: Any, k: int, path: str) -> dict[str, Any]:
    props = _mapping(props, k, path)
    for key in props:
        if key not in VESSEL_PROPERTIES:
            if key in ("name", "from", "to"):
                raise ModelError(f"{_where(k, f'{path}.{key}')}: a variant cannot change the "
                                 "network's topology")
            raise _unknown(k, f"{path}.{key}", "vessel property", VESSEL_PROPERTIES)
    _scalars(props, "vessels", k, path)
    if "lumped" in props:
        lumped = _mapping(props["lumped"], k, f"{path}.lumped")
        for key in lumped:
            if key not in LUMPED_KEYS:
                raise _unknown(k, f"{path}.lumped.{key}", "lumped property", LUMPED_KEYS)
        _scalars(lumped, "lumped", k, f"{path}.lumped")
    base = dict(vessel)
    if "radius" in props:
        base.pop("radius_in", None)
        base.pop("radius_out", None)
    elif ("radius_in" in props or "radius_out" in props) and "radius" in base:
        r = base.pop("radius")
        base["radius_in"] = base["radius_out"] = r
    return _merge(base, props)


def _patch_condition(bc: Mapping[str, Any], props: Any, k: int, path: str) -> dict[str, Any]:
    props = _mapping(props, k, path)
    kind = str(props.get("type", bc.get("type", ""))).lower()
    allowed = BC_KEYS.get(kind, set())
    for key in props:
        if key not in allowed:
            raise _unknown(k, f"{path}.{key}", f"property of a {kind} condition", allowed)
    _scalars(props, "boundary_conditions", k, path)
    if "type" in props and str(props["type"]).lower() != str(bc.get("type", "")).lower():
        return _copy(dict(props))  # another kind of condition: nothing of the old one holds
    base = dict(bc)
    if kind in ("flow", "pressure") and props.keys() & (WAVEFORM_KEYS - {"interpolation",
                                                                         "steady"}):
        for key in WAVEFORM_KEYS:
            base.pop(key, None)
    if "pressure" in props:  # a resistance/RCR outlet pressure: a number or a waveform
        base.pop("pressure", None)
    return _merge(base, props)


def _value(x: Any, k: int, path: str) -> float:
    """A number of the model to scale (YAML 1.1 reads 5.0e5 as a string)."""
    try:
        return float(x)
    except (TypeError, ValueError):
        raise ModelError(f"{_where(k, path)}: cannot scale {x!r}, not a number") from None


def _scaled(data: dict[str, Any], scale: Any, k: int) -> tuple[set[int], set[str]]:
    """Apply the ``scale`` section to ``data`` (the merged model; every element written is a
    new container) and return the indices of the vessels and the nodes of the conditions it
    changed."""
    index = {v["name"]: i for i, v in enumerate(data["vessels"])}
    chosen, factors = _scale_terms(scale, index, k)
    selected = set(range(len(data["vessels"]))) if chosen is None else chosen
    vessels = data["vessels"] = list(data["vessels"])
    nodes: set[str] = set()
    changed: set[int] = set()
    for i in sorted(selected):
        v = vessels[i]
        nodes.update((str(v.get("from")), str(v.get("to"))))
        if "lumped" in v:
            lp = dict(v["lumped"])
            for key, prop in (("resistance", "resistance"), ("compliance", "capacitance")):
                if key in factors and prop in lp:
                    lp[prop] = _value(lp[prop], k, f"vessels.{v['name']}.lumped.{prop}") \
                        * factors[key]
            vessels[i] = {**v, "lumped": lp}
            changed.add(i)
        elif "compliance" in factors and "youngs_modulus" in v:
            e = _value(v["youngs_modulus"], k, f"vessels.{v['name']}.youngs_modulus")
            # compliance ∝ 1/E; a factor 0 gives E = inf, which the model refuses for the
            # variant (naming the vessel), as it refuses a negative factor's E < 0
            f = factors["compliance"]
            vessels[i] = {**v, "youngs_modulus": e / f if f != 0 else math.inf}
            changed.add(i)
    bcs = data["boundary_conditions"] = dict(data.get("boundary_conditions", {}))
    changed_nodes: set[str] = set()
    for node in [n for n in bcs if n in nodes]:
        bc = dict(bcs[node])
        kind = str(bc.get("type", "")).lower()
        where = f"boundary_conditions.{node}"
        props = RESISTANCES.get(kind, ()) if "resistance" in factors else ()
        for prop in props:
            bc[prop] = _value(bc.get(prop), k, f"{where}.{prop}") * factors["resistance"]
        if "compliance" in factors and kind == "rcr":
            bc["capacitance"] = _value(bc.get("capacitance"), k, f"{where}.capacitance") \
                * factors["compliance"]
            props = (*props, "capacitance")
        if props:  # only the conditions whose values change (an inflow stays as it is)
            bcs[node] = bc
            changed_nodes.add(node)
    return changed, changed_nodes


def merge_patch(source: Mapping[str, Any], patch: Mapping[str, Any], k: int = 0,
                ) -> tuple[dict[str, Any], set[int], set[str]]:
    """The native model ``source`` with ``patch`` (variant ``k``) merged in, sharing every
    element the patch leaves alone, and the indices of the vessels and the nodes of the
    conditions it changed. Raises :class:`ModelError` for unknown names."""
    patch = _mapping(patch, k, "patch")
    for key in patch:
        if key not in SECTIONS:
            raise _unknown(k, key, "patch section", SECTIONS)
    data = dict(source)
    touched_vessels: set[int] = set()
    touched_nodes: set[str] = set()
    if "vessels" in patch:
        vessels = data["vessels"] = list(source["vessels"])
        index = {v.get("name"): i for i, v in enumerate(vessels)}
        for name, props in _mapping(patch["vessels"], k, "vessels").items():
            if name not in index:
                raise ModelError(f"{_where(k, f'vessels.{name}')}: no vessel named {name!r} in "
                                 f"model '{source.get('name', 'network')}'")
            i = index[name]
            vessels[i] = _patch_vessel(vessels[i], props, k, f"vessels.{name}")
            touched_vessels.add(i)
    if "boundary_conditions" in patch:
        bcs = data["boundary_conditions"] = dict(source.get("boundary_conditions", {}))
        for node, props in _mapping(patch["boundary_conditions"], k,
                                    "boundary_conditions").items():
            if node not in bcs:
                raise ModelError(f"{_where(k, f'boundary_conditions.{node}')}: no boundary "
                                 f"condition at node {node!r} in model "
                                 f"'{source.get('name', 'network')}'")
            bcs[node] = _patch_condition(bcs[node], props, k, f"boundary_conditions.{node}")
            touched_nodes.add(node)
    if "blood" in patch:
        for key in _mapping(patch["blood"], k, "blood"):
            if key not in BLOOD_KEYS:
                raise _unknown(k, f"blood.{key}", "blood property", BLOOD_KEYS)
        _scalars(patch["blood"], "blood", k, "blood")
        data["blood"] = _merge(source.get("blood") or {}, patch["blood"])
    for section in ("oxygen", "transport"):
        if section in patch:
            if section not in source:
                raise ModelError(f"{_where(k, section)}: the model has no '{section}' section "
                                 "to patch")
            _check_transport(source, section, _mapping(patch[section], k, section), k)
            data[section] = _merge(source[section], patch[section])
            wall = patch[section].get("wall") if section == "oxygen" else None
            if isinstance(wall, Mapping) and "model" in wall \
                    and str(wall["model"]) != _wall_model(source[section].get("wall")):
                # another wall closure: none of the old one's keys hold (as a new condition
                # type replaces the whole condition)
                data[section]["wall"] = _copy(dict(wall))
    if "period" in patch:
        data["period"] = patch["period"]
    if "scale" in patch:
        scaled_vessels, scaled_nodes = _scaled(data, patch["scale"], k)
        touched_vessels |= scaled_vessels
        touched_nodes |= scaled_nodes
    return data, touched_vessels, touched_nodes


def apply_patch(model: Model | Mapping[str, Any] | str, patch: Mapping[str, Any]
                ) -> dict[str, Any]:
    """The native model dict of one variant: ``patch`` deep-merged into ``model`` (a
    :class:`~oxyline.Model`, a native dict or anything :func:`oxyline.load_model` reads).
    ``oxyline.simulate(apply_patch(model, patch))`` is that variant run on its own.

    >>> import oxyline
    >>> from oxyline.ensemble import apply_patch
    >>> m = apply_patch("bifurcation", {"vessels": {"parent": {"radius": 0.004}}})
    >>> m["vessels"][0]["radius"]
    0.004
    """
    from oxyline.loader import load_model

    base = load_model(model)
    return _copy(merge_patch(base.source, patch)[0])


def _column_path(column: Any, names: Mapping[str, set[str]], k: int) -> list[str]:
    """The keys of a dotted-path column (``vessels.CCA.radius`` -> ``["vessels", "CCA",
    "radius"]``); a vessel or node name may itself contain dots: the longest known name wins.
    A tuple (a MultiIndex column) is the keys themselves (trailing empty levels dropped).
    Unknown names and empty keys raise :class:`ModelError` naming variant ``k`` and the
    column."""
    if isinstance(column, tuple):
        parts = [str(p) for p in column]
        while len(parts) > 1 and parts[-1] == "":
            parts.pop()
        label = ".".join(parts)
    else:
        label = str(column)
        parts = label.split(".")
    section, rest = parts[0], parts[1:]
    if section in names and not isinstance(column, tuple):
        for cut in range(len(rest) - 1, 0, -1):
            if ".".join(rest[:cut]) in names[section]:
                rest = [".".join(rest[:cut]), *rest[cut:]]
                break
        else:
            no_property = len(rest) <= 1 or ".".join(rest) in names[section]
            raise ModelError(f"{_where(k, label)}: expected {section}.NAME.PROPERTY"
                             if no_property else
                             f"{_where(k, label)}: no vessel or node of the model starts "
                             "this path")
    if "" in (section, *rest):
        raise ModelError(f"{_where(k, label)}: empty key in the column's dotted path")
    return [section, *rest]


def _cell(value: Any) -> tuple[bool, Any]:
    """(whether the cell sets a value, the plain Python value): an empty cell (NaN, None, or
    pandas' ``NA``/``NaT`` of a nullable column) leaves the base model's value."""
    if type(value) is float:  # most cells (``tolist()`` of a float column): one test
        return (False, None) if math.isnan(value) else (True, value)
    if hasattr(value, "item") and not isinstance(value, (list, tuple, dict)):
        try:
            value = value.item()  # a numpy scalar (or 0-d array): the Python value
        except (ValueError, TypeError):
            pass
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return False, None
    if type(value).__name__ in ("NAType", "NaTType"):  # pandas' missing values
        return False, None
    return True, value


def _put(patch: dict[str, Any], path: Sequence[str], value: Any) -> None:
    node: dict[str, Any] = patch
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value


def dotted_patch(row: Mapping[str, Any], vessel_names: Iterable[str], nodes: Iterable[str],
                 k: int = 0) -> dict[str, Any]:
    """The patch of one row of dotted-path columns (``vessels.CCA.radius``,
    ``boundary_conditions.ica_out.resistance``, ``blood.viscosity``, ``scale.resistance``).
    A vessel or node name may itself contain dots: the longest known name wins. An empty
    (NaN) cell leaves the base model's value."""
    names = {"vessels": set(vessel_names), "boundary_conditions": set(nodes)}
    patch: dict[str, Any] = {}
    for column, value in row.items():
        keep, value = _cell(value)
        if keep:
            _put(patch, _column_path(column, names, k), value)
    return patch


def frame_patches(frame: Any, vessel_names: Iterable[str], nodes: Iterable[str]
                  ) -> list[dict[str, Any]]:
    """The patches of a DataFrame's rows (see :func:`dotted_patch`): each column's path is
    resolved once (not once per cell) and its values read as one list, so a wide frame of
    many rows (a sensitivity design, a population table) costs the calling thread a dict
    insertion per cell. The same patches as :func:`dotted_patch` of each row, with the
    same key order (the columns')."""
    names = {"vessels": set(vessel_names), "boundary_conditions": set(nodes)}
    patches: list[dict[str, Any]] = [{} for _ in range(len(frame))]
    for c, column in enumerate(frame.columns):
        path = None  # resolved at the column's first value: an empty column names nothing
        # tolist(): Python scalars (as DataFrame.to_dict gives) for numeric columns
        for k, (patch, value) in enumerate(zip(patches, frame.iloc[:, c].tolist(),
                                               strict=True)):
            keep, value = _cell(value)
            if keep:
                if path is None:
                    path = _column_path(column, names, k)
                _put(patch, path, value)
    return patches


def as_patches(variants: Any, model: Model) -> tuple[list[dict[str, Any]], Any]:
    """The patches of ``variants`` (a sequence of patch dicts or a pandas DataFrame with
    dotted-path columns) and the DataFrame's index (None for a sequence)."""
    if hasattr(variants, "to_dict") and hasattr(variants, "columns"):
        nodes = list(model.source.get("boundary_conditions", {}))
        return frame_patches(variants, model.vessel_names, nodes), variants.index
    if isinstance(variants, (str, bytes)) or not isinstance(variants, Iterable):
        raise ModelError("simulate_ensemble: variants must be a sequence of patch dicts or a "
                         f"DataFrame, got {type(variants).__name__}")
    patches = [dict(_mapping(p, k, "patch")) for k, p in enumerate(variants)]
    return patches, None


def flatten(patch: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """The scalar leaves of a patch by dotted path (tables and lists are left out)."""
    out: dict[str, Any] = {}
    for key, value in patch.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, path + "."))
        elif isinstance(value, (bool, int, float, str)):
            out[path] = value
    return out


@dataclass
class Variant:
    """A variant ready to run: its canonical patch for the core (None: the base model), its
    model (canonical description, period and transport facts; never assembled here). The
    patch's vessels (by index) and plain outlets (resistance, RCR with a constant pressure)
    are handed to the core as the canonical dicts themselves (``vessels``, ``outlets``), the
    rest as JSON text: the text of a variant that rescales every vessel cost the thread that
    feeds the workers more than the rest of its work (the repr of every float). A patch on
    the value route (:mod:`oxyline.ensemble.values`) has ``values`` and ``tables`` instead."""

    patch_json: str | None
    model: Model
    vessels: dict[int, Any] | None = None
    outlets: dict[str, Any] | None = None
    #: one SI value per target of :class:`~oxyline.ensemble.values.ValueTable` (NaN: the
    #: base value), or None
    values: np.ndarray | None = None
    #: the replaced waveform tables ``(target, time, value)`` in SI, or None
    tables: list[tuple[int, np.ndarray, np.ndarray]] | None = None


class Patcher:
    """Turns patches into :class:`Variant` s. The canonical form of the base model's elements
    is computed once; a variant converts only the vessels and conditions its patch changed,
    or takes the value route (:mod:`oxyline.ensemble.values`)."""

    def __init__(self, base: Model) -> None:
        self.base = base
        table = ValueTable(base)
        #: the value route (None: every patch takes the full path)
        self.scaler = table if table.targets else None
        canon = base.canonical
        self._vessels = canon["vessels"]
        self._bcs = canon["boundary_conditions"]

    @property
    def _periods(self) -> dict[str, list[tuple[float, str]]]:
        """Each condition's waveform periods, to check a variant's period as a model load
        does (computed once, when a patch first needs them)."""
        periods = self.__dict__.get("_periods_cache")
        if periods is None:
            units = str(self.base.source.get("units", "SI"))
            bcs = self.base.source.get("boundary_conditions", {})
            periods = self.__dict__["_periods_cache"] = {
                node: _core.read_conditions({node: bc}, units)[1] for node, bc in bcs.items()}
        return periods

    def _parse(self, patch: Any, k: int) -> Any:
        return None if self.scaler is None else self.scaler.parse(patch, k)

    def check(self, patch: Any, k: int) -> None:
        """Raise :class:`ModelError` for unknown names in ``patch`` (variant ``k``), as
        :meth:`variant` would; a patch on the value route is checked without merging it."""
        if self._parse(patch, k) is None:
            merge_patch(self.base.source, patch, k)

    def check_all(self, patches: Sequence[Any], numbers: range | None = None) -> dict[int, Any]:
        """:meth:`check` every patch (variant ``numbers[i]``, default ``i``) and return the
        value-route rows of those that take it, by position in ``patches`` (see
        :meth:`~oxyline.ensemble.values.ValueTable.rows`): the parse serves both, and the
        values of the whole ensemble are one numpy pass."""
        numbers = range(len(patches)) if numbers is None else numbers
        fast: list[int] = []
        parsed = []
        for i, patch in enumerate(patches):
            p = self._parse(patch, numbers[i]) if patch else None
            if p is None:
                merge_patch(self.base.source, patch, numbers[i])
            else:
                parsed.append(p)
                fast.append(i)
        if not parsed:
            return {}
        assert self.scaler is not None
        rows = self.scaler.rows(parsed)
        return {i: row for i, row in zip(fast, rows, strict=True) if row is not None}

    def variant(self, patch: Mapping[str, Any], k: int, row: Any = None) -> Variant:
        """Variant ``k``. Unknown names raise :class:`ModelError`; a value the model refuses
        raises it too, which the caller records as that variant's failure. ``row``: the
        value-route row of the patch from :meth:`check_all`, if computed there."""
        if not patch:
            return Variant(None, self.base)
        if row is None and self.scaler is not None:
            parsed = self.scaler.parse(patch, k)
            row = None if parsed is None else self.scaler.rows([parsed])[0]
        if row is not None:
            assert self.scaler is not None
            return Variant(None, self.scaler.model_with_period(row.period), values=row.values,
                           tables=row.tables)
        data, vessels, nodes = merge_patch(self.base.source, patch, k)

        def convert_vessels(items: list[Any], units: str) -> list[Any]:
            out = list(self._vessels)
            for i in sorted(vessels):
                out[i] = _core.read_vessels([items[i]], units)[0]
            return out

        def convert_conditions(items: Mapping[str, Any], units: str
                               ) -> tuple[dict[str, Any], list[Any]]:
            out, periods = dict(self._bcs), []
            for node, bc in items.items():
                if node in nodes:
                    canon, p = _core.read_conditions({node: bc}, units)
                    out[node] = canon[node]
                    periods += p
                else:
                    periods += self._periods[node]
            return out, periods

        model = _unassembled(data, convert_vessels, convert_conditions)
        canon, base = model.canonical, self.base.canonical
        core: dict[str, Any] = {}
        handed = {i: canon["vessels"][i] for i in sorted(vessels)}
        outlets, other = {}, {}
        for n in nodes:
            bc = canon["boundary_conditions"][n]
            (outlets if _plain_outlet(bc) else other)[n] = bc
        if other:
            core["boundary_conditions"] = other
        if canon["blood"] != base["blood"]:
            core["blood"] = canon["blood"]
        if canon.get("transport") != base.get("transport"):
            core["transport"] = canon["transport"]
        return Variant(json.dumps(core, separators=(",", ":")), model, handed or None,
                       outlets or None)
