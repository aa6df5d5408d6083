"""Network models: the :class:`Model` handle over the core's model. The core's schema
(``oxyline_core::model``) reads a native model dict in one call (every key, unit, default and
range check, the oxygen/species sections included) and builds the network from what it read;
this module hands the user's dict over and keeps the run settings and transport facts. A leaf
module: reading files, built-in names and other formats is :func:`oxyline.loader.load_model`'s
job. The schema is described in docs/schema.md.
"""

from __future__ import annotations

import functools
import pickle
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from oxyline import _core
from oxyline import memory as _memory  # a leaf too: imports only _core and errors
from oxyline.description import copy_description
from oxyline.errors import core_errors, warn_implausible
from oxyline.options import output_names, output_vessels
from oxyline.structured_tree import build_with_trees, expanded, has_trees

#: Above this many segments a model keeps its ``source`` packed (the large-model threshold of
#: :data:`oxyline.run.LARGE_MODEL_SEGMENTS`): its dicts, ~170 B per segment, are the largest
#: Python-side part of a whole-tree run's memory, and nothing reads them while the core runs.
PACKED_SOURCE_SEGMENTS = _core.PACKED_DESCRIPTION_SEGMENTS


@dataclass
class Model:
    """A validated network model in SI units, assembled by the core.

    ``simulation`` holds the run settings from the file (overridable in
    :func:`oxyline.simulate`), ``source`` the native dict it was read from. ``canonical``, the
    JSON-able SI description (the core's input), is written from ``source`` when first asked
    for: a whole tree's canonical vessels cost ~185 B per segment beside the core's own tables.
    Above :data:`PACKED_SOURCE_SEGMENTS` segments ``source`` is kept packed (pickled and
    compressed: a few bytes per segment instead of ~170 B of dicts beside the running core)
    and each read of it returns a fresh copy.

    >>> import oxyline
    >>> m = oxyline.load_model("bifurcation")
    >>> m.name, m.vessel_names, m.period
    ('bifurcation', ['parent', 'daughter1', 'daughter2'], 1.0)
    """

    name: str
    simulation: dict[str, Any] = field(default_factory=dict)
    period: float | None = None
    #: the native dict (see ``source``), None while packed in ``_packed``
    _source: dict[str, Any] | None = field(default_factory=dict)
    #: species transport facts for results: ``species`` (names), ``oxygen`` (name of the O2
    #: species or None), ``solubility`` (O2, mol m^-3 mmHg^-1)
    transport: dict[str, Any] = field(default_factory=dict)
    #: the vessels output when the run selects none (None: all; structured-tree vessels are
    #: left out, see :mod:`oxyline.structured_tree`)
    default_output_vessels: list[str] | None = None
    _network: Any = field(default=None, repr=False, compare=False)
    _canonical: dict[str, Any] | None = field(default=None, repr=False, compare=False)
    #: the vessel names and canonical transport section the core read (without ``canonical``)
    _names: list[str] | None = field(default=None, repr=False, compare=False)
    _transport_spec: dict[str, Any] | None = field(default=None, repr=False, compare=False)
    #: ``source`` pickled and compressed (large models, see :data:`PACKED_SOURCE_SEGMENTS`)
    _packed: bytes | None = field(default=None, repr=False, compare=False)

    @property
    def source(self) -> dict[str, Any]:
        """The native dict the model was read from (a fresh copy when kept packed)."""
        if self._source is None and self._packed is not None:
            return pickle.loads(zlib.decompress(self._packed))
        return self._source if self._source is not None else {}

    @source.setter
    def source(self, data: dict[str, Any]) -> None:
        self._source, self._packed = data, None
        self._pack_source()

    def _pack_source(self) -> None:
        """Keep ``source`` packed when the assembled network has more than
        :data:`PACKED_SOURCE_SEGMENTS` segments and the dict pickles (anything else: as is)."""
        if self._source is None or self._network is None:
            return
        if int(self._network.summary()["segments"]) <= PACKED_SOURCE_SEGMENTS:
            return
        packed = _packed(self._source)
        if packed is not None:
            self._source, self._packed = None, packed

    @property
    def canonical(self) -> dict[str, Any]:
        """The canonical SI description (written from ``source`` on first use)."""
        if self._canonical is None:
            native = expanded(self.source)
            canonical = _core.canonical_model(native)
            # the core's map is sorted by node; keep the file's order (plots, legends, tables)
            bcs = canonical.get("boundary_conditions") or {}
            order = {n: i for i, n in enumerate(native.get("boundary_conditions") or {})}
            canonical["boundary_conditions"] = dict(
                sorted(bcs.items(), key=lambda kv: order.get(kv[0], len(order))))
            self._canonical = canonical
        return self._canonical

    @property
    def transport_spec(self) -> dict[str, Any] | None:
        """The canonical transport section (None without species)."""
        if self._canonical is None:
            return self._transport_spec
        return self._canonical.get("transport")

    @property
    def network(self) -> _core.Network:
        """The assembled Rust network (built on first use)."""
        if self._network is None:
            self._network = _network(self.canonical, self.simulation.get("max_memory"))
        return self._network

    @property
    def vessel_names(self) -> list[str]:
        if self._names is not None:
            return list(self._names)
        return [v["name"] for v in self.canonical["vessels"]]

    def summary(self) -> dict[str, Any]:
        """Counts, totals and the RK4 stability limit (for ``oxyline validate``)."""
        s = dict(self.network.summary())
        dt_max, element, exact = self.network.rk4_stability_limit()
        s.update(rk4_dt_max=dt_max, rk4_limiting_element=element, rk4_limit_exact=exact,
                 period=self.period, name=self.name)
        return s

    def to_dict(self) -> dict[str, Any]:
        """The model as a plain dict in the user-facing schema (SI)."""
        if self._source is None:  # packed: each read is a fresh copy already
            return self.source
        return copy_description(self._source)

    def __getstate__(self) -> dict[str, Any]:
        # the core's network (and the output layout cached beside it) cannot be pickled: a
        # model sent to a Dask worker builds its own there
        state = dict(self.__dict__, _network=None)
        state.pop("_layout_cache", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        # a model pickled before ``source`` could be packed kept it as a plain attribute
        if "source" in state:
            state = dict(state, _source=state.pop("source"), _packed=None)
        self.__dict__.update(state)


def _network(canonical: dict[str, Any], max_memory: Any = None, *,
             keep_circuit: bool | None = None) -> _core.Network:
    """The core network of a canonical model (an ensemble's variant, an unpickled model): its
    dicts are read by the core's serde types in place, no text written in between.
    ``keep_circuit``: keep the circuit's tables (the circuit's diagnostics, the impedance) or
    drop them once the run's matrices are built (None: drop them for a large network; a run
    reads only its matrices)."""
    limit = _memory.limit(max_memory, "simulation: max_memory")
    with core_errors(f"model '{canonical.get('name', '?')}'"):
        return _core.Network(canonical, limit, keep_circuit)


def circuit_network(model: Model) -> _core.Network:
    """A network of ``model`` that keeps its circuit's tables: its own, or for a large model
    (whose network dropped them once built) the model assembled anew."""
    if model.network.circuit_kept():
        return model.network
    return _network(model.canonical, model.simulation.get("max_memory"), keep_circuit=True)


def build_model(data: dict[str, Any]) -> Model:
    """Validate a native model dict (the README schema) and assemble it. A description that
    counts more than :data:`PACKED_SOURCE_SEGMENTS` segments by itself (its vessels'
    ``segments``) is not copied: the core reads the caller's dict and the model keeps it
    packed before the network is built (a copy's dicts, ~100 B per segment, would sit under
    the build's peak)."""
    data = dict(data)
    if _segments_at_least(data) > PACKED_SOURCE_SEGMENTS and not has_trees(data):
        packed = _packed(data)  # the snapshot the model keeps, taken as the core reads it
        if packed is not None:
            return _build_native(data, packed=packed)
    return _build(copy_description(data))


def _segments_at_least(data: dict[str, Any]) -> int:
    """A lower bound of the segments of a native description: its vessels' own ``segments``
    (1 for a vessel without an integer count; segmentation settings only add segments)."""
    vessels = data.get("vessels")
    if not isinstance(vessels, list):
        return 0
    n = 0
    for v in vessels:
        k = v.get("segments") if isinstance(v, dict) else None
        n += k if type(k) is int and k > 1 else 1
    return n


def _packed(data: dict[str, Any]) -> bytes | None:
    """``data`` pickled and compressed (None if it does not pickle): a copy of a few bytes
    per segment."""
    try:
        # level 1: the vessels' repeated keys and values compress ~10x at a fraction of the
        # pickling's cost
        return zlib.compress(pickle.dumps(data, protocol=5), 1)
    except (pickle.PicklingError, TypeError, AttributeError):
        return None


def _build(data: dict[str, Any], *, plausibility: bool = True) -> Model:
    """The model of ``data``, which becomes the model's ``source``: callers pass a dict they
    own (a copy of the user's, or one they built). ``plausibility=False`` for numbers that are
    not in SI (the svZeroDSolver drop-in runs in a cgs file's own numbers): the ranges are SI."""
    native = functools.partial(_build_native, plausibility=plausibility)
    if has_trees(data):  # a model-to-model step, like an importer
        # the trees' vessels are estimated against the memory allowed before they are grown
        return build_with_trees(data, native, _core.read_conditions, _memory.default_limit())
    return native(data)


def _build_native(data: dict[str, Any], grow: Callable[[Any], Any] | None = None, *,
                  plausibility: bool = True, packed: bytes | None = None) -> Model:
    """:func:`_build` of a model without structured-tree conditions: the core reads ``data``
    once and builds the network from what it read; ``grow`` adds the structured trees to those
    parts first (:func:`oxyline.structured_tree.build_with_trees`). ``packed``: ``data``
    is the caller's own dict and this its packed copy, which the model keeps instead."""
    parts, name, period, tr, info = _core.read_model(data)
    if grow is not None:
        grow(parts)
    sim = copy_description(dict(data.get("simulation") or {}))
    model = Model(name=name, simulation=sim, period=period,
                  _source=None if packed is not None else data, _packed=packed, transport=info,
                  _names=parts.names(), _transport_spec=tr)
    limit = _memory.limit(sim.get("max_memory"), "simulation: max_memory")
    with core_errors(f"model '{name}'"):
        model._network = _core.Network.from_parts(parts, limit)
    model._pack_source()
    if plausibility:
        warn_implausible(model._network.plausibility())
    out = sim.get("output") or {}
    if "variables" in out or "vessels" in out:  # unknown names fail at load time too
        model.network.output_layout(variables=output_names(out.get("variables"), "variables"),
                                    vessels=output_vessels(out.get("vessels", "all")))
    return model
