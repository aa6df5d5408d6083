"""RK4 stability bound above the dense size: the Krylov estimate of the core
against numpy's dense eigenvalues of the same operator (exported by ``rk4_operator``), for
chains, trees and refined built-in models from ~100 to ~5,000 differential unknowns.

The reference is independent of the Krylov code: LAPACK eigenvalues (numpy) and an RK4 region
test written here (the stability polynomial evaluated along each eigenvalue's ray).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import oxyline


def rk4_step_limits(lam: np.ndarray) -> np.ndarray:
    """Largest h with |R(h λ)| <= 1 along each eigenvalue's ray, R the RK4 polynomial
    (bisection; the region's boundary lies within |z| < 3 in the left half-plane)."""
    lam = np.asarray(lam, dtype=complex)
    mag = np.abs(lam)
    lo, hi = np.zeros_like(mag), np.where(mag > 0, 3.2 / np.where(mag > 0, mag, 1.0), np.inf)

    def stable(h: np.ndarray) -> np.ndarray:
        z = lam * h
        return np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) <= 1 + 1e-12

    finite = np.isfinite(hi)
    for _ in range(70):
        mid = np.where(finite, 0.5 * (lo + hi), 0.0)
        ok = stable(mid)
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    return np.where(finite, lo, np.inf)


def dense_limit(model: oxyline.Model) -> tuple[float, int]:
    flat, n = model.network.rk4_operator()
    lam = np.linalg.eigvals(flat.reshape(n, n))
    return float(rk4_step_limits(lam).min()), n


def chain(n: int, wiggle: bool = True) -> dict[str, Any]:
    """``n`` vessels in series, radii tapering 12 -> 3 mm (with a deterministic wiggle so no two
    neighbours are alike), 2 segments each, flow inlet, resistance outlet."""
    vessels = []
    for i in range(n):
        r = 0.012 - 0.009 * i / max(n, 2) + (0.001 * ((i * 37) % 11) / 11 if wiggle else 0.0)
        length = 0.04 + 0.02 * ((i * 13) % 7) / 7
        vessels.append({"name": f"v{i}", "from": f"n{i}", "to": f"n{i + 1}", "length": length,
                        "radius": r, "wall_thickness": 1e-3, "youngs_modulus": 4e5,
                        "segments": 2})
    return {"name": f"chain{n}", "period": 1.0, "vessels": vessels,
            "boundary_conditions": {"n0": {"type": "flow", "value": 1e-5},
                                    f"n{n}": {"type": "resistance", "resistance": 1e8}}}


def tree(depth: int) -> dict[str, Any]:
    """Complete binary tree, Murray radii r = 5 mm 2^(-d/3), l = 20 r, 2 segments a vessel."""
    vessels, outlets = [], {}
    for i in range(2 ** depth - 1):
        d = int(np.log2(i + 1))
        r = 0.005 * 2 ** (-d / 3)
        child = 2 * i + 1
        to = f"n{i}" if child < 2 ** depth - 1 else f"out{i}"
        vessels.append({"name": f"v{i}", "from": "in" if i == 0 else f"n{(i - 1) // 2}",
                        "to": to, "length": 20 * r, "radius": r, "wall_thickness": 3e-4,
                        "youngs_modulus": 6e5, "segments": 2})
        if to.startswith("out"):
            outlets[to] = {"type": "resistance", "resistance": 1e8 * 2 ** (depth - 1)}
    return {"name": f"tree{depth}", "period": 1.0, "vessels": vessels,
            "boundary_conditions": {"in": {"type": "flow", "value": 1e-5}, **outlets}}


def refined(name: str, max_length: float) -> dict[str, Any]:
    d = copy.deepcopy(oxyline.catalogue.load_dict(name))
    d["segmentation"] = {"max_length": max_length}
    for v in d["vessels"]:
        v.pop("segments", None)
    return d


def check(model_dict: dict[str, Any]) -> tuple[float, float, int]:
    model = oxyline.load_model(copy.deepcopy(model_dict))
    exact, n = dense_limit(model)
    krylov, _, is_exact = model.network.rk4_stability_limit(method="krylov")
    assert not is_exact
    # conservative: never above the dense limit (1e-6: LAPACK and faer round the eigenvalues
    # differently); tight: the core stops when the residual push changes the limit < 0.1 %,
    # 3 % leaves room for a clustered top of the spectrum
    assert krylov <= exact * (1 + 1e-6), (n, krylov, exact)
    assert krylov >= 0.97 * exact, (n, krylov, exact)
    return krylov, exact, n


