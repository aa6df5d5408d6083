"""Networks with loops: the flow solve and the oxygen step eliminate the pendant trees around
the loop-carrying core (docs/solvers.md, "Networks with loops"). Checked against outside
truths: the oxygen balance of the whole network closes to rounding, and the run is the same
on any number of threads. (The core's solve against the general sparse LU of the same
system: `sparse::core` tests of the core crate.)"""

from __future__ import annotations

import numpy as np
import pytest

import oxyline
from tests.test_threads import assert_same_bits, random_tree_with_loops


@pytest.mark.parametrize("loops", [1, 2, 3])
def test_a_network_with_loops_conserves_oxygen_at_a_fixed_step(loops: int) -> None:
    # fixed-step generalized-alpha: the O2 balance (inflow = outflow + wall flux + change of
    # the stored amount) holds per step to the rounding of the solve, so a term lost or
    # double-counted between the trees and the core (their faces, the boundaries at core
    # nodes) would show at the size of that term's flux, far above 1e-10 of the inflow
    m = oxyline.load_model(random_tree_with_loops(60, loops, seed=10 + loops))
    res = oxyline.simulate(m, cycles=1, dt=1e-3, output_every=0.01, segments=True)
    mb = res.o2_mass_balance
    scale = np.abs(mb["inflow"]).max()
    assert np.abs(mb["residual"]).max() <= 1e-10 * scale, (mb["residual"][-1], scale)
    # and no negative concentration beyond rounding (the upwind rows are an M-matrix)
    c = res.species["o2"].concentration
    assert np.nanmin(c) >= -1e-12 * np.nanmax(np.abs(c))


def test_a_large_network_with_loops_gives_the_same_bits_on_any_number_of_threads() -> None:
    # ~17 k segments: the pendant trees' elimination is split over the threads (blocks of
    # more than 16 k unknowns), the core is solved serially; exact equality is the claim
    m = oxyline.load_model(random_tree_with_loops(5000, 3, seed=5))
    assert m.network.summary()["segments"] > 15_000
    runs = {
        n: oxyline.simulate(m, cycles=1, dt=2e-3, output_every=0.02, segments=False, threads=n)
        for n in (1, 2, 3)
    }
    assert_same_bits(runs)
    mb = runs[3].o2_mass_balance
    assert np.abs(mb["residual"]).max() <= 1e-9 * np.abs(mb["inflow"]).max()
