"""Structured-tree outlets (Olufsen 1999, Ann Biomed Eng 27; Olufsen et al. 2000): below an
outlet, an asymmetric binary tree of small arteries down to a minimum radius, expanded on load
into ordinary native vessels. See docs/structured-tree.md.

Growth rule: the tree's root is the outlet node. A node whose radius is r has daughters of radius
``alpha·r`` (path letter ``a``) and ``beta·r`` (``b``), the root having ``root_radius``. A
daughter exists only if its radius is >= ``min_radius``; a tree vessel without daughters ends at
the ``terminal`` condition. A vessel of radius r has length ``length_ratio·r`` and is named
``<node>/st/<path>``; its distal node has the same name. Only geometry and wall data are
written here: the core computes every segment's R, L and C from them.

The translation is a model-to-model step like an importer: :func:`expand` rewrites a native
model dict, and :func:`oxyline.model._build` calls it when a boundary condition has
``type: structured-tree``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from oxyline.errors import ModelError
from oxyline.units import factor

TYPE = "structured-tree"
KEYS = {"type", "alpha", "beta", "length_ratio", "min_radius", "root_radius", "stiffness",
        "terminal", "segments", "max_length", "max_vessels"}
#: Olufsen et al. (2000) Eh/r = k1 exp(k2 r) + k3, converted to SI (Pa, 1/m, Pa)
OLUFSEN_STIFFNESS = {"k1": 2.0e6, "k2": -2253.0, "k3": 8.65e4}
#: wall thickness / radius written with the {k1, k2, k3} law, whose value fixes only E·h/r
#: (all the thin-wall compliance depends on)
K_LAW_THICKNESS_RATIO = 0.1
MAX_VESSELS = 2_000_000


def _err(node: str, message: str) -> ModelError:
    return ModelError(f"boundary condition '{node}' ({TYPE}): {message}")


def _num(node: str, key: str, value: Any, lo: float = 0.0, hi: float = math.inf,
         lo_open: bool = True, hi_open: bool = True) -> float:
    """A finite number in (lo, hi) (closed ends where asked), named by its key."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _err(node, f"'{key}' must be a finite number, got {value!r}")
    v = float(value)
    if (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi):
        lb, rb = "(" if lo_open else "[", ")" if hi_open else "]"
        raise _err(node, f"'{key}' must be in {lb}{lo:g}, {hi:g}{rb}, got {v:g}")
    return v


def _wall(node: str, stiffness: Any, L: float, E: float) -> Callable[[float], tuple[float, float]]:
    """(youngs_modulus, wall_thickness) of a tree vessel of radius r (SI) from ``stiffness``."""
    s = OLUFSEN_STIFFNESS if stiffness is None else stiffness
    if not isinstance(s, Mapping):
        raise _err(node, f"'stiffness' must be a mapping, got {stiffness!r}")
    keys = set(s)
    if keys == {"k1", "k2", "k3"}:
        given = stiffness is not None
        k1 = E * _num(node, "stiffness.k1", s["k1"], -math.inf) if given else s["k1"]
        k2 = _num(node, "stiffness.k2", s["k2"], -math.inf) / L if given else s["k2"]
        k3 = E * _num(node, "stiffness.k3", s["k3"], -math.inf) if given else s["k3"]

        def k_law(r: float) -> tuple[float, float]:
            ehr = k1 * math.exp(k2 * r) + k3
            if not ehr > 0:
                raise _err(node, f"stiffness gives E·h/r = {ehr:g} Pa <= 0 at radius {r:g} m")
            return ehr / K_LAW_THICKNESS_RATIO, K_LAW_THICKNESS_RATIO * r

        return k_law
    if keys == {"youngs_modulus", "thickness_ratio"}:
        e = E * _num(node, "stiffness.youngs_modulus", s["youngs_modulus"])
        ratio = _num(node, "stiffness.thickness_ratio", s["thickness_ratio"])
        return lambda r: (e, ratio * r)
    raise _err(node, f"'stiffness' needs {{k1, k2, k3}} or {{youngs_modulus, thickness_ratio}}, "
                     f"got keys {sorted(keys)}")


