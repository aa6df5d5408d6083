"""Variant patches: what one member of an ensemble changes in the base model.

A patch is a dict in the native model format, deep-merged into the model::

    {"vessels": {"CCA": {"radius": 3.1e-3}},              # vessels by name
     "boundary_conditions": {"ica_out": {"resistance": 2e9}},   # conditions by node
     "blood": {"viscosity": 4e-3}, "oxygen": {"wall": {"k": 5e-6}},
     "period": 0.8,
     "scale": {"resistance": 1.2, "compliance": 0.8, "vessels": ["CCA", "ICA"] | "all"}}

The core applies it (``oxyline_core::model::patch``: the merge rules, the ``scale`` section
and the checks are there, docs/ensembles.md); this module turns tables and DataFrames into
patches (a row with dotted-path columns such as ``vessels.CCA.radius`` is a patch) and
prepares each variant for the core's workers.

An unknown vessel, node, section or property raises :class:`~oxyline.ModelError` naming the
variant and the path before anything runs; a value the patch or the model refuses (a
compliance factor 0, a negative radius) fails only its variant, with a message naming the
patch path and the value.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from oxyline import _core
from oxyline.description import copy_description
from oxyline.errors import ModelError
from oxyline.model import Model
from oxyline.structured_tree import TYPE as STRUCTURED_TREE


def _where(k: int, path: str) -> str:
    """The prefix of every patch error: the variant and the patch path."""
    return f"variant {k}: {path}"


def _mapping(value: Any, k: int, path: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ModelError(f"{_where(k, path)}: expected a mapping, got {value!r}")
    return value


@dataclass
class Merged:
    """A patch applied by the core (``oxyline_core::model::patch``): the variant's native
    model dict (None if ``refused``), the indices of the vessels and the nodes of the
    conditions it changed, the patch paths (``path = value``) that changed each of them
    (keys ``("vessel", i)``, ``("condition", node)``), and the message of a value the patch
    cannot apply (a compliance factor 0, a factor that is not a number), which fails only
    its variant."""

    data: dict[str, Any] | None
    vessels: set[int]
    nodes: set[str]
    paths: dict[tuple[str, Any], list[str]]
    refused: str | None


def merge(source: Mapping[str, Any], patch: Any, k: int = 0) -> Merged:
    """``patch`` (variant ``k``) applied to the native model ``source`` by the core. A path
    that names nothing of the model raises :class:`ModelError` naming the variant and the
    path; a value the patch cannot apply is returned as ``refused``."""
    # the core shares the patch's objects in the model: a copy, so that the variant's model
    # never aliases the caller's lists
    data, vessels, nodes, paths, refused = _core.merge_patch(dict(source), copy_description(patch), k)
    return Merged(data, set(vessels), set(nodes), paths, refused)


def merge_patch(source: Mapping[str, Any], patch: Mapping[str, Any], k: int = 0) -> Merged:
    """:func:`merge`, its ``data`` the native model ``source`` with ``patch`` (variant ``k``)
    applied, sharing every element the patch leaves alone. Raises :class:`ModelError` for
    unknown names and refused values."""
    m = merge(source, patch, k)
    if m.data is None:
        raise ModelError(m.refused)
    return m


def patch_paths(patch: Mapping[str, Any]) -> list[str]:
    """The scalar leaves of a patch as ``path = value`` (what an error of its variant that the
    core finds while it assembles the variant is traced to)."""
    return [f"{p} = {v!r}" for p, v in flatten(patch).items()]


def traced(k: int, paths: Sequence[str] | None, error: Exception | str) -> str:
    """A schema error of a patched element, prefixed by the variant and the patch paths that
    changed the element (``variant 1: vessels.aorta.radius = -1.0: vessel 'aorta': ...``)."""
    text = str(error)
    if text.startswith(f"variant {k}: "):
        return text
    return f"variant {k}: {'; '.join(paths)}: {text}" if paths else f"variant {k}: {text}"


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
    return copy_description(merge_patch(base.source, patch).data)


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
    if value is None or (isinstance(value, float) and math.isnan(value)) \
            or type(value).__name__ in ("NAType", "NaTType"):  # pandas' missing values
        return False, None
    return True, value


def frame_patches(frame: Any, vessel_names: Iterable[str], nodes: Iterable[str]
                  ) -> list[dict[str, Any]]:
    """The patches of a DataFrame's rows of dotted-path columns (``vessels.CCA.radius``,
    ``boundary_conditions.ica_out.resistance``, ``blood.viscosity``, ``scale.resistance``; a
    name may itself contain dots: the longest known name wins; an empty (NaN) cell leaves the
    base model's value): each column's path is resolved once (not once per cell) and its
    values read as one list, so a wide frame of many rows (a sensitivity design, a population
    table) costs the calling thread a dict insertion per cell; keys in the columns' order."""
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
                node = patch
                for key in path[:-1]:
                    node = node.setdefault(key, {})
                node[path[-1]] = value
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


