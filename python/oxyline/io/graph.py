"""networkx graphs: nodes are network nodes, edges are vessels (edge attributes = vessel keys).

``to_networkx`` returns a :class:`networkx.DiGraph` (a :class:`networkx.MultiDiGraph` keyed by
vessel name when two vessels join the same pair of nodes); node attribute
``boundary_condition`` holds each boundary condition, ``G.graph`` the other top-level model
keys and ``G.graph["vessel_order"]`` the vessel order, so ``from_networkx(to_networkx(m))`` is
``m`` again. networkx is an optional dependency
(``pip install oxyline[graph]``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from oxyline.errors import ModelError
from oxyline.io._common import (
    ALIASES,
    LUMPED_COLUMNS,
    VESSEL_COLUMNS,
    build,
    is_missing,
    model_source,
    plain,
)
from oxyline.model import Model


def _nx() -> Any:
    try:
        import networkx as nx
    except ImportError:
        raise ImportError("networkx is needed for graph import/export: "
                          "pip install 'oxyline[graph]' (or networkx>=3)") from None
    return nx


def to_networkx(model: Model) -> Any:
    """The model as a directed networkx graph (see the module docstring).

    >>> import oxyline, oxyline.io
    >>> G = oxyline.io.to_networkx(oxyline.load_model("bifurcation"))
    >>> sorted(G.successors("J1")), G.edges["inlet", "J1"]["name"]
    (['eca_out', 'ica_out'], 'parent')
    """
    nx = _nx()
    src = model_source(model)
    pairs = [(str(v["from"]), str(v["to"])) for v in src["vessels"]]
    multi = len(set(pairs)) < len(pairs)
    G = nx.MultiDiGraph() if multi else nx.DiGraph()
    G.graph.update({k: v for k, v in src.items() if k not in ("vessels", "boundary_conditions")})
    G.graph["vessel_order"] = [str(v["name"]) for v in src["vessels"]]
    for v in src["vessels"]:
        attrs = {k: val for k, val in v.items() if k not in ("from", "to")}
        G.add_edge(str(v["from"]), str(v["to"]), **({"key": str(v["name"])} if multi else {}),
                   **attrs)
    for node, bc in (src.get("boundary_conditions") or {}).items():
        G.add_node(str(node), boundary_condition=bc)
    return G


def from_networkx(G: Any, boundary_conditions: Mapping[str, Any] | None = None,
                  ignore_unknown: bool = False, **model_keys: Any) -> Model:
    """Build a model from a networkx graph whose edges are vessels.

    Edge attributes are the vessel keys of the native format (``length``, ``radius`` or
    ``radius_in``/``radius_out``, ``wall_thickness``, ``youngs_modulus``, ``poisson_ratio``,
    ``segments``, ``lumped`` or the flat ``resistance``/``inductance``/``capacitance``/
    ``stenosis_coefficient``; aliases as in the tables). The vessel name is the ``name``
    attribute, else the multigraph key, else ``"u-v"``. A directed graph's edges run
    ``u → v``; for an undirected graph give ``from``/``to`` attributes or the insertion order is
    used. Boundary conditions come from node attributes ``boundary_condition`` and from
    ``boundary_conditions`` (which wins); top-level keys from ``G.graph`` and ``model_keys``
    (which wins). Unknown edge attributes are an error unless ``ignore_unknown``.

    >>> import networkx as nx, oxyline.io
    >>> G = nx.DiGraph()
    >>> G.add_edge("in", "out", name="A", length=0.1, radius=0.003)
    >>> m = oxyline.io.from_networkx(G, {"in": {"type": "flow", "value": 1e-6},
    ...                                  "out": {"type": "pressure", "value": 0.0}})
    >>> m.vessel_names
    ['A']
    """
    known = set(VESSEL_COLUMNS) | {"lumped"}
    vessels = []
    edges = G.edges(keys=True, data=True) if G.is_multigraph() \
        else ((u, v, None, d) for u, v, d in G.edges(data=True))
    for u, v, key, d in edges:
        name = d.get("name", key if key is not None and not isinstance(key, int) else f"{u}-{v}")
        el = f"graph edge ({u!r}, {v!r}) (vessel '{name}')"
        vessel: dict[str, Any] = {"name": str(name), "from": str(d.get("from", u)),
                                  "to": str(d.get("to", v))}
        lumped: dict[str, Any] = dict(d.get("lumped") or {})
        for attr, val in d.items():
            k = ALIASES.get(str(attr).lower(), ALIASES.get(str(attr), str(attr)))
            if k in ("name", "from", "to", "lumped") or is_missing(val):
                continue
            if k in LUMPED_COLUMNS:
                lumped[k] = val
            elif k in known:
                vessel[k] = val
            elif not ignore_unknown:
                raise ModelError(f"{el}: unknown attribute '{attr}' (known: "
                                 f"{', '.join(sorted(known | set(LUMPED_COLUMNS)))}; pass "
                                 "ignore_unknown=True to skip it)")
        if lumped:
            vessel["lumped"] = lumped
        vessels.append(vessel)
    if not vessels:
        raise ModelError("graph: no edges (each edge is a vessel)")
    order = {n: i for i, n in enumerate(G.graph.get("vessel_order") or [])}
    if order:  # the model's vessel order (edge iteration follows node order instead)
        vessels.sort(key=lambda v: order.get(v["name"], len(order)))
    bcs: dict[str, Any] = {}
    for node, nd in G.nodes(data=True):
        if nd.get("boundary_condition") is not None:
            bcs[str(node)] = nd["boundary_condition"]
    bcs.update({str(k): v for k, v in (boundary_conditions or {}).items()})
    data = {k: v for k, v in G.graph.items() if k != "vessel_order"}
    data.update(model_keys)
    data["vessels"] = plain(vessels)
    data["boundary_conditions"] = plain(bcs)
    return build(data, "graph")