def tree_size(alpha: float, beta: float, root_radius: float, min_radius: float) -> int:
    """Number of tree vessels, counted without growing the tree: radii only shrink along a
    path, so a vessel exists iff its own radius alpha^i beta^j r0 >= min_radius, and there are
    C(i + j, i) paths with i a's and j b's."""
    n, i = 0, 0
    while alpha**i * root_radius >= min_radius:
        j = 0
        while alpha**i * beta**j * root_radius >= min_radius:
            if i + j > 0:
                n += math.comb(i + j, i)
            j += 1
        i += 1
    return n


def structured_tree(node: str, *, root_radius: float, alpha: float = 0.9, beta: float = 0.6,
                    length_ratio: float = 50.0, min_radius: float = 1.0e-4,
                    stiffness: Mapping[str, float] | None = None, segments: int | None = None,
                    max_length: float | None = None, max_vessels: int = MAX_VESSELS,
                    units: str = "SI") -> list[dict[str, Any]]:
    """The native vessels of the structured tree below outlet ``node`` (parents before
    daughters). Leaves end at nodes ``<node>/st/<path>`` that no vessel leaves: give them a
    boundary condition (the ``structured-tree`` condition applies its ``terminal`` one).

    Lengths and moduli are in ``units`` (``stiffness`` k1, k3 as moduli, k2 per length);
    ``stiffness`` defaults to Olufsen et al. (2000), E·h/r = 2e6 e^(-2253 r) + 8.65e4 Pa.

    >>> import oxyline
    >>> vs = oxyline.structured_tree("out", root_radius=1e-3, min_radius=5.5e-4)
    >>> [v["name"] for v in vs]
    ['out/st/a', 'out/st/aa', 'out/st/aaa', 'out/st/aaaa', 'out/st/aaaaa', 'out/st/b']
    """
    L, E = factor(units, "length"), factor(units, "modulus")
    a = _num(node, "alpha", alpha, 0.0, 1.0)
    b = _num(node, "beta", beta, 0.0, 1.0)
    lrr = _num(node, "length_ratio", length_ratio)
    rmin = L * _num(node, "min_radius", min_radius)
    r0 = L * _num(node, "root_radius", root_radius)
    if isinstance(max_vessels, bool) or not isinstance(max_vessels, (int, float)) \
            or not max_vessels >= 1:
        raise _err(node, f"'max_vessels' must be a number >= 1, got {max_vessels!r}")
    if segments is not None and max_length is not None:
        raise _err(node, "give 'segments' or 'max_length', not both")
    if segments is not None and (isinstance(segments, bool) or not isinstance(segments, int)
                                 or segments < 1):
        raise _err(node, f"'segments' must be an integer >= 1, got {segments!r}")
    dx = None if max_length is None else L * _num(node, "max_length", max_length)
    wall = _wall(node, stiffness, L, E)
    n = tree_size(a, b, r0, rmin)
    if n > max_vessels:
        raise _err(node, f"the tree has {n} vessels, more than max_vessels = {max_vessels:g} "
                         f"(raise min_radius = {rmin:g} m or max_vessels)")
    if n == 0:
        raise _err(node, f"no daughter reaches min_radius = {rmin:g} m (root radius {r0:g} m, "
                         f"alpha = {a:g})")
    return _grow(node, a, b, lrr, rmin, r0, wall, segments, dx, L, E)


def _grow(node: str, a: float, b: float, lrr: float, rmin: float, r0: float,
          wall: Callable[[float], tuple[float, float]], segments: int | None, dx: float | None,
          L: float, E: float) -> list[dict[str, Any]]:
    """Depth-first growth (SI inside, vessels written in the caller's units)."""
    prefix = f"{node}/st/"
    out: list[dict[str, Any]] = []
    stack = [("b", b * r0), ("a", a * r0)]  # popped a first: a-subtree before b
    while stack:
        path, r = stack.pop()
        if r < rmin:
            continue
        length = lrr * r
        e, h = wall(r)
        v: dict[str, Any] = {"name": prefix + path,
                             "from": node if len(path) == 1 else prefix + path[:-1],
                             "to": prefix + path, "length": length / L, "radius": r / L,
                             "wall_thickness": h / L, "youngs_modulus": e / E}
        if segments is not None:
            v["segments"] = segments
        elif dx is not None:
            v["segments"] = max(1, math.ceil(length / dx - 1e-9))
        out.append(v)
        stack.append((path + "b", b * r))
        stack.append((path + "a", a * r))
    return out