@pytest.mark.parametrize("case", [
    pytest.param(lambda: chain(30), id="chain-120"),
    pytest.param(lambda: tree(6), id="tree-221"),
    # shipped, 687 unknowns: the power iteration reported 2.18e-5 s for it
    pytest.param(lambda: oxyline.catalogue.load_dict("circle-of-willis"), id="circle-of-willis"),
])
def test_krylov_limit_matches_dense_eigenvalues(case: Any) -> None:
    check(case())


@pytest.mark.slow
@pytest.mark.parametrize("case", [
    pytest.param(lambda: chain(150), id="chain-600"),
    # shipped, 1,085 unknowns: the power iteration reported 6.5e-6 s for it
    pytest.param(lambda: oxyline.catalogue.load_dict("matthys37"), id="matthys37"),
    pytest.param(lambda: refined("circle-of-willis", 0.01), id="circle-of-willis-10mm"),
    pytest.param(lambda: chain(600), id="chain-2400"),
    pytest.param(lambda: tree(9), id="tree-2044"),
    pytest.param(lambda: refined("circle-of-willis", 0.003), id="circle-of-willis-fine"),
    pytest.param(lambda: chain(1250, wiggle=False), id="chain-5000"),
])
def test_krylov_limit_matches_dense_eigenvalues_large(case: Any) -> None:
    check(case())


@pytest.mark.parametrize("case", [
    pytest.param(lambda: chain(30), id="chain-120"),
    pytest.param(lambda: chain(200, wiggle=False), id="chain-800"),
    pytest.param(lambda: tree(6), id="tree-221"),
    pytest.param(lambda: tree(8), id="tree-1020"),
    pytest.param(lambda: oxyline.catalogue.load_dict("circle-of-willis"), id="circle-of-willis"),
    pytest.param(lambda: oxyline.catalogue.load_dict("matthys37"), id="matthys37"),
])
def test_the_cheap_step_ceiling_is_above_the_dense_limit(case: Any) -> None:
    """`method: auto` skips the spectrum probe of a large circuit where even an upper bound of
    the stable step leaves the explicit pair dearer: that bound (a few power iterations, no
    eigen-iteration) must lie above the largest stable RK4 step of the dense eigenvalues
    (LAPACK, independent of the core), or `auto` could refuse the pair where it wins, and
    within 8x of it to be of use (its margin for a non-normal operator is 2, the power
    iteration's estimate of the spectral radius a little below it)."""
    model = oxyline.load_model(copy.deepcopy(case()))
    exact, n = dense_limit(model)
    ceiling = model.network.rk4_step_ceiling()
    assert exact <= ceiling <= 8.0 * exact, (n, ceiling, exact)


def test_adding_vessels_to_a_chain_keeps_the_limit() -> None:
    """The limit is set by the stiffest segments: 10 more vessels of the same kind leave it
    nearly unchanged (the taper makes the last vessels a little narrower). 145 vessels (580
    unknowns) take the dense branch, 155 (620) the Krylov one: the power iteration dropped the
    limit 70x across this threshold."""
    base = oxyline.load_model(chain(145, wiggle=False)).network.rk4_stability_limit()[0]
    more = oxyline.load_model(chain(155, wiggle=False)).network.rk4_stability_limit()[0]
    assert 0.9 < more / base < 1.1, (base, more)
    assert more == oxyline.load_model(chain(155, wiggle=False)).network.rk4_stability_limit(
        method="krylov")[0]


def test_auto_uses_krylov_above_600_unknowns_and_validate_reports_it() -> None:
    model = oxyline.load_model(chain(200))  # 800 differential unknowns
    dt_max, _, exact = model.network.rk4_stability_limit()
    assert not exact
    s = model.summary()
    assert s["rk4_dt_max"] == dt_max and not s["rk4_limit_exact"]
    res = oxyline.simulate(model, method="rk4", cycles=1, output_every=0.01)
    dt = res.settings["dt"]
    assert res.settings["rk4_dt_max"] == dt_max
    # the automatic step: half the corrected limit, shortened to a whole number of steps per
    # 10 ms output interval (so within a factor (k+1)/k of it, k >= 1 steps)
    assert 0.25 * dt_max <= dt <= 0.5 * dt_max * (1 + 1e-9), (dt, dt_max)


