"""Hearts and valves under the default error control (docs/solvers.md, "Hearts and valves
under the default"): `method: auto` keeps the implicit method where the explicit pair's
stages would need a Newton iteration, and a circuit with a growing mode (a negative
stenosis coefficient) is refused by name at any size, or, where no bound was probed, its
run's failure names the cause."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import svzerod as svz
from tests.conftest import data_path


def _default(case: str) -> dict[str, Any]:
    """An svZeroDSolver case with its fixed step and method dropped: the default run."""
    m = svz.to_oxyline_dict(str(data_path("svzerod", "cases", f"{case}.json")))
    for key in ("dt", "method", "rtol", "cycles", "until_periodic", "output_every"):
        m.get("simulation", {}).pop(key, None)
    return m


def test_auto_keeps_generalized_alpha_for_the_coronary_heart() -> None:
    """The coronary closed-loop heart's algebraic rows hold its valve laws: the explicit
    pair would solve them by Newton in every stage (where it failed at 0.93 s); `auto`
    takes generalized-α, which runs."""
    m = oxyline.load_model(_default("closedLoopHeart_withCoronaries"))
    res = oxyline.simulate(m, rtol=1e-3, cycles=1, until_periodic=None)
    assert res.settings["method"] == "generalized-alpha"
    assert res.settings["step_control"] != "fixed"


def _stenosis(segments: int) -> dict[str, Any]:
    """A tube of `segments` sections into a lumped stenosis of coefficient −1e12 at a
    steady flow of 1e-5 m³/s: R + 2S|Q| = 1e6 − 2e7 < 0."""
    return {
        "name": "stenosis", "period": 1.0,
        "vessels": [
            {"name": "a", "from": "in", "to": "j", "length": 0.0625, "radius": 0.0039,
             "wall_thickness": 3e-4, "youngs_modulus": 1e6, "segments": segments},
            {"name": "s", "from": "j", "to": "out",
             "lumped": {"resistance": 1e6, "capacitance": 1e-10, "inductance": 1e4,
                        "stenosis_coefficient": -1e12}}],
        "boundary_conditions": {"in": {"type": "flow", "value": 1e-5},
                                "out": {"type": "resistance", "resistance": 1e7}},
    }


def _growth_rate(message: str) -> complex:
    """The eigenvalue a growing mode's refusal states."""
    text = message.split("eigenvalue ")[1].split(" 1/s")[0]
    re, sign, im = text.split(" ")
    return complex(float(re), float(im.rstrip("i")) * (1 if sign == "+" else -1))


@pytest.mark.parametrize("method", ["rk4", "auto"])
def test_a_growing_mode_is_refused_naming_the_stenosis_at_any_size(method: str) -> None:
    """Below 600 differential unknowns the dense spectrum shows the growing mode, above it
    (709 segments) the Cayley search does (before: not refused, a misleading 'singular
    system' at t = 0.011 s). Both refusals name the stenosis and its coefficient, and state
    the same eigenvalue: the tube's segmentation barely moves a mode of the stenosis' own
    L, C and negative R (within 1 %)."""
    lam = {}
    for segments in (100, 709):
        with pytest.raises(oxyline.ModelError) as info:
            oxyline.simulate(_stenosis(segments), method=method, cycles=1, start="zero",
                             progress=False)
        msg = str(info.value)
        assert "growing mode" in msg and "vessel 's'" in msg, msg
        assert "stenosis_coefficient -1.000e12" in msg and "R + 2S|Q| = -1.900e7" in msg, msg
        lam[segments] = _growth_rate(msg)
    assert lam[100].real > 0 and abs(lam[709] - lam[100]) < 1e-2 * abs(lam[100]), lam


def test_a_run_that_blows_up_names_the_negative_resistance() -> None:
    """Generalized-α with a fixed step probes no bound: the growing mode ends the run, and
    the solver's message names the stenosis of negative incremental resistance."""
    with pytest.raises(oxyline.SolverError) as info:
        oxyline.simulate(_stenosis(100), method="generalized-alpha", dt=1e-3, cycles=1,
                         start="zero", progress=False)
    msg = str(info.value)
    assert "cause: flow in vessel 's' has a negative incremental resistance" in msg, msg
    assert "S = -1.000e12" in msg, msg


def _cardiac_output(res: oxyline.Result, vessel: str, period: float) -> float:
    """The mean flow through `vessel` over the last cycle (trapezoid over the rows)."""
    t, q = np.asarray(res.time), np.asarray(res.vessel(vessel).flow_in)
    last = t >= t[-1] - period * (1 + 1e-9)
    t, q = t[last], q[last]
    return float(np.sum(0.5 * (q[1:] + q[:-1]) * np.diff(t)) / (t[-1] - t[0]))


def _left_heart() -> dict[str, Any]:
    from tests.test_sensitivity_heart import HEART
    m = dict(HEART)
    m.pop("simulation")
    return m


#: (model, its outlet vessel, rtol, the relative cardiac output error allowed): runs that
#: failed with a typed SolverError before the leap (docs/physics.md §10.5, "Newton
#: failure"), against generalized-α at a fixed step of 1/5000 of the period, the same 5
#: cycles from the same start. Allowed: 2x rtol (the valves' event timing is within the
#: control's tolerance, and the cardiac output integrates it), measured in the comment.
FIXED = [
    (_left_heart, "aortic", 1e-2, "left heart"),
    (lambda: _default("closedLoopHeart_singleVessel_decomposed"), "AV", 1e-2, "decomposed"),
]


@pytest.mark.parametrize(("make", "vessel", "rtol", "label"), FIXED,
                         ids=[f[3] for f in FIXED])
def test_hearts_that_failed_run_and_keep_their_cardiac_output(
        make: Any, vessel: str, rtol: float, label: str) -> None:
    model = oxyline.load_model(make())
    period = model.period
    res = oxyline.simulate(model, rtol=rtol, cycles=5, until_periodic=None,
                           output_every=period / 1000)
    ref = oxyline.simulate(model, method="generalized-alpha", dt=period / 5000, cycles=5,
                           until_periodic=None, output_every=period / 1000)
    got, want = (_cardiac_output(r, vessel, period) for r in (res, ref))
    assert abs(want) > 0
    assert abs(got - want) <= 2 * rtol * abs(want), (label, got, want)
