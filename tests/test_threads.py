"""One run on several threads (``threads=``): the same bits on any number of threads, the
mass balance of the run kept, and a bad thread count refused naming the setting."""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline.errors import ModelError


def binary_tree(depth: int, per_vessel: int) -> dict[str, Any]:
    """A symmetric binary tree of ``2^depth - 1`` vessels with Murray radii, a pulsatile
    inflow, one RCR per leaf and oxygen transport with a constant-k wall. At depth 11 and 8
    segments per vessel it has ~16 k segments and ~50 k unknowns: above the sizes from which
    the tree elimination and the step's residual are split over the threads."""
    n_leaves = 2 ** (depth - 1)
    r_total, c_total = 1.33e8, 1.0e-8
    rcr = {"type": "rcr", "proximal_resistance": 0.1 * r_total * n_leaves,
           "capacitance": c_total / n_leaves, "distal_resistance": 0.9 * r_total * n_leaves}
    t = [i / 100 for i in range(101)]
    inflow = {"type": "flow", "time": t,
              "flow": [9e-5 * (1.0 + 0.8 * math.sin(2 * math.pi * ti)) for ti in t]}
    vessels, bcs = [], {"in": inflow}
    for i in range(2 ** depth - 1):
        level = int(math.log2(i + 1))
        r = 0.01 * 2.0 ** (-level / 3.0)
        vessels.append({"name": f"v{i}", "from": "in" if i == 0 else f"n{(i - 1) // 2}",
                        "to": f"n{i}", "length": 10 * r, "radius": r, "wall_thickness": 0.1 * r,
                        "youngs_modulus": 4e5, "segments": per_vessel})
        if level == depth - 1:
            bcs[f"n{i}"] = rcr
    return {"name": "tree", "period": 1.0, "vessels": vessels, "boundary_conditions": bcs,
            "oxygen": {"inlet": {"po2": 95.0}, "hemoglobin": "none",
                       "wall": {"model": "mass-transfer", "k": 1e-5, "po2": 60.0}}}


def random_tree_with_loops(vessels: int, loops: int, seed: int) -> dict[str, Any]:
    """A random tree (up to three children per junction, 1-6 segments per vessel) whose
    ``loops`` extra vessels join random pairs of inner junctions (anastomoses), with oxygen: the
    flow solve takes the general sparse LU and the transport the flow-order sweep."""
    rng = np.random.default_rng(seed)
    children = [0] * vessels
    vessels_, bcs = [], {}
    for i in range(vessels):
        if i == 0:
            parent = "in"
        else:
            p = int(rng.integers(i))
            while children[p] >= 3:
                p = (p + 1) % i
            children[p] += 1
            parent = f"n{p}"
        r = 2e-3 * (0.5 + rng.random())
        vessels_.append({"name": f"v{i}", "from": parent, "to": f"n{i}", "length": 0.02,
                         "radius": r, "wall_thickness": 0.1 * r, "youngs_modulus": 4e5,
                         "segments": int(rng.integers(1, 7))})
    junctions = [i for i in range(vessels) if children[i] > 0]
    for k in range(loops):
        a, b = rng.choice(junctions, size=2, replace=False)
        vessels_.append({"name": f"loop{k}", "from": f"n{a}", "to": f"n{b}", "length": 0.03,
                         "radius": 1e-3, "wall_thickness": 1e-4, "youngs_modulus": 4e5,
                         "segments": 3})
    t = [i / 50 for i in range(51)]
    bcs["in"] = {"type": "flow", "time": t,
                 "flow": [2e-5 * (1.0 + 0.8 * math.sin(2 * math.pi * ti)) for ti in t]}
    leaves = [i for i in range(vessels) if children[i] == 0]
    for i in leaves:
        bcs[f"n{i}"] = {"type": "rcr", "proximal_resistance": 1e8 * len(leaves),
                        "capacitance": 1e-9 / len(leaves),
                        "distal_resistance": 9e8 * len(leaves)}
    return {"name": "random", "period": 1.0, "vessels": vessels_, "boundary_conditions": bcs,
            "oxygen": {"inlet": {"po2": 95.0}, "hemoglobin": "hill",
                       "wall": {"model": "mass-transfer", "k": 1e-5, "po2": 60.0}}}


THREADS = (1, 2, 3, 4)


@pytest.fixture(scope="module")
def tree() -> oxyline.Model:
    m = oxyline.load_model(binary_tree(11, 8))
    assert m.network.summary()["segments"] == (2 ** 11 - 1) * 8
    return m


@pytest.fixture(scope="module")
def runs(tree: oxyline.Model) -> dict[int, oxyline.Result]:
    return {n: oxyline.simulate(tree, cycles=1, dt=2e-3, output_every=0.02, segments=True,
                                threads=n) for n in THREADS}


def assert_same_bits(runs: dict[int, oxyline.Result]) -> None:
    # exact equality is the claim: the threads do the same operations on every value in the
    # same order (fixed partitions, every sum in a fixed order whatever the thread count)
    serial = runs[1]
    for n, other in runs.items():
        assert np.array_equal(other.time, serial.time)
        assert np.array_equal(other.data, serial.data), f"{n} threads"
        for species, res in serial.species.items():
            for part in ("vessel_data", "segment_data", "balance_data"):
                # (columns not recorded are NaN in every run)
                assert np.array_equal(getattr(other.species[species], part),
                                      getattr(res, part), equal_nan=True), f"{part}, {n} threads"


