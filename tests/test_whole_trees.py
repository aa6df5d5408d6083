"""Built-in whole trees: ``whole-body-140-st``, whole-body-140 with each
lumped terminal compartment replaced by a structured tree of the same steady resistance
(docs/structured-tree.md). The independent truths: the steady resistance of each grown tree
summed vessel by vessel (Poiseuille, series and parallel) against the source's R_T, and the
exact steady pressures of the Windkessel version."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

import oxyline
from oxyline import catalogue
from oxyline.structured_tree import (
    expand,
    murray_root_radii,
    replace_terminal_vessels,
)

# the whole trees' recipes (the built-in files are their output)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benches"))
import make_models_data

N_TERMINALS = 95  # whole-body-140's terminal R-C-R compartments (names ending in _T)


@pytest.fixture(scope="module")
def base() -> dict:
    return catalogue.load_dict("whole-body-140")


@pytest.fixture(scope="module")
def st() -> dict:
    return catalogue.load_dict("whole-body-140-st")


def grown_resistance(vessels: list[dict], bcs: dict, node: str, mu: float) -> float:
    """Steady resistance below ``node``, vessel by vessel: each vessel 8 mu l / (pi r^4)
    from its own length and radius, in series with what is below its end, in parallel over
    the vessels leaving a node; a leaf adds its terminal resistance."""
    leaving: dict[str, list[dict]] = {}
    for v in vessels:
        leaving.setdefault(v["from"], []).append(v)
    below: dict[str, float] = {}
    order = [node]  # parents before daughters, then summed in reverse (no recursion depth)
    for n in order:
        order.extend(v["to"] for v in leaving.get(n, []))
    for n in reversed(order):
        if n not in leaving:
            below[n] = bcs[n]["resistance"]
            continue
        g = sum(1.0 / (8.0 * mu * v["length"] / (math.pi * v["radius"] ** 4) + below[v["to"]])
                for v in leaving[n])
        below[n] = 1.0 / g
    return below[node]


def test_whole_body_140_st_structure_and_steady_resistance(base, st) -> None:
    """95 trees, one per terminal compartment; the named arteries keep their names and the
    compliance of their wall branches (folded back into them); each tree's steady resistance
    (root vessel included) equals the source's R_T."""
    trees = {n: bc for n, bc in st["boundary_conditions"].items()
             if bc.get("type") == "structured-tree"}
    assert len(trees) == N_TERMINALS
    assert set(st["boundary_conditions"]) == set(trees) | {"aortic_inlet"}
    names = {v["name"] for v in st["vessels"]}
    base_names = {v["name"] for v in base["vessels"]}
    walls = {v["name"]: v["lumped"]["capacitance"] for v in base["vessels"]
             if ".wall" in v["name"]}
    terminal_walls = {f"{n}.wall" for n in trees}
    halves = {n for n in base_names if n.endswith(".distal_half")}
    # gone: every wall branch, the terminals' distal halves and the second halves of the
    # source's T modules (merged with their first halves)
    assert names == base_names - set(walls) - halves
    # the named arteries hold the compliance of their wall branches: 2 pi r^3 l / (E h)
    # with Poisson ratio 0, summed against the branches' capacitances
    c = sum(2 * math.pi * v["radius"] ** 3 * v["length"] / (v["youngs_modulus"]
            * v["wall_thickness"]) for v in st["vessels"] if "youngs_modulus" in v
            and v["to"] not in trees)
    c_walls = sum(cap for n, cap in walls.items() if n not in terminal_walls)
    assert abs(c / c_walls - 1.0) < 1e-12  # sums of the same terms in another order

    expanded, tree_vessels = expand(st)
    mu = base["blood"]["viscosity"]
    by_name = {v["name"]: v for v in base["vessels"]}
    roots = {v["to"]: v for v in expanded["vessels"] if v["to"] in trees}
    grown: dict[str, list[dict]] = {}
    for v in expanded["vessels"]:
        if "/st/" in v["name"]:
            grown.setdefault(v["name"].split("/st/")[0], []).append(v)
    for node in trees:
        name = node[:-len(".out")]
        # the Windkessel total: R_T/2 before the compartment's C_T, R_T/2 after it
        total = (by_name[name]["lumped"]["resistance"]
                 + by_name[f"{name}.distal_half"]["lumped"]["resistance"])
        root = roots[node]
        r_root = 8.0 * mu * root["length"] / (math.pi * root["radius"] ** 4)
        got = r_root + grown_resistance(grown[node], expanded["boundary_conditions"], node, mu)
        # bisection to 1e-15 on a per-radius-class sum; here a per-vessel sum (other order)
        assert abs(got / total - 1.0) < 1e-9, (node, got, total)
    segments = sum(v.get("segments", 1) for v in expanded["vessels"]
                   if "lumped" not in v)
    assert len(tree_vessels) == 256_132
    assert 1e5 < segments < 1e6


def test_whole_body_140_st_keeps_the_steady_pressures(base) -> None:
    """Mean pressures of the periodic state of this linear circuit (linear vessels, lumped
    elements, linear trees) are its steady state, which depends on resistances only: at every
    node of the named arteries it equals the Windkessel version's (which also keeps the wall
    viscosity branches: no steady flow). Trees grown to 0.5 mm here (14 k segments); the
    built-in 0.1 mm model: test below (slow) and docs."""
    data = make_models_data.whole_body_trees(min_radius=5e-4)
    p_wk = oxyline.load_model(base).network.steady_state()
    p_st = oxyline.load_model(data).network.steady_state()
    assert_named_pressures_agree(base, p_wk, p_st)