def _root_radius(data: Mapping[str, Any], node: str) -> float:
    """The radius of the vessel end at outlet ``node`` (model units)."""
    for v in data.get("vessels") or []:
        if not isinstance(v, Mapping):
            continue
        for end, keys in (("to", ("radius_out", "radius")), ("from", ("radius_in", "radius"))):
            if v.get(end) == node:
                for k in keys:
                    if k in v:
                        return v[k]
                raise _err(node, f"vessel '{v.get('name')}' at this node has no radius: give "
                                 f"'root_radius'")
    raise _err(node, "no vessel ends at this node")


def has_trees(data: Mapping[str, Any]) -> bool:
    bcs = data.get("boundary_conditions")
    return isinstance(bcs, Mapping) and any(
        isinstance(bc, Mapping) and bc.get("type") == TYPE for bc in bcs.values())


def expand(data: Mapping[str, Any]) -> tuple[dict[str, Any], set[str]]:
    """``data`` with every structured-tree condition replaced by its vessels and terminal
    conditions, and the names of the tree vessels."""
    units = str(data.get("units", "SI"))
    vessels = list(data.get("vessels") or [])
    bcs: dict[str, Any] = {}
    tree: set[str] = set()
    for node, bc in data["boundary_conditions"].items():
        if not (isinstance(bc, Mapping) and bc.get("type") == TYPE):
            bcs[node] = bc
            continue
        node = str(node)
        unknown = set(bc) - KEYS
        if unknown:
            raise _err(node, f"unknown key '{min(unknown)}' (allowed: "
                             f"{', '.join(sorted(KEYS))})")
        kw = {k: bc[k] for k in KEYS - {"type", "terminal", "root_radius"} if k in bc}
        root = bc["root_radius"] if "root_radius" in bc else _root_radius(data, node)
        grown = structured_tree(node, root_radius=root, units=units, **kw)
        terminal = bc.get("terminal", {"type": "pressure", "value": 0.0})
        if not isinstance(terminal, Mapping) or terminal.get("type") == TYPE:
            raise _err(node, f"'terminal' must be an outlet condition, got {terminal!r}")
        sources = {v["from"] for v in grown}
        tree.update([v["name"] for v in grown])
        for to in [v["to"] for v in grown]:
            if to not in sources:
                bcs[to] = dict(terminal)
        vessels.extend(grown)
    out = dict(data)
    out["vessels"], out["boundary_conditions"] = vessels, bcs
    return out, tree


def build_with_trees(data: dict[str, Any], build_native: Callable[[dict[str, Any]], Any]) -> Any:
    """The model of ``data`` (which has structured-tree conditions): expanded, built by
    ``build_native``, with ``data`` kept as its source and tree vessels out of the default
    output selection."""
    expanded, tree = expand(data)
    model = build_native(expanded)
    model.source = data
    # the model's own vessels come first in ``expanded`` (the tree vessels are appended), with
    # the names and output flags of their canonical form: reading ``model.canonical`` would
    # write its released description again (a second pass of the whole conversion)
    own = expanded["vessels"][:len(data.get("vessels") or [])]
    names = (str(v["name"]) for v in own if isinstance(v, Mapping) and v.get("output", True))
    model.default_output_vessels = [n for n in names if n not in tree]
    return model


__all__ = ["structured_tree", "tree_size"]


