"""The output rows of an error-controlled generalized-α run of closed-loop-o2's heart circuit
(svZeroDSolver's heart block between the systemic veins and the arteries, docs/physics.md
§1.10) against a fine fixed step: the heart block's inflow (its ``flow_in``, the venous return
into the right atrium's node, whose pressure the atrium's volume fixes while the veins'
capacitance shares the node: an index-2 algebraic unknown) and every other vessel's flow and
pressure, at every row of three cycles; and a fixed step's rows of that inflow against the
fixed step's own error in the other vessels' flows (docs/physics.md §10, "Index-2
unknowns")."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import oxyline
from oxyline import closed_loop
from oxyline.model import build_model

RTOLS = (1e-2, 1e-3, 1e-4)
CYCLES = 3
#: the heart block's vessel (its flow_in: the venous return)
HEART = "heart_pulmonary"
#: the reference's steps per cycle: generalized-α at T/40000 (its heart inflow within 1e-6 of
#: its range of T/20000's at every row from `SKIP` on)
REFERENCE_STEPS = 40000
ROWS = 1000
#: rows before this time (s) are left out: the start state's inflow is not consistent with
#: the veins' pressure rate (index 2), and the fixed steps' first rows differ by 0.42 of the
#: range between T/20000 and T/40000 at t = 0.8 ms
SKIP = 0.01


@pytest.fixture(scope="module")
def model() -> oxyline.Model:
    heart = closed_loop.heart_model(closed_loop.load("closed-loop-o2"))
    heart["simulation"].pop("dt", None)
    return build_model(heart)


def run(model: oxyline.Model, **kw: float | str) -> oxyline.Result:
    with warnings.catch_warnings():
        # (the periodicity warning of a fixed number of cycles)
        warnings.simplefilter("ignore")
        return oxyline.simulate(model, progress=False, until_periodic=None, cycles=CYCLES,
                                output_cycles="all", output_every=float(model.period) / ROWS,
                                **kw)


@pytest.fixture(scope="module")
def reference(model: oxyline.Model) -> oxyline.Result:
    return run(model, method="generalized-alpha", dt=float(model.period) / REFERENCE_STEPS)


def row_errors(res: oxyline.Result, ref: oxyline.Result, name: str,
               var: str = "") -> tuple[float, ...]:
    """max |x − x_ref| over the rows relative to range(x_ref), for `name`'s flow_in and
    pressure_in (or `var` alone)."""
    assert np.allclose(res.time, ref.time, atol=1e-9)
    rows = np.asarray(ref.time) >= SKIP
    out = []
    for v in (var,) if var else ("flow_in", "pressure_in"):
        x, e = getattr(res.vessel(name), v)[rows], getattr(ref.vessel(name), v)[rows]
        out.append(float(np.max(np.abs(x - e)) / np.ptp(e)))
    return tuple(out)


#: the largest row error of the heart's inflow allowed, relative to its range, per rtol (about
#: 1.3x the measured worst rows, 0.068 / 0.045 / 0.0032 at rtol 1e-2 / 1e-3 / 1e-4). Its rows
#: are the values its balance row gives with the veins' pressure rate taken from that
#: pressure's α_f-level values, which lie on the atrium's law, and the error control judges
#: that rate's error (docs/physics.md §10, "Index-2 unknowns"). Unjudged, the rows were 0.079 /
#: 0.109 / 0.029 off (a 13 ms step over the onset of the atrium's contraction at rtol 1e-3):
#: the bounds at 1e-3 and 1e-4 fail them. Not yet rtol: the rows just past that onset (a kink
#: of the pressure's rate, 0.5626 s into the cycle) are extrapolated from levels before it.
INFLOW_BOUND = {1e-2: 0.09, 1e-3: 0.06, 1e-4: 0.0042}
#: the heart block's inlet pressure (the veins' node, a differential unknown): 3x rtol of its
#: range (measured 4.1e-4 / 1.1e-4 / 2.4e-5)


@pytest.mark.parametrize("rtol", RTOLS)
def test_heart_inflow_rows_follow_a_fine_fixed_step(model: oxyline.Model,
                                                    reference: oxyline.Result,
                                                    rtol: float) -> None:
    res = run(model, method="generalized-alpha", rtol=rtol)
    q, p = row_errors(res, reference, HEART)
    assert q <= INFLOW_BOUND[rtol], (rtol, q)
    assert p <= 3 * rtol, (rtol, p)


#: the vessels whose flows set a fixed step's own error (every vessel but the heart block)
OTHERS = ("veins", "arteries", "brain", "heart", "kidneys", "splanchnic", "muscle", "skin_other")
#: a fixed step's inflow rows within this many times the largest row error of the other
#: vessels' flows, by steps per cycle: 1.5x the measured 8.4 / 5.7 / 0.37 at T/1000, T/2000,
#: T/4000 (the worst rows are single rows at a valve's opening, which a fixed step straddles).
#: generalized-α's own step-end values read 920 / 5.5 / 3.6x the others' error (1.2 / 0.0041 /
#: 0.0014 of the range): the bounds at T/1000 and T/4000 fail them, T/2000's does not
FIXED_FACTOR = {1000: 12.0, 2000: 8.5, 4000: 0.6}


@pytest.mark.parametrize("steps", (1000, 2000, 4000))
def test_fixed_step_rows_of_the_heart_inflow_are_within_the_steps_error(
        model: oxyline.Model, reference: oxyline.Result, steps: int) -> None:
    res = run(model, method="generalized-alpha", dt=float(model.period) / steps)
    q, _ = row_errors(res, reference, HEART)
    others = max(row_errors(res, reference, v, var="flow_in")[0] for v in OTHERS)
    assert q <= FIXED_FACTOR[steps] * others, (steps, q, others)
