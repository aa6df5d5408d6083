"""The default start of a run (docs/physics.md §10 "The default start"): an error-controlled run
to periodicity starts from the periodic state the core estimates, and reaches its tolerance in
no more cycles than from the steady start, ending on the same periodic cycle; a fixed step, a
run of exactly `cycles` and a start given keep theirs."""

from __future__ import annotations

import numpy as np
import pytest

import oxyline

#: a linear circuit whose Windkessels (R·C ~ the period) take cycles to charge from the mean
MODEL = "aortic-bifurcation"
#: the periodicity tolerance of these runs (the cycle-to-cycle change of the state)
UNTIL = 1e-4


def _to_periodic(**kw: object) -> oxyline.Result:
    # rtol 1e-7: the time-integration error of either start (~rtol) far below UNTIL, so the
    # two runs' last cycles differ by where each stopped, not by their different steps
    return oxyline.simulate(MODEL, cycles=1, until_periodic=UNTIL, max_cycles=80, rtol=1e-7,
                            output_every=1e-3, progress=False, **kw)


@pytest.fixture(scope="module")
def runs() -> tuple[oxyline.Result, oxyline.Result]:
    return _to_periodic(), _to_periodic(start="steady")


def test_the_default_start_of_a_run_to_periodicity_takes_no_more_cycles(runs) -> None:
    default, steady = runs
    assert default.settings["start"] == "periodic"
    assert steady.settings["start"] == "steady"
    assert default.settings["periodic_reached"] and steady.settings["periodic_reached"]
    # the measured comparison (it fails if the periodic estimate were the worse start)
    assert default.settings["cycles_run"] <= steady.settings["cycles_run"], (
        default.settings["cycles_run"], steady.settings["cycles_run"])


def test_its_last_cycle_is_the_steady_starts_converged_cycle(runs) -> None:
    default, steady = runs
    # both stopped with a cycle-to-cycle change below UNTIL; each is within a few UNTIL of
    # the periodic solution (the change contracts from cycle to cycle), so the two last
    # cycles agree to a small multiple of it, each kind against its own largest magnitude
    for name in ("pressure_in", "flow_in"):
        a, b = getattr(default, name), getattr(steady, name)
        assert a.shape == b.shape
        err = float(np.max(np.abs(a - b)) / np.max(np.abs(b)))
        assert err <= 5 * UNTIL, (name, err)


@pytest.mark.filterwarnings("ignore::oxyline.PeriodicityWarning")  # (runs cut at max_cycles)
def test_a_fixed_step_a_run_of_exactly_cycles_and_a_start_given_keep_theirs() -> None:
    fixed = oxyline.simulate(MODEL, dt=1e-3, cycles=1, until_periodic=UNTIL, max_cycles=3,
                             output_every=1e-2)
    assert fixed.settings["start"] == "steady"
    exact = oxyline.simulate(MODEL, cycles=1, until_periodic=None, output_every=1e-2)
    assert exact.settings["start"] == "steady"
    given = oxyline.simulate(MODEL, cycles=1, until_periodic=UNTIL, max_cycles=2,
                             output_every=1e-2, start="zero")
    assert given.settings["start"] == "zero"
    # the fixed step's outputs are those of the steady start named, bit for bit
    named = oxyline.simulate(MODEL, dt=1e-3, cycles=1, until_periodic=UNTIL, max_cycles=3,
                             output_every=1e-2, start="steady")
    assert np.array_equal(fixed.data, named.data)