def variant_model(data: dict[str, Any], reader: Any = None, vessels: Iterable[int] = (),
                  nodes: Iterable[str] = ()) -> Model:
    """The model of ``data`` with its canonical description, read by the core in its one order
    and not assembled (an ensemble's variant). ``reader``: a ``_core.VariantReader`` of the
    base model, whose canonical vessels and conditions are reused, except the vessels at the
    indices ``vessels`` and the conditions of the nodes ``nodes``, which are read (None: every
    element is read). A :class:`ModelError` about one element has the attribute ``element``:
    ``("vessel", i)`` or ``("condition", node)`` (None: the other sections)."""
    reader = _core.VariantReader() if reader is None else reader
    name, canon, period, info = reader.read(data, sorted(vessels), list(nodes))
    sim = data.get("simulation", {}) or {}
    return Model(name=name, simulation=dict(sim), period=period, _source=data, transport=info,
                 _canonical=canon)


@dataclass
class Variant:
    """A variant ready to run: its canonical patch for the core (None: the base model), its
    model (canonical description, period and transport facts; never assembled here). The
    patch's vessels (by index) and conditions (by node) are handed to the core as the
    canonical dicts themselves (``vessels``, ``outlets``), read there by the core's serde
    types; the rest as JSON text (the text of a variant that rescales every vessel cost the
    thread that feeds the workers more than the rest of its work)."""

    patch_json: str | None
    model: Model
    vessels: dict[int, Any] | None = None
    outlets: dict[str, Any] | None = None


def _refuse_structured_trees(base: Model) -> None:
    """Raise :class:`ModelError` naming the first structured-tree outlet of ``base``: a
    variant shares the base model's canonical elements by position, and the vessels of a
    grown tree are not elements of the file (each variant would have to grow its trees)."""
    bcs = base.source.get("boundary_conditions")
    for node, bc in (bcs.items() if isinstance(bcs, Mapping) else ()):
        if isinstance(bc, Mapping) and bc.get("type") == STRUCTURED_TREE:
            raise ModelError(
                f"boundary condition '{node}' ({STRUCTURED_TREE}): an ensemble cannot vary a "
                "model with structured-tree outlets; run each variant with simulate(), or "
                "give the outlet a Windkessel (rcr) condition")


class Patcher:
    """Turns patches into :class:`Variant` s: the core applies each patch
    (``oxyline_core::model::patch``) and reads the vessels and conditions it changed; the
    canonical form of the base model's other elements is computed once and shared."""

    def __init__(self, base: Model) -> None:
        _refuse_structured_trees(base)
        self.base = base
        #: the base's canonical elements, which a variant shares where its patch leaves them
        self._reader = _core.VariantReader(base.canonical)

    def check_all(self, patches: Sequence[Any], numbers: range | None = None) -> None:
        """Raise :class:`ModelError` for unknown names in every patch (variant ``numbers[i]``,
        default ``i``), as :meth:`variant` would; a value the patch cannot apply is not
        raised here: it fails only its variant."""
        numbers = range(len(patches)) if numbers is None else numbers
        for i, patch in enumerate(patches):
            if patch:
                merge(self.base.source, patch, numbers[i])

    def _read(self, merged: Merged, patch: Mapping[str, Any], k: int) -> Model:
        """The model of a merged variant: the elements it changed read by the core's schema
        (the others are the base model's); an error names the patch paths that changed the
        element it is about."""
        assert merged.data is not None
        try:
            return variant_model(merged.data, self._reader, merged.vessels, merged.nodes)
        except ModelError as e:
            element = getattr(e, "element", None)
            if element is not None:  # a vessel or condition the patch changed
                paths = merged.paths.get(element)
            else:  # blood, oxygen, transport, period: the other sections
                paths = patch_paths({key: value for key, value in patch.items()
                                     if key not in ("vessels", "boundary_conditions", "scale")})
            raise ModelError(traced(k, paths, e)) from None

    def variant(self, patch: Mapping[str, Any], k: int) -> Variant:
        """Variant ``k``. Unknown names raise :class:`ModelError`; a value the patch or the
        model refuses raises it too, naming the variant and the patch paths, which the
        caller records as that variant's failure."""
        if not patch:
            return Variant(None, self.base)
        merged = merge_patch(self.base.source, patch, k)
        model = self._read(merged, patch, k)
        canon, base = model.canonical, self.base.canonical
        core = {k: canon[k] for k in ("blood", "transport") if canon.get(k) != base.get(k)}
        handed = {i: canon["vessels"][i] for i in sorted(merged.vessels)}
        outlets = {n: canon["boundary_conditions"][n] for n in merged.nodes}
        return Variant(json.dumps(core, separators=(",", ":")), model, handed or None,
                       outlets or None)