def test_any_number_of_threads_gives_the_same_bits(runs: dict[int, oxyline.Result]) -> None:
    assert_same_bits(runs)


def test_the_default_error_controlled_run_gives_the_same_bits(tree: oxyline.Model) -> None:
    # the default settings: error-controlled generalized-alpha (its estimates and the O2
    # step on the threads), the step sequence included; rows every 20 ms as in `runs` (the
    # rows never change the steps: 355 either way; 51 dense-output rows instead of 1001)
    runs = {n: oxyline.simulate(tree, cycles=1, output_every=0.02, segments=True, threads=n)
            for n in THREADS}
    assert runs[1].settings.get("steps") is not None, "an error-controlled run"
    assert_same_bits(runs)


def test_the_error_controls_split_passes_give_the_same_bits() -> None:
    # ~70 k segments: more than two chunks (32,768 unknowns each) of pressures and of flows,
    # so that the error control's own passes (the estimate with its peak test, the peak and
    # flow-scale tracking, the algebraic unknowns' errors, the start-state copies and the
    # species rows' interpolation) are split over the threads; the step sequence included
    m = oxyline.load_model(binary_tree(12, 17))
    runs = {n: oxyline.simulate(m, cycles=1, output_every=0.05, segments=False, threads=n)
            for n in THREADS}
    assert runs[1].settings.get("steps") is not None, "an error-controlled run"
    assert_same_bits(runs)
    # and an outside check of that run: the tree's O2 balance closes
    mb = runs[1].o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-6 * abs(mb["inflow"][-1])


def test_a_random_tree_with_loops_gives_the_same_bits() -> None:
    m = oxyline.load_model(random_tree_with_loops(400, 12, seed=3))
    runs = {n: oxyline.simulate(m, cycles=1, dt=2e-3, output_every=0.02, segments=True,
                                threads=n) for n in THREADS}
    assert_same_bits(runs)
    # and its O2 balance closes (inflow = outflow + wall + stored), an outside check
    mb = runs[4].o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-6 * abs(mb["inflow"][-1])


def test_the_vessel_rows_split_over_the_threads_give_the_same_bits() -> None:
    # 8 191 vessels: more than two chunks of 2 048 vessels, so each output row's vessel
    # observation (inlet and outlet concentrations and fluxes, wall uptake) is split over
    # the threads; the forcing's constant outlet pressures are summed once
    m = oxyline.load_model(binary_tree(13, 2))
    runs = {n: oxyline.simulate(m, cycles=1, dt=2e-3, output_every=0.02, segments=False,
                                threads=n) for n in THREADS}
    assert runs[1].species["o2"].vessel_data.shape[1] == 8191
    assert_same_bits(runs)
    # an outside check of the threaded run: the tree's O2 balance closes
    mb = runs[3].o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-6 * abs(mb["inflow"][-1])


def test_the_outlets_and_output_rows_split_over_the_threads_give_the_same_bits() -> None:
    # 8 192 outlets: more than two chunks of 4 096 boundary faces, so every step's boundary
    # faces (their flows, their terms in their nodes' rows, their O2 fluxes, summed in face
    # order) are split over the threads; 81 915 cells: more than two chunks of 32 768, so
    # each output row's cell volumes, face flows and concentrations are too
    m = oxyline.load_model(binary_tree(14, 5))
    assert m.network.summary()["segments"] == (2 ** 14 - 1) * 5
    runs = {n: oxyline.simulate(m, cycles=1, dt=2e-3, output_every=0.05, segments=False,
                                threads=n) for n in THREADS}
    assert_same_bits(runs)
    # an outside check of the threaded run: the tree's O2 balance closes
    mb = runs[2].o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-6 * abs(mb["inflow"][-1])


def test_the_threaded_run_conserves_oxygen(runs: dict[int, oxyline.Result]) -> None:
    # an independent check of the threaded run: the O2 balance of the whole tree (inflow =
    # outflow + wall flux + change of stored mass) closes to the transport's own accuracy
    mb = runs[2].o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-6 * abs(mb["inflow"][-1])


@pytest.mark.parametrize("controlled", [False, True])
def test_the_steps_on_the_pool_leave_the_callbacks_on_the_calling_thread(
        tree: oxyline.Model, controlled: bool) -> None:
    # each step's passes run as one entry of the run's pool, on a pool thread; the progress
    # callback (and with it Ctrl-C and cancel) stays on the thread that called simulate
    seen: list[int] = []
    dt = {} if controlled else {"dt": 2e-3}
    res = oxyline.simulate(tree, cycles=1, output_every=0.05, segments=False, threads=2,
                           progress=lambda t, t_end: seen.append(threading.get_ident()), **dt)
    assert (res.settings.get("steps") is not None) == controlled
    assert seen, "the progress callback was called"
    assert set(seen) == {threading.get_ident()}


@pytest.mark.parametrize("bad", [0, -2, 1.5, "two"])
def test_a_bad_thread_count_is_refused_naming_the_setting(bad: object) -> None:
    with pytest.raises(ModelError, match="threads"):
        oxyline.simulate("bifurcation", cycles=1, threads=bad)


def test_the_model_file_may_set_the_threads() -> None:
    m = oxyline.load_model("bifurcation")
    d = m.to_dict()
    d.setdefault("simulation", {})["threads"] = 2
    one = oxyline.simulate(oxyline.load_model(d), cycles=1)
    assert np.array_equal(one.data, oxyline.simulate(m, cycles=1, threads=1).data)