def assert_named_pressures_agree(base: dict, p_wk: dict, p_st: dict) -> float:
    wk = dict(zip(p_wk["nodes"], p_wk["node_pressure"]))
    tree = dict(zip(p_st["nodes"], p_st["node_pressure"]))
    named = {n for v in base["vessels"] if "lumped" not in v for n in (v["from"], v["to"])
             if not n.endswith(".mid")}  # the named arteries' ends (not the T's midpoints)
    assert len(named) == 135 and named <= set(wk) & set(tree)
    for node in named:
        # terminal resistances bisected to 1e-15; two sparse solves of different circuits
        # (measured 1e-14); the issue asks for 2 %
        assert abs(tree[node] / wk[node] - 1.0) < 1e-8, node
    return max(abs(tree[n] / wk[n] - 1.0) for n in named)  # printed by pytest -s


@pytest.mark.slow
def test_whole_body_140_st_full_size(base) -> None:
    """The built-in model itself (0.1 mm trees): its size, and the steady pressures at the
    named arteries (load + steady solve ~10-30 s on the shared machine)."""
    m = catalogue.load("whole-body-140-st")
    s = m.network.summary()
    assert (s["vessels"], s["segments"]) == (256_368, 305_949)
    worst = assert_named_pressures_agree(
        base, oxyline.load_model(base).network.steady_state(), m.network.steady_state())
    print(f"whole-body-140-st: steady pressures of the named arteries within {worst:.2e}")


def test_murray_root_radius_from_the_steady_flow_share() -> None:
    data = {"vessels": [{"name": "p", "from": "in", "to": "j", "radius": 2e-3},
                        {"name": "c", "from": "j", "to": "k", "radius": 1.5e-3},
                        {"name": "t", "from": "j", "to": "t.out", "lumped": {"resistance": 1}}]}
    steady = {"vessels": ["p", "c", "t"], "flow_in": [8e-6, 7e-6, 1e-6]}
    r0 = murray_root_radii(data, steady, ["t"])["t"]
    assert abs(r0 - 2e-3 * 0.5) < 1e-18  # (1/8)^(1/3) = 1/2
    with pytest.raises(oxyline.ModelError, match="0 vessels with a radius end at 'in'"):
        murray_root_radii(data, steady, ["p"])
    with pytest.raises(oxyline.ModelError, match="flow share"):
        murray_root_radii(data, {"vessels": ["p", "t"], "flow_in": [1e-6, -1e-7]}, ["t"])


def test_replace_terminal_vessels_rejects_what_it_cannot_match() -> None:
    data = {"units": "SI", "vessels": [
        {"name": "p", "from": "in", "to": "j", "length": 0.1, "radius": 2e-3},
        {"name": "t", "from": "j", "to": "t.out", "lumped": {"resistance": 1e9}},
        {"name": "t2", "from": "t.out", "to": "o", "length": 0.01, "radius": 1e-3}],
        "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                "o": {"type": "pressure", "value": 0.0}}}
    with pytest.raises(oxyline.ModelError, match="'t2' is not a lumped"):
        replace_terminal_vessels(data, {"t": 1e-3})
    data["vessels"][2] = {"name": "t2", "from": "t.out", "to": "o",
                          "lumped": {"resistance": 1e9}}
    with pytest.raises(oxyline.ModelError, match="no such terminal vessel"):
        replace_terminal_vessels(data, {"nope": 1e-3})
    out = replace_terminal_vessels(data, {"t": 1e-3}, min_radius=4e-4)
    assert [v["name"] for v in out["vessels"]] == ["p", "t"]
    bc = out["boundary_conditions"]["t.out"]
    assert bc["type"] == "structured-tree" and "o" not in out["boundary_conditions"]
    m = oxyline.load_model(out)
    p = dict(zip(*(m.network.steady_state()[k] for k in ("nodes", "node_pressure"))))
    # 1e-6 m^3/s through the replaced 2e9 Pa s/m^3 compartment
    assert abs(p["j"] / 2e3 - 1.0) < 1e-9


def test_whole_body_140_st_carries_oxygen() -> None:
    """The folded named arteries hold lumen volume wherever they hold compliance, so the
    model takes an oxygen section (whole-body-140 itself is refused) and conserves O2 over
    its default one-cycle run. Trees grown only to 1 mm (capped at alpha·r0: 3.8 k segments;
    ~0.7 s CPU; residual measured 9e-14 of the inflow)."""
    data = make_models_data.whole_body_trees(min_radius=1e-3)
    data["oxygen"] = {"inlet": {"po2": 95.0}, "wall": {"model": "leveque", "po2": 60.0}}
    res = oxyline.simulate(oxyline.load_model(data), segments=False)
    mb = res.o2_mass_balance
    # residual of the conservative transport: rounding of sums over the cells and 1000 steps
    assert abs(mb["residual"][-1]) < 1e-9 * mb["inflow"][-1]
    assert mb["wall_uptake"][-1] > 0.0
    base = catalogue.load_dict("whole-body-140")
    base["oxygen"] = data["oxygen"]
    with pytest.raises(oxyline.ModelError, match="no lumen volume"):
        oxyline.simulate(oxyline.load_model(base), cycles=1)
