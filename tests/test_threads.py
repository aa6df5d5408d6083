"""One run on several threads (``threads=``): the same bits on any number of threads, the
mass balance of the run kept, and a bad thread count refused naming the setting."""

from __future__ import annotations

import math
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


@pytest.fixture(scope="module")
def runs() -> dict[int, oxyline.Result]:
    m = oxyline.load_model(binary_tree(11, 8))
    assert m.network.summary()["segments"] == (2 ** 11 - 1) * 8
    return {n: oxyline.simulate(m, cycles=1, dt=2e-3, output_every=0.02, segments=True,
                                threads=n) for n in (1, 2, 3)}


def test_any_number_of_threads_gives_the_same_bits(runs: dict[int, oxyline.Result]) -> None:
    # exact equality is the claim: the threads do the same operations on every value in the
    # same order (fixed partition of the tree, every sum in the serial order)
    serial = runs[1]
    for n in (2, 3):
        assert np.array_equal(runs[n].time, serial.time)
        assert np.array_equal(runs[n].data, serial.data), f"{n} threads"
        for species, res in serial.species.items():
            other = runs[n].species[species]
            for part in ("vessel_data", "segment_data", "balance_data"):
                assert np.array_equal(getattr(other, part), getattr(res, part)), part


def test_the_threaded_run_conserves_oxygen(runs: dict[int, oxyline.Result]) -> None:
    # an independent check of the threaded run: the O2 balance of the whole tree (inflow =
    # outflow + wall flux + change of stored mass) closes to the transport's own accuracy
    mb = runs[2].o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-6 * abs(mb["inflow"][-1])


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
