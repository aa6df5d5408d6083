"""Network models: the :class:`Model` handle over the core's model. The core's schema
(``oxyline_core::model``) checks every key, unit and value of a native model dict and writes
the canonical SI description; this module hands the user's dict over and keeps the run
settings and transport facts. A leaf module: reading files, built-in names and other formats
is :func:`oxyline.loader.load_model`'s job.

The user-facing schema (see README) is::

    name: carotid
    units: SI                          # or cgs (cm, dyn/cm^2, mL/s) as svZeroDSolver files
    blood: {density: 1050, viscosity: 0.0035}
    arrangement: inverted-L            # L, pi
    segmentation: {max_length: 0.0065} # or per-vessel `segments: N`
    period: 1.0
    vessels: [...]
    boundary_conditions: {...}
    simulation: {cycles: 10, dt: auto, method: auto, output: {cycles: last, every: 1e-3}}
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from oxyline import _core
from oxyline import memory as _memory  # a leaf too: imports only _core and errors
from oxyline.errors import ModelError, warn_implausible
from oxyline.structured_tree import build_with_trees, expanded, has_trees
from oxyline.units import factor

#: the schema's key sets, as the core checks them
VESSEL_KEYS = frozenset(_core.VESSEL_KEYS)
LUMPED_KEYS = frozenset(_core.LUMPED_KEYS)
BC_KEYS = {kind: frozenset(keys) for kind, keys in _core.BC_KEYS.items()}
METHODS = frozenset(_core.METHODS)


def output_names(value: Any, key: str) -> list[str] | None:
    """An output selection list of names (None, or ``all``: everything); a single name is a
    list of one."""
    if value is None or value == "all":
        return None
    if isinstance(value, str):
        return [value]
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise ModelError(f"simulation output: {key} must be a list of names, got {value!r}")
    return list(value)


def output_vessels(value: Any) -> list[str] | None:
    """Output ``vessels``: ``all`` (None: every vessel with output), ``none`` (no vessel) or a
    list of vessel names."""
    if value == "all":
        return None
    if value == "none":
        return []
    return output_names(value, "vessels")


_ATOMS = frozenset({str, int, float, bool, type(None)})


def _copy(data: Any) -> Any:
    """Deep copy of a model description: dicts and lists (tuples become lists) are rebuilt,
    plain values shared, anything else (arrays, ...) deep-copied. A quarter of the cost of a JSON
    round trip on 10^5-vessel models and linear in their size."""
    t = type(data)
    # a dict or list of plain values only (a vessel, a waveform table) is copied in C: the
    # type check of its values runs in C too (map + issuperset), 4x faster than rebuilding it
    if t is dict:
        if _ATOMS.issuperset(map(type, data.values())):
            return data.copy()
        return {k: v if type(v) in _ATOMS else _copy(v) for k, v in data.items()}
    if t is list or t is tuple:
        if _ATOMS.issuperset(map(type, data)):
            return list(data)
        return [v if type(v) in _ATOMS else _copy(v) for v in data]
    if t in _ATOMS:
        return data
    if isinstance(data, Mapping):
        return {k: _copy(v) for k, v in data.items()}
    return copy.deepcopy(data)


def _vessels(vessels: list[Any], units: str) -> list[dict[str, Any]]:
    """The canonical vessels of a native ``vessels`` list (the core's full check)."""
    return _core.read_vessels(vessels, units)


def _boundary_conditions(bcs: Mapping[str, Any], units: str
                         ) -> tuple[dict[str, Any], list[tuple[float, str]]]:
    """Canonical boundary conditions and the periods of their waveforms (with the element)."""
    return _core.read_conditions(bcs, units)


def _element_periods(vessels: list[dict[str, Any]]) -> list[tuple[float, str]]:
    """The cardiac periods of the canonical heart elements (a `chamber`'s activation, a
    `heart_pulmonary` block), with the element: each must equal the model period."""
    out: list[tuple[float, str]] = []
    for v in vessels:
        for kind in ("chamber", "heart_pulmonary"):
            spec = v.get(kind)
            if isinstance(spec, dict) and "period" in spec:
                out.append((spec["period"], f"vessel '{v['name']}' {kind} (its activation)"))
    return out


@dataclass
class Model:
    """A validated network model in SI units.

    ``canonical`` is the JSON-able description passed to the Rust core; ``simulation`` holds
    the run settings from the file (overridable in :func:`oxyline.simulate`).

    Once the core has assembled the model, its per-vessel canonical dicts are released (a
    whole tree's canonical vessels and outlets took ~185 B per segment beside the core's
    own tables; the scale targets) and written again from ``source`` on first use
    (:meth:`release_canonical`); a run reads only the small transport section
    (:attr:`transport_spec`) and the vessel names.

    >>> import oxyline
    >>> m = oxyline.load_model("bifurcation")
    >>> m.name, m.vessel_names, m.period
    ('bifurcation', ['parent', 'daughter1', 'daughter2'], 1.0)
    """

    name: str
    canonical: dict[str, Any]
    simulation: dict[str, Any] = field(default_factory=dict)
    period: float | None = None
    source: dict[str, Any] = field(default_factory=dict)
    #: species transport facts for results: ``species`` (names), ``oxygen`` (name of the O2
    #: species or None), ``solubility`` (O2, mol m^-3 mmHg^-1)
    transport: dict[str, Any] = field(default_factory=dict)
    #: the vessels output when the run selects none (None: all; structured-tree vessels are
    #: left out, see :mod:`oxyline.structured_tree`)
    default_output_vessels: list[str] | None = None
    _network: Any = field(default=None, repr=False, compare=False)
    #: the native dict ``canonical`` is written from again once released (None: kept)
    _rebuild: Any = field(default=None, repr=False, compare=False)
    #: the vessel names and the transport section of a released ``canonical``
    _kept: Any = field(default=None, repr=False, compare=False)

    def release_canonical(self, names: list[str] | None = None) -> None:
        """Drop ``canonical`` (the core holds the model); it is written again from the
        native dict it came from when next asked for, identical (the same conversion).
        ``names``: the vessel names, when ``canonical`` was written without its vessels."""
        canon = self.__dict__.get("_canonical")
        if canon is None or not self.source:  # nothing to write it again from
            return
        if names is None:
            names = [v["name"] for v in canon["vessels"]]
        self._kept = (names, canon.get("transport"))
        self._rebuild = self.source
        self.__dict__["_canonical"] = None

    @property
    def transport_spec(self) -> dict[str, Any] | None:
        """The canonical transport section (None without species), without writing a
        released ``canonical`` again."""
        if self.__dict__.get("_canonical") is None and self._kept is not None:
            return self._kept[1]
        return self.canonical.get("transport")

    @property
    def network(self) -> _core.Network:
        """The assembled Rust network (built on first use)."""
        if self._network is None:
            self._network = _network(self.canonical, self.simulation.get("max_memory"))
        return self._network

    @property
    def vessel_names(self) -> list[str]:
        if self.__dict__.get("_canonical") is None and self._kept is not None:
            return list(self._kept[0])
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
        return copy.deepcopy(self.source)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_network"] = None
        return state


def _get_canonical(self: Model) -> dict[str, Any]:
    canon = self.__dict__.get("_canonical")
    if canon is None and self._rebuild is not None:

        canon = _unassembled(expanded(self._rebuild)).canonical
        self.__dict__["_canonical"] = canon
    return canon


def _set_canonical(self: Model, value: dict[str, Any]) -> None:
    self.__dict__["_canonical"] = value
    self._rebuild = self._kept = None


# a property over the dataclass field: the generated __init__, __eq__ and __repr__ go
# through it, so a released description is written again when they need it
Model.canonical = property(_get_canonical, _set_canonical)  # type: ignore[assignment]


def _plain_outlet(bc: Any) -> bool:
    """A canonical resistance or RCR condition with a constant (or no) pressure: the core
    reads it from the dict itself."""
    if type(bc) is not dict or bc.get("type") not in ("rcr", "resistance"):
        return False
    p = bc.get("pressure")
    return p is None or (type(p) is dict and p.get("kind") == "constant")


def _network(canonical: dict[str, Any], max_memory: Any = None,
             parts: Any = None) -> _core.Network:
    """The core network of a canonical model. The vessels and the plain outlets (the bulk of a
    large tree) are handed over as the dicts themselves, read key by key by the binding; the
    rest as JSON text. Writing the whole model as text cost ~2 µs per segment (the repr of
    every float, then the parse). The core refuses a model whose memory estimate exceeds
    ``max_memory`` (see :mod:`oxyline.memory`) before it allocates for it. ``parts``: the
    vessels and outlets :class:`_NativeReader` read from the native dict (not in
    ``canonical``)."""
    bcs = canonical.get("boundary_conditions")
    outlets, other = {}, {}
    if isinstance(bcs, dict):
        for node, bc in bcs.items():
            (outlets if _plain_outlet(bc) and type(node) is str else other)[node] = bc
    else:
        other = bcs
    rest = {k: v for k, v in canonical.items() if k not in ("vessels", "boundary_conditions")}
    rest["vessels"], rest["boundary_conditions"] = [], other
    rest["max_memory"] = _memory.limit(max_memory, "simulation: max_memory")
    vessels = canonical.get("vessels")
    if type(vessels) is not list:  # not a canonical model: the JSON parse reports it
        rest["vessels"], vessels = vessels, None
    # compact separators: the text is the core's input only (5 % less to write)
    from oxyline.errors import core_errors

    with core_errors(f"model '{canonical.get('name', '?')}'"):
        return _core.Network(json.dumps(rest, separators=(",", ":")), vessels, outlets, parts)


class _NativeReader:
    """The vessels and outlets of a native model dict read by the core's binding
    (``_core.NativeParts``) instead of through a canonical dict per element: the plain
    geometric vessels and resistance/RCR outlets (the bulk of a large tree) by its fast
    reader, every other element by the core's full schema check. Used as ``_unassembled``'s
    converters: the canonical description it gives has only the outlets the fast reader left;
    ``parts`` holds all the vessels and the plain outlets for :func:`_network`."""

    def __init__(self) -> None:
        self.parts: Any = None
        #: the periods of the heart elements among the vessels, with the element
        self.periods: list[tuple[float, str]] = []

    def vessels(self, vessels: list[Any], units: str) -> list[dict[str, Any]]:
        self.parts = _core.NativeParts(vessels, units)
        self.periods = self.parts.read_rest(vessels, units)
        return []

    def boundary_conditions(self, bcs: Mapping[str, Any], units: str
                            ) -> tuple[dict[str, Any], list[tuple[float, str]]]:
        if type(bcs) is not dict:
            return _boundary_conditions(bcs, units)
        slow = self.parts.read_outlets(bcs, units)
        return _boundary_conditions({node: bcs[node] for node in slow}, units)


def build_model(data: dict[str, Any]) -> Model:
    """Validate a native model dict (the README schema) and assemble it."""
    return _build(_copy(dict(data)))


def _build(data: dict[str, Any]) -> Model:
    """The model of ``data``, which becomes the model's ``source``: callers pass a dict they
    own (a copy of the user's, or one they built)."""
    if has_trees(data):  # a model-to-model step, like an importer
        # the trees' vessels are estimated against the memory allowed before they are grown
        return build_with_trees(data, _build_native, _boundary_conditions,
                                _memory.default_limit())
    return _build_native(data)


def _build_native(data: dict[str, Any], grow: Callable[[Any], Any] | None = None) -> Model:
    """:func:`_build` of a model without structured-tree conditions; ``grow`` adds the
    structured trees to the parts the core reads (:func:`oxyline.structured_tree.build_with_trees`)."""
    # the bulk of the vessels and outlets goes to the core without canonical dicts; the
    # canonical description is written in full from ``source`` when asked for
    reader = _NativeReader()
    model = _unassembled(data, reader.vessels, reader.boundary_conditions)
    if grow is not None:
        grow(reader.parts)
    names = reader.parts.names()
    # assemble now so that invalid models fail at load time
    model._network = _network(model.canonical, model.simulation.get("max_memory"), reader.parts)
    warn_implausible(model._network.plausibility())
    sim = model.simulation
    out = sim.get("output") or {}
    if "variables" in out or "vessels" in out:  # unknown names fail at load time too
        model.network.output_layout(variables=output_names(out.get("variables"), "variables"),
                                    vessels=output_vessels(out.get("vessels", "all")))
    model.release_canonical(names)
    return model


def _unassembled(data: dict[str, Any], convert_vessels: Callable[..., Any] | None = None,
                 convert_boundary_conditions: Callable[..., Any] | None = None) -> Model:
    """The model of ``data`` with its canonical description, not yet assembled.
    ``convert_vessels`` and ``convert_boundary_conditions`` stand in for :func:`_vessels` and
    :func:`_boundary_conditions` (an ensemble reuses the base model's canonical elements that
    a variant leaves as they are)."""
    name, canon = _core.read_header(data)
    units = str(data.get("units", "SI"))
    vessels = data["vessels"]
    canon["vessels"] = (convert_vessels or _vessels)(vessels, units)
    canon["boundary_conditions"], periods = (convert_boundary_conditions
                                             or _boundary_conditions)(
        data.get("boundary_conditions", {}), units)
    # the native reader's canonical vessel list is empty: it found the heart elements' periods
    known = getattr(getattr(convert_vessels, "__self__", None), "periods", [])
    period = _core.check_periods(data, periods + _element_periods(canon["vessels"]) + known)
    sim = data.get("simulation", {}) or {}
    _core.check_simulation(sim)
    from oxyline import transport as _transport

    cycles = sim.get("max_cycles", 100) if sim.get("until_periodic") else sim.get("cycles", 10)
    duration = (period or 1.0) * float(cycles) if isinstance(cycles, (int, float)) else None
    tr, tr_info = _transport.canonical(data, factor(units, "pressure"), period, duration)
    if tr is not None:
        _transport.add_blood(tr, canon["blood"])
        canon["transport"] = tr
    # ``data`` is the caller's private copy (load_model, build_model) and is only read here
    return Model(name=name, canonical=canon, simulation=dict(sim), period=period, source=data,
                 transport=tr_info)
