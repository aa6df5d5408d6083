"""``oxyline.sensitivity.sobol`` against closed-form Sobol' indices.

The network is Ohm's law: a constant inflow Q through a lumped resistance R1 into a resistance
outlet R2, started at its steady state, so the inlet pressure is exactly P = Q (R1 + R2). With
Q, R1, R2 independent and uniform, the indices of this product are closed-form (a sum of
variances, e.g. Saltelli et al. 2008, Global Sensitivity Analysis, ch. 4):

    V    = E[Q²] E[S²] − E[Q]² E[S]²                 (S = R1 + R2)
    S1_Q = E[S]² Var Q / V,   S1_Ri = E[Q]² Var Ri / V
    ST_Q = 1 − E[Q]² Var S / V,   ST_Ri = E[Q²] Var Ri / V

and the blood density (it sets only inertances, which carry no steady flow) has S1 = ST = 0.
"""

from __future__ import annotations

import numpy as np
import pytest

import oxyline

pytest.importorskip("SALib")
from oxyline import sensitivity

OHM = {"name": "ohm", "period": 1.0,
       "vessels": [{"name": "v", "from": "in", "to": "out", "lumped": {"resistance": 1e8}}],
       "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                               "out": {"type": "resistance", "resistance": 1e9}}}
BOUNDS = {"boundary_conditions.in.value": (0.5e-6, 1.5e-6),
          "vessels.v.lumped.resistance": (1e8, 9e8),
          "boundary_conditions.out.resistance": (2e8, 1e9),
          "blood.density": (1000.0, 1100.0)}


def _closed_form() -> tuple[np.ndarray, np.ndarray]:
    (q0, q1), (a0, a1), (b0, b1) = list(BOUNDS.values())[:3]
    mean = lambda lo, hi: (lo + hi) / 2
    var = lambda lo, hi: (hi - lo) ** 2 / 12
    eq, vq = mean(q0, q1), var(q0, q1)
    es, v1, v2 = mean(a0, a1) + mean(b0, b1), var(a0, a1), var(b0, b1)
    eq2, es2 = vq + eq**2, v1 + v2 + es**2
    v = eq2 * es2 - eq**2 * es**2
    s1 = np.array([es**2 * vq, eq**2 * v1, eq**2 * v2, 0.0]) / v
    st = np.array([1 - eq**2 * (v1 + v2) / v, eq2 * v1 / v, eq2 * v2 / v, 0.0])
    return s1, st


def test_sobol_indices_of_ohms_law_match_the_closed_form() -> None:
    def inlet_pressure(res: oxyline.Result) -> float:
        return float(res.pressure_in[0, 0])

    problem = {"names": list(BOUNDS), "bounds": [list(b) for b in BOUNDS.values()]}
    si = sensitivity.sobol(OHM, problem, 512, inlet_pressure, cycles=1, output_every=0.5,
                           progress=False)["quantity"]
    s1, st = _closed_form()
    # the model is exact (P = Q (R1 + R2) to rounding), so the only error is the estimator's:
    # with 512 x 6 scrambled Sobol' samples (seed 0) it is about 1e-3 here (SALib's 95 %
    # bootstrap intervals, 0.04-0.08, are far more cautious); 0.01 tells a wrong formula, a
    # mixed-up parameter or a lost variant apart from the estimator's noise
    np.testing.assert_allclose(si["S1"].to_numpy(), s1, atol=0.01)
    np.testing.assert_allclose(si["ST"].to_numpy(), st, atol=0.01)
    assert si["S1"].iloc[-1] == 0.0 and si["ST"].iloc[-1] == 0.0  # no effect at all
    # the interaction of Q with R1 + R2: ST - S1 summed over parameters
    assert (si["ST"] - si["S1"]).sum() == pytest.approx((st - s1).sum(), abs=0.01)


def test_named_summary_quantities_and_failures() -> None:
    problem = {"names": ["vessels.v.lumped.resistance"], "bounds": [[1e8, 9e8]]}
    si = sensitivity.sobol(OHM, problem, 8, "pressure_in_mean[v]", cycles=1,
                           output_every=0.5, progress=False)
    assert list(si) == ["pressure_in_mean[v]"]
    # one parameter explains all of a deterministic output
    assert si["pressure_in_mean[v]"]["S1"].iloc[0] == pytest.approx(1.0, abs=0.1)
    bad = {"names": ["vessels.v.lumped.resistance"], "bounds": [[-1e9, -1e8]]}
    with pytest.raises(oxyline.ModelError, match="variants failed"):
        sensitivity.sobol(OHM, bad, 4, "pressure_in_mean[v]", cycles=1, progress=False)
    with pytest.raises(oxyline.ModelError, match="summary variable"):
        sensitivity.sobol(OHM, problem, 4, "pressure_in_mean", cycles=1, progress=False)


R = "vessels.v.lumped.resistance"


@pytest.mark.parametrize(("problem", "n", "message"), [
    ([R], 4, "problem must be a mapping"),
    ({"names": R, "bounds": [[1e8, 2e8]]}, 4, "needs 'names'"),
    ({"names": [R], "bounds": [[1e8, 2e8], [1.0, 2.0]]}, 4, "one 'bounds' entry per name"),
    ({"names": [R], "bounds": [[2e8, 1e8]]}, 4, f"parameter '{R}': bounds .* low < high"),
    ({"names": [R], "bounds": [[2e8, 2e8]]}, 4, "low < high"),
    ({"names": [R], "bounds": [[1e8, 2e8, 3e8]]}, 4, "low < high"),
    ({"names": [R], "bounds": [["a", "b"]]}, 4, "bounds must be numbers, got \\['a', 'b'\\]"),
    # NaN samples would be empty DataFrame cells (the base value): silent zero indices
    ({"names": [R], "bounds": [[float("nan"), 2e8]]}, 4, "bounds must be finite"),
    ({"names": [R, R], "bounds": [[1e8, 2e8]] * 2}, 4, "named twice"),
    ({"names": [R], "bounds": [[1e8, 2e8]], "groups": ["g"]}, 4, "groups not supported"),
    ({"names": [R], "bounds": [[1e8, 2e8]], "num_vars": 2}, 4, "'num_vars' is 2"),
    ({"names": [R], "bounds": [[1e8, 2e8]], "dists": ["gauss"]}, 4,
     "SALib refused the problem: Distributions: choose one of unif"),
    ({"names": ["vessels.v.lumped.resistanse"], "bounds": [[1e8, 2e8]]}, 4,
     r"variant 0: vessels\.v\.lumped\.resistanse: unknown lumped property"),
    ({"names": ["vessels.w.radius"], "bounds": [[1e-3, 2e-3]]}, 4,
     r"variant 0: vessels\.w\.radius: no vessel"),
    ({"names": [R], "bounds": [[1e8, 2e8]]}, 6, "n must be a power of 2 .*, got 6"),
    ({"names": [R], "bounds": [[1e8, 2e8]]}, 0, "n must be a power of 2"),
    ({"names": [R], "bounds": [[1e8, 2e8]]}, 4.0, "n must be a power of 2"),
])
def test_a_bad_problem_is_a_model_error_naming_the_parameter(problem: object, n: object,
                                                             message: str) -> None:
    with pytest.raises(oxyline.ModelError, match=message):
        sensitivity.sobol(OHM, problem, n, "pressure_in_mean[v]", cycles=1, progress=False)


def test_bad_quantities_are_model_errors_and_constant_ones_get_zero_indices() -> None:
    problem = {"names": [R, "blood.density"], "bounds": [[1e8, 9e8], [1000.0, 1100.0]]}
    run = {"cycles": 1, "output_every": 0.5, "progress": False}
    # refused before anything runs: an unknown vessel, a quantity that is no quantity
    with pytest.raises(oxyline.ModelError, match=r"'pressure_in_mean\[w\]': no vessel named 'w'"):
        sensitivity.sobol(OHM, problem, 4, "pressure_in_mean[w]", **run)
    with pytest.raises(oxyline.ModelError, match="a quantity is a callable"):
        sensitivity.sobol(OHM, problem, 4, 3, **run)
    # a NaN quantity names the quantity and a sample, never NaN or made-up indices
    with pytest.raises(oxyline.ModelError, match=r"quantity 'po2' is nan for 16 of 16 samples, "
                                                 r"e.g. variant 0 \(vessels\.v\.lumped"):
        sensitivity.sobol(OHM, problem, 4, lambda res: {"po2": float("nan")}, **run)
    # the inlet pressure does not depend on the density at all (steady flow: only inertances
    # see it): a constant quantity has zero variance, indices 0 (not 0/0) and a warning
    with pytest.warns(UserWarning, match="'p_density' is the same"):
        si = sensitivity.sobol({**OHM, "blood": {"density": 1050.0}},
                               {"names": ["blood.density"], "bounds": [[1000.0, 1100.0]]}, 4,
                               lambda res: {"p_density": float(res.pressure_in[0, 0])}, **run)
    frame = si["p_density"]
    assert frame[["S1", "S1_conf", "ST", "ST_conf"]].to_numpy().tolist() == [[0.0] * 4]
    # P = Q (R1 + R2) exactly: the same closed form as above, at every sample
    p = frame.attrs["values"]
    assert np.allclose(p, 1e-6 * (1e8 + 1e9), rtol=1e-12)
