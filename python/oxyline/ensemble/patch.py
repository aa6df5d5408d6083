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
    :class:`~oxyline.Model`, a native dict or anything :func:`oxyline.load_model` reads) by the
    core. ``oxyline.simulate(apply_patch(model, patch))`` is that variant run on its own.
    Raises :class:`ModelError` for unknown names and refused values.

    >>> import oxyline
    >>> from oxyline.ensemble import apply_patch
    >>> m = apply_patch("bifurcation", {"vessels": {"parent": {"radius": 0.004}}})
    >>> m["vessels"][0]["radius"]
    0.004
    """
    from oxyline.loader import load_model

    data, _, _, _, refused = _core.merge_patch(dict(load_model(model).source), patch, 0)
    if data is None:
        raise ModelError(refused)
    # a copy: the result is the caller's, sharing nothing with the model or the patch
    return copy_description(data)


def _column_path(column: Any, names: tuple[list[str], list[str]], k: int) -> list[str]:
    """The keys of a dotted-path column (``vessels.CCA.radius`` -> ``["vessels", "CCA",
    "radius"]``), resolved by the core (``oxyline_core::model::path::column_keys``: a vessel
    or node name may itself contain dots, the longest known name wins); a tuple (a MultiIndex
    column) is the keys themselves. ``names``: the model's vessel names and nodes. Unknown
    names and empty keys raise :class:`ModelError` naming variant ``k`` and the column."""
    if isinstance(column, tuple):
        return _core.column_keys([str(p) for p in column], False, *names, k)
    return _core.column_keys(str(column).split("."), True, *names, k)


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
    names = ([str(n) for n in vessel_names], [str(n) for n in nodes])
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
    """A variant ready to run: the sections besides its elements that differ from the base
    model's, as canonical JSON for the core (None: the base model), its model (canonical
    description, period and transport facts; never assembled here), and the elements its
    patch changed as canonical dicts, vessels by index and conditions by node (read there by
    the core's serde types)."""

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
    """Turns patches into :class:`Variant` s, one core call each
    (``_core.VariantReader.prepare``: the patch merged by ``oxyline_core::model::patch``, the
    elements it changed read, errors traced to the patch paths); the canonical form of the
    base model's other elements is computed once and shared."""

    def __init__(self, base: Model) -> None:
        _refuse_structured_trees(base)
        self.base = base
        #: the base's canonical elements, which a variant shares where its patch leaves them
        self._reader = _core.VariantReader(base.canonical)

    def check_all(self, patches: Sequence[Any], numbers: range | None = None) -> None:
        """Raise :class:`ModelError` for unknown names in every patch (variant ``numbers[i]``,
        default ``i``), checked by the core in one call; a value the patch cannot apply is not
        raised here: it fails only its variant."""
        numbers = range(len(patches)) if numbers is None else numbers
        self._reader.check(self.base.source, list(patches), list(numbers))

    def variant(self, patch: Mapping[str, Any], k: int) -> Variant:
        """Variant ``k``. Unknown names raise :class:`ModelError`; a value the patch or the
        model refuses raises it too, naming the variant and the patch paths, which the
        caller records as that variant's failure."""
        if not patch:
            return Variant(None, self.base)
        sections, vessels, outlets, (name, canon, period, info), data = \
            self._reader.prepare(self.base.source, patch, k)
        sim = data.get("simulation", {}) or {}
        model = Model(name=name, simulation=dict(sim), period=period, _source=data,
                      transport=info, _canonical=canon)
        return Variant(sections, model, vessels, outlets)