def test_method_is_checked() -> None:
    with pytest.raises(ValueError, match="method 'qr'"):
        oxyline.load_model(chain(3)).network.rk4_stability_limit(method="qr")


def test_stiff_oxygen_wall_exchange_stays_finite_under_rk4() -> None:
    """k = 30 m/s in a 3 mm tube is an exchange rate 2k/r = 2e4 /s; RK4's
    automatic step (7.7e-4 s from the flow alone) gave NaN O2 columns. The step now keeps that
    rate at half RK4's real-axis limit 2.785, and every O2 output is finite."""
    model = oxyline.load_model(_stiff_tube())
    res = oxyline.simulate(model, method="rk4", cycles=1, output_every=0.01)
    # 1 %: the compliant volumes at the steady pressure differ slightly from pi r^2 dx
    assert res.settings["dt"] <= 0.5 * 2.785 / (2 * 30.0 / 3e-3) * 1.01
    po2 = np.asarray(res.segment_po2)
    assert np.isfinite(po2).all()
    assert 55 * 0.99 < po2.min() and po2.max() < 85 * 1.01  # between wall and inlet PO2


def _stiff_tube(k: float = 30.0) -> dict:
    return {
        "name": "stiff", "period": 1.0,
        "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 10, "length": 0.1,
                     "radius": 3e-3, "wall_thickness": 1e-3, "youngs_modulus": 4e5}],
        "boundary_conditions": {"in": {"type": "flow", "value": 5e-6},
                                "out": {"type": "resistance", "resistance": 1e8}},
        "oxygen": {"inlet": {"po2": 85.0},
                   "wall": {"model": "mass-transfer", "k": k, "po2": 55}}}


def test_a_user_rk4_step_above_the_species_limit_is_refused_naming_species_and_vessel() -> None:
    """a user step stable for the flow (7.7e-4 s) but not for the O2 wall
    exchange: rate 2k/r = 2e4 /s (1 %: the compliant volume at the steady pressure), RK4's
    real-axis limit 2.785 / rate = 1.40e-4 s. Before, the run wrote NaN (then stopped with a
    SolverError); now it is refused before the first step, like the flow's own limit."""
    with pytest.raises(oxyline.UnstableTimeStep,
                       match=r"time step 7.692e-4 s is unstable for rk4: the largest stable step "
                             r"is 1.40\de-4 s, set by species 'o2' in vessel 'tube' \(wall "
                             r"exchange and decay rate 1.98\d+e4 1/s\)"):
        oxyline.simulate(_stiff_tube(), method="rk4", dt=1 / 1300, cycles=1, output_every=0.01)
    # a step inside the limit runs, finite
    res = oxyline.simulate(_stiff_tube(), method="rk4", dt=1e-4, cycles=1, output_every=0.01)
    assert np.isfinite(np.asarray(res.segment_po2)).all()
    # generalized-alpha's implicit transport has no such limit
    oxyline.simulate(_stiff_tube(), method="generalized-alpha", dt=1 / 1300, cycles=1,
                     output_every=0.01)


def test_non_finite_species_is_a_typed_error_with_the_partial_result(tmp_path) -> None:
    """A non-finite species amount stops the run with a SolverError naming the species, the
    vessel (by name), the cell's node and the time, with the partial result attached, instead
    of NaN columns. Deterministic trigger: a checkpoint whose O2 amount in one cell of the tube
    is NaN, resumed (any step size now refused up front would have to get there first)."""
    ck = tmp_path / "run.ckpt"
    oxyline.simulate(_stiff_tube(1e-4), method="rk4", cycles=2, output_cycles="all",
                     checkpoint=ck, checkpoint_every="1 cycles")
    with np.load(ck) as z:
        arrays = {k: np.array(z[k]) for k in z.files}
    arrays["z"][5] = np.nan  # the amount of O2 in cell 5 (of the tube's 10 segments)
    with open(ck, "wb") as f:
        np.savez(f, **arrays)
    with pytest.raises(oxyline.SolverError,
                       match=r"species 'o2': amount NaN in vessel 'tube', the cell of node "
                             r"'.+' \(t = 1.00\d+ s\)") as info:
        oxyline.resume(ck)
    part = info.value.result
    assert part is not None and not part.complete and part.time.size >= 1001