def _dc_resistance(r0: float, a: float, b: float, lrr: float, rmin: float, mu: float,
                   r_leaf: float) -> float:
    """Steady resistance below a node of radius r0 with every leaf ending at ``r_leaf``
    (Poiseuille, as the core's segment resistance of docs/physics.md §1.1). A subtree depends
    only on its root radius alpha^i beta^j r0, so it is computed once per (i, j)."""
    memo: dict[tuple[int, int], float] = {}

    def below(i: int, j: int) -> float:  # resistance from node (i, j) to the leaves
        if (i, j) not in memo:
            g = 0.0
            for di, dj in ((1, 0), (0, 1)):
                r = a ** (i + di) * b ** (j + dj) * r0
                if r >= rmin:
                    g += 1.0 / (8.0 * mu * lrr / (math.pi * r**3) + below(i + di, j + dj))
            memo[(i, j)] = r_leaf if g == 0.0 else 1.0 / g
        return memo[(i, j)]

    return below(0, 0)


def _tree_condition(node: str, r0: float, total: float, mu: float, min_radius: float,
                    tree_fraction: float, pressure: float,
                    tree: Mapping[str, Any]) -> dict[str, Any]:
    """The structured-tree condition at ``node`` (root radius ``r0``) whose steady resistance
    is ``total`` (SI): the tree grows to ``min_radius`` (at most alpha·r0), raised by factors
    of 1.05 until the tree alone (leaves at the outlet pressure) has at most ``tree_fraction``
    of ``total``, and every leaf ends at one terminal resistance that supplies the rest
    (bisection)."""
    a, b = tree.get("alpha", 0.9), tree.get("beta", 0.6)
    lrr = tree.get("length_ratio", 50.0)
    if not total > 0:
        raise _err(node, f"the resistance to match is {total:g} Pa s/m^3, not > 0")
    rmin = min(min_radius, a * r0)  # at least the a-daughter (binds only for coarse trees)
    while _dc_resistance(r0, a, b, lrr, rmin, mu, 0.0) > tree_fraction * total:
        rmin *= 1.05
        if rmin > a * r0:  # no tree vessel left: the root alone is above the fraction
            raise _err(node, f"no tree below root radius {r0:g} m has at most "
                             f"{tree_fraction:g} of the resistance {total:g} Pa s/m^3")
    lo, hi = 0.0, total * 2.0 ** 20
    for _ in range(200):  # R(leaf) is increasing: bisection to rounding
        mid = 0.5 * (lo + hi)
        if _dc_resistance(r0, a, b, lrr, rmin, mu, mid) < total:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-15 * hi:
            break
    return {"type": TYPE, **tree, "min_radius": rmin,
            "terminal": {"type": "resistance", "resistance": 0.5 * (lo + hi),
                         "pressure": pressure}}


def replace_windkessels(data: Mapping[str, Any], min_radius: float = 1.0e-4,
                        tree_fraction: float = 0.9, **tree: Any) -> dict[str, Any]:
    """``data`` (a native SI model) with every RCR outlet replaced by a structured tree of the
    same steady resistance R_p + R_d: the tree grows to ``min_radius``, raised per outlet (by
    factors of 1.05) until the tree alone has at most ``tree_fraction`` of that resistance,
    and every leaf ends at one terminal resistance that supplies the rest (solved by
    bisection). ``tree`` overrides the other structured-tree parameters."""
    mu = float((data.get("blood") or {}).get("viscosity", 3.5e-3))
    out = dict(data)
    bcs = dict(out["boundary_conditions"])
    for node, bc in bcs.items():
        if not (isinstance(bc, Mapping) and bc.get("type") == "rcr"):
            continue
        total = float(bc["proximal_resistance"]) + float(bc["distal_resistance"])
        bcs[node] = _tree_condition(str(node), float(_root_radius(data, node)), total, mu,
                                    min_radius, tree_fraction, bc.get("pressure", 0.0), tree)
    out["boundary_conditions"] = bcs
    return out


