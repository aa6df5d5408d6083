"""Structured-tree outlets (Olufsen 1999, Ann Biomed Eng 27; Olufsen et al. 2000): below an
outlet, an asymmetric binary tree of small arteries down to a minimum radius. The core grows
it (``rust/oxyline-core/src/model/structured_tree.rs``: the growth rule, the closed-form
vessel count, the wall law, the steady resistance); this module orchestrates. See
docs/structured-tree.md.

Growth rule: the tree's root is the outlet node. A node whose radius is r has daughters of radius
``alpha·r`` (path letter ``a``) and ``beta·r`` (``b``), the root having ``root_radius``. A
daughter exists only if its radius is >= ``min_radius``; a tree vessel without daughters ends at
the ``terminal`` condition. A vessel of radius r has length ``length_ratio·r`` and is named
``<node>/st/<path>``; its distal node has the same name.

On load (:func:`build_with_trees`, which :func:`oxyline.model._build` calls when a boundary
condition has ``type: structured-tree``) the core reads each condition dict and grows its tree
straight into the model it assembles: no vessel dict is written. :func:`expand` writes the
expanded native model (for the canonical description and for editing).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from typing import Any, Literal

from oxyline import _core
from oxyline.errors import ModelError
from oxyline.units import factor

TYPE = "structured-tree"
MAX_VESSELS = 2_000_000


def _err(node: str, message: str) -> ModelError:
    return ModelError(f"boundary condition '{node}' ({TYPE}): {message}")


def structured_tree(node: str, *, root_radius: float, alpha: float = 0.9, beta: float = 0.6,
                    length_ratio: float = 50.0, min_radius: float = 1.0e-4,
                    stiffness: Mapping[str, float] | None = None,
                    segments: int | Literal["auto"] | None = None,
                    max_length: float | None = None, max_vessels: int = MAX_VESSELS,
                    units: str = "SI", memory_limit: float | None = None,
                    stopping: str = "min-radius", wall_friction: str | None = None
                    ) -> list[dict[str, Any]]:
    """The native vessels of the structured tree below outlet ``node`` (parents before
    daughters), grown by the core. Leaves end at nodes ``<node>/st/<path>`` that no vessel
    leaves: give them a boundary condition (the ``structured-tree`` condition applies its
    ``terminal`` one).

    Before any vessel is made the core bounds the vessel count in closed form, then counts
    it: a tree above ``max_vessels`` (at most 1e8) is a ModelError, and one whose estimated
    memory exceeds ``memory_limit`` (bytes; None: no limit) a ResourceError.

    Lengths and moduli are in ``units`` (``stiffness`` k1, k3 as moduli, k2 per length);
    ``stiffness`` defaults to Olufsen et al. (2000), E·h/r = 2e6 e^(-2253 r) + 8.65e4 Pa.
    ``stopping="olufsen"`` grows the tree as Olufsen's code (the first vessel at or below
    ``min_radius`` is a leaf); ``wall_friction`` ("poiseuille" or "womersley") is written on
    every vessel (docs/structured-tree.md).

    >>> import oxyline
    >>> vs = oxyline.structured_tree("out", root_radius=1e-3, min_radius=5.5e-4)
    >>> [v["name"] for v in vs]
    ['out/st/a', 'out/st/aa', 'out/st/aaa', 'out/st/aaaa', 'out/st/aaaaa', 'out/st/b']
    """
    condition = {"alpha": alpha, "beta": beta, "length_ratio": length_ratio,
                 "min_radius": min_radius, "stiffness": stiffness, "segments": segments,
                 "max_length": max_length, "max_vessels": max_vessels, "stopping": stopping}
    if wall_friction is not None:
        condition["wall_friction"] = wall_friction
    vessels, _ = _grow(node, condition, root_radius, units, memory_limit)
    return vessels


def _grow(node: str, condition: Mapping[str, Any], root_radius: Any, units: str,
          memory_limit: float | None = None) -> tuple[list[dict[str, Any]], list[str]]:
    """(vessel dicts in ``units``, leaf nodes) of the tree of ``condition`` at ``node``."""
    if not isinstance(condition, dict):
        condition = dict(condition)
    return _core.grow_structured_tree(node, condition, root_radius, factor(units, "length"),
                                      factor(units, "modulus"), memory_limit)


def _root_radius(data: Mapping[str, Any], node: str) -> float:
    """The radius of the vessel end at outlet ``node`` (model units; the core's lookup)."""
    return _core.outlet_root_radius(node, data.get("vessels"))


def has_trees(data: Mapping[str, Any]) -> bool:
    bcs = data.get("boundary_conditions")
    return isinstance(bcs, Mapping) and any(
        isinstance(bc, Mapping) and bc.get("type") == TYPE for bc in bcs.values())


def _terminal(node: str, bc: Mapping[str, Any]) -> Mapping[str, Any]:
    terminal = bc.get("terminal", {"type": "pressure", "value": 0.0})
    if not isinstance(terminal, Mapping) or terminal.get("type") == TYPE:
        raise _err(node, f"'terminal' must be an outlet condition, got {terminal!r}")
    return terminal


def _split(data: Mapping[str, Any]
           ) -> tuple[dict[str, Any], list[tuple[str, dict[str, Any], Any]]]:
    """(the other boundary conditions, the structured-tree conditions as (node, condition,
    root radius)) of ``data``, in the model's order."""
    rest: dict[str, Any] = {}
    trees: list[tuple[str, dict[str, Any], Any]] = []
    for node, bc in data["boundary_conditions"].items():
        if not (isinstance(bc, Mapping) and bc.get("type") == TYPE):
            rest[node] = bc
            continue
        node = str(node)
        root = bc["root_radius"] if "root_radius" in bc else _root_radius(data, node)
        trees.append((node, dict(bc), root))
    return rest, trees


def expand(data: Mapping[str, Any]) -> tuple[dict[str, Any], set[str]]:
    """``data`` with every structured-tree condition replaced by its vessels (dicts written
    by the core) and terminal conditions, and the names of the tree vessels."""
    units = str(data.get("units", "SI"))
    vessels = list(data.get("vessels") or [])
    bcs, trees = _split(data)
    tree: set[str] = set()
    for node, bc, root in trees:
        grown, leaves = _grow(node, bc, root, units)
        terminal = _terminal(node, bc)
        tree.update(v["name"] for v in grown)
        bcs.update((leaf, dict(terminal)) for leaf in leaves)
        vessels.extend(grown)
    return {**data, "vessels": vessels, "boundary_conditions": bcs}, tree


def expanded(data: dict[str, Any]) -> dict[str, Any]:
    """``data``, its structured trees expanded if it has any."""
    return expand(data)[0] if has_trees(data) else data


def build_with_trees(data: dict[str, Any], build_native: Callable[..., Any],
                     convert_conditions: Callable[..., Any],
                     memory_limit: float | None = None) -> Any:
    """The model of ``data`` (which has structured-tree conditions): the rest of the model
    read as usual, each tree grown by the core into the parts it assembles (after the
    model's own vessels, each leaf with its copy of the terminal condition), ``data`` kept
    as its source and tree vessels out of the default output selection. The trees'
    estimated memory is checked against ``memory_limit`` (bytes) before they are grown.
    ``convert_conditions(conditions, units)`` is the model's reader of boundary conditions
    (passed in: this module is below :mod:`oxyline.model`, not beside it)."""
    units = str(data.get("units", "SI"))
    rest, trees = _split(data)
    # checked and grown first (their errors before the other elements'), moved in on assembly
    grown = _core.StructuredTrees(trees, factor(units, "length"), factor(units, "modulus"),
                                  memory_limit, len(data.get("vessels") or []))
    # each terminal condition converted once (any outlet condition), copied per leaf
    terminals = [json.dumps(convert_conditions({node: _terminal(node, bc)}, units)[0][node])
                 for node, bc, _ in trees]
    model = build_native({**data, "boundary_conditions": rest},
                         lambda parts: grown.move_into(parts, terminals))
    model.source = data  # ``canonical`` is written from it, trees grown, when asked for
    own = (v for v in data.get("vessels") or [] if isinstance(v, Mapping))
    model.default_output_vessels = [str(v["name"]) for v in own if v.get("output", True)]
    return model


__all__ = ["structured_tree"]


def _shape(tree: Mapping[str, Any]) -> tuple[float, float, float]:
    """(alpha, beta, length_ratio) of the structured-tree parameters ``tree``."""
    return tree.get("alpha", 0.9), tree.get("beta", 0.6), tree.get("length_ratio", 50.0)


def _tree_condition(matched: tuple[float, float], pressure: Any,
                    tree: Mapping[str, Any]) -> dict[str, Any]:
    """The structured-tree condition of ``matched`` = (min_radius, the leaves' terminal
    resistance), as the core matched them to a steady resistance (``Shape::matched``:
    min_radius raised by factors of 1.05 until the tree alone has at most ``tree_fraction``
    of it, the terminal resistance by bisection)."""
    rmin, leaf = matched
    return {"type": TYPE, **tree, "min_radius": rmin,
            "terminal": {"type": "resistance", "resistance": leaf, "pressure": pressure}}


def replace_windkessels(data: Mapping[str, Any], min_radius: float = 1.0e-4,
                        tree_fraction: float = 0.9, **tree: Any) -> dict[str, Any]:
    """``data`` (a native SI model) with every RCR outlet replaced by a structured tree of the
    same steady resistance R_p + R_d: the tree grows to ``min_radius``, raised per outlet (by
    factors of 1.05) until the tree alone has at most ``tree_fraction`` of that resistance,
    and every leaf ends at one terminal resistance that supplies the rest (solved by
    bisection; the core's ``model/structured_tree/windkessel.rs``). ``tree`` overrides the
    other structured-tree parameters."""
    mu = float((data.get("blood") or {}).get("viscosity", 3.5e-3))
    bcs = dict(data["boundary_conditions"])
    for node, bc in bcs.items():
        if not (isinstance(bc, Mapping) and bc.get("type") == "rcr"):
            continue
        matched = _core.windkessel_tree_match(
            str(node), bc, _root_radius(data, str(node)), mu, min_radius, tree_fraction,
            *_shape(tree))
        bcs[node] = _tree_condition(matched, bc.get("pressure", 0.0), tree)
    return {**data, "boundary_conditions": bcs}


def replace_terminal_vessels(data: Mapping[str, Any], root_radii: Mapping[str, float],
                             min_radius: float = 1.0e-4, tree_fraction: float = 0.9,
                             **tree: Any) -> dict[str, Any]:
    """``data`` (a native SI model) with each lumped terminal compartment (a lumped vessel
    named in ``root_radii`` and every vessel downstream of it, ending at a pressure outlet,
    e.g. an R-C-R made of lumped vessels with a dead-end wall branch) replaced by a structured
    tree of the same steady resistance. The tree's root vessel keeps the terminal vessel's
    name and nodes, with radius ``root_radii[name]`` (m) and length ``length_ratio`` times
    it (Olufsen's root vessel); below its end node the tree follows the rule of
    :func:`replace_windkessels` for the resistance the root vessel leaves. ``tree``
    overrides the other structured-tree parameters. The compartment's steady resistance and
    the root vessel are the core's (``model/structured_tree/terminal.rs``)."""
    mu = float((data.get("blood") or {}).get("viscosity", 3.5e-3))
    vessels = {str(v["name"]): v for v in data["vessels"]}
    bcs = dict(data["boundary_conditions"])
    drop: set[str] = set()
    roots: dict[str, dict[str, Any]] = {}
    for name, r0 in root_radii.items():
        names, nodes, total, pressure = _core.terminal_compartment(
            name, list(data["vessels"]), dict(data["boundary_conditions"]))
        drop.update(names)
        for node in nodes:
            bcs.pop(node, None)
        length, e, h, segments, r_root = _core.structured_tree_root(
            name, r0, float(tree.get("length_ratio", 50.0)), tree.get("stiffness"),
            tree.get("max_length"), mu)
        node = str(vessels[name]["to"])
        root = {"name": name, "from": vessels[name]["from"], "to": node, "length": length,
                "radius": r0, "wall_thickness": h, "youngs_modulus": e,
                "description": f"structured-tree root vessel replacing the terminal "
                               f"compartment (steady resistance {total:.6e} Pa s/m^3)"}
        if "segments" in tree or segments is not None:  # the tree vessels' segmentation
            root["segments"] = tree.get("segments", segments)
        roots[name] = root
        # below the root vessel: the resistance it leaves
        matched = _core.match_structured_tree(node, r0, total - r_root, mu, min_radius,
                                              tree_fraction, *_shape(tree))
        bcs[node] = _tree_condition(matched, pressure, tree)
    return {**data, "vessels": [roots.get(v["name"], v) for v in data["vessels"]
                                if v["name"] not in drop or v["name"] in roots],
            "boundary_conditions": bcs}


def murray_root_radii(data: Mapping[str, Any], steady: Mapping[str, Any],
                      terminals: list[str]) -> dict[str, float]:
    """Root radius of each terminal vessel by Murray's law (the core's ``murray_radius``)
    from its share of the steady flow of the one vessel with a radius that ends where it
    starts (its parent). ``steady`` is a steady state (``Network.steady_state()``:
    ``vessels`` and ``flow_in``)."""
    flow = dict(zip(steady["vessels"], steady["flow_in"]))
    vessels = {str(v["name"]): v for v in data["vessels"]}
    out: dict[str, float] = {}
    for name in terminals:
        start = vessels[name]["from"]
        parents = [v for v in data["vessels"] if v["to"] == start
                   and ("radius" in v or "radius_out" in v)]
        if len(parents) != 1:
            raise _err(name, f"{len(parents)} vessels with a radius end at '{start}' (need one)")
        parent = parents[0]
        out[name] = _core.murray_radius(name, str(parent["name"]),
                                        float(parent.get("radius_out", parent.get("radius"))),
                                        float(flow[name]), float(flow[parent["name"]]))
    return out