def _compartment(data: Mapping[str, Any], vessel: Mapping[str, Any]
                 ) -> tuple[set[str], set[str], float, float]:
    """The lumped terminal compartment that starts with ``vessel`` (every vessel downstream of
    it): its vessel names, its end nodes, its steady resistance to its pressure outlets and
    their pressure. Dead ends held at zero flow (wall branches) carry no steady flow."""
    name = str(vessel["name"])
    bcs = data["boundary_conditions"]
    leaving: dict[str, list[Mapping[str, Any]]] = {}
    for v in data["vessels"]:
        leaving.setdefault(v["from"], []).append(v)
    names: set[str] = set()
    nodes: set[str] = set()
    pressures: set[float] = set()

    def below(v: Mapping[str, Any]) -> float:  # steady resistance from v's inlet (inf: none)
        lumped = v.get("lumped")
        if not isinstance(lumped, Mapping) or v["name"] in names:
            raise _err(name, f"terminal compartment vessel '{v['name']}' is not a lumped "
                             f"element of a tree")
        names.add(str(v["name"]))
        end = v["to"]
        nodes.add(str(end))
        bc = bcs.get(end)
        if isinstance(bc, Mapping) and bc.get("type") == "flow" and bc.get("value") == 0.0:
            return math.inf
        if isinstance(bc, Mapping) and bc.get("type") == "pressure":
            pressures.add(float(bc.get("value", 0.0)))
            rest = 0.0
        elif bc is None and end in leaving:
            g = sum(1.0 / below(w) for w in leaving[end])
            rest = math.inf if g == 0.0 else 1.0 / g
        else:
            raise _err(name, f"terminal compartment node '{end}' has condition {bc!r} "
                             f"(only pressure outlets and zero-flow dead ends are replaced)")
        return float(lumped.get("resistance", 0.0)) + rest

    total = below(vessel)
    if len(pressures) != 1 or not math.isfinite(total):
        raise _err(name, f"terminal compartment has outlet pressures {sorted(pressures)}")
    return names, nodes, total, pressures.pop()


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
    overrides the other structured-tree parameters."""
    mu = float((data.get("blood") or {}).get("viscosity", 3.5e-3))
    lrr = float(tree.get("length_ratio", 50.0))
    vessels = {str(v["name"]): v for v in data["vessels"]}
    out = dict(data)
    bcs = dict(out["boundary_conditions"])
    drop: set[str] = set()
    roots: dict[str, dict[str, Any]] = {}
    for name, r0 in root_radii.items():
        if name not in vessels:
            raise _err(name, "no such terminal vessel")
        names, nodes, total, pressure = _compartment(data, vessels[name])
        drop |= names
        for node in nodes:
            bcs.pop(node, None)
        r0 = _num(name, "root radius", r0)
        e, h = _wall(name, tree.get("stiffness"), 1.0, 1.0)(r0)
        node = str(vessels[name]["to"])
        root = {"name": name, "from": vessels[name]["from"], "to": node,
                "length": lrr * r0, "radius": r0, "wall_thickness": h, "youngs_modulus": e,
                "description": f"structured-tree root vessel replacing the terminal "
                               f"compartment (steady resistance {total:.6e} Pa s/m^3)"}
        if "segments" in tree:  # the tree vessels' segmentation (see _grow)
            root["segments"] = tree["segments"]
        elif "max_length" in tree:
            root["segments"] = max(1, math.ceil(lrr * r0 / float(tree["max_length"]) - 1e-9))
        roots[name] = root
        r_root = 8.0 * mu * lrr / (math.pi * r0**3)  # Poiseuille, docs/physics.md §1.1
        bcs[node] = _tree_condition(node, r0, total - r_root, mu, min_radius, tree_fraction,
                                    pressure, tree)
    out["vessels"] = [roots.get(v["name"], v) for v in data["vessels"]
                      if v["name"] not in drop or v["name"] in roots]
    out["boundary_conditions"] = bcs
    return out


def murray_root_radii(data: Mapping[str, Any], steady: Mapping[str, Any],
                      terminals: list[str]) -> dict[str, float]:
    """Root radius of each terminal vessel by Murray's law (flow ∝ r³) from its share of the
    steady flow of the one vessel with a radius that ends where it starts (its parent):
    r0 = r_parent · (Q_terminal / Q_parent)^(1/3). ``steady`` is a steady state
    (``Network.steady_state()``: ``vessels`` and ``flow_in``)."""
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
        share = flow[name] / flow[parent["name"]]
        if not 0.0 < share <= 1.0:
            raise _err(name, f"steady flow share {share:g} of parent '{parent['name']}'")
        out[name] = float(parent.get("radius_out", parent.get("radius"))) * share ** (1.0 / 3.0)
    return out
