"""The default wall closure since the inlet-renewal fit, `graetz` with `flow: inlet-renewal` (the Graetz
law of the net mean flow plus the inlet renewal by the Womersley profile's near-wall backward
excursion, docs/physics.md §3.6), wired into runs: against the outlet-independent 2-D reference
(the tube continued downstream beyond the backflow's excursion, uptake over the vessel's own
length, docs/validation-oxygen.md §13) stored in tests/data/oxygen_2d_extended.json, against the
law's formula evaluated independently in Python (scipy Bessel functions, exact harmonics of the
prescribed inflow), and the run's O2 mass balance with both integrators. The 2-D values are
data (the reference solver and its extension are tested in test_reference_axisymmetric.py);
only the 1-D model runs here."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import oxyline

pytest.importorskip("scipy")

from validation.closures import (
    heldout_rows,
    inlet_renewal_uptake,
    one_d,
    one_d_run,
    paper_rows,
)

EXTENDED = {r["row"]: r for r in json.loads(
    (Path(__file__).parent / "data" / "oxygen_2d_extended.json").read_text())["rows"]}
DEFAULT = {"model": "graetz"}  # flow: inlet-renewal is the default


def _worst(rows) -> tuple[float, str]:
    worst, name_worst = 0.0, ""
    for name, case, flow in rows:
        err = one_d(case, flow, DEFAULT)[0] / EXTENDED[name]["womersley_extended"] - 1
        if abs(err) > abs(worst):
            worst, name_worst = err, name
    return worst, name_worst


def test_the_default_on_held_out_vessels_against_the_outlet_independent_reference() -> None:
    """The 20 held-out vessels (none used to fit the law's constant A): the issue-12 target of
    2 % on the cycle-mean wall uptake. Measured worst in docs/validation-oxygen.md §13; the
    reference is converged to ~0.1 % (§1.2, §11) and independent of the outlet to < 0.1 %
    (§13), so 2 % is the target itself, not a loosened tolerance."""
    worst, name = _worst(heldout_rows())
    assert abs(worst) < 0.02, (name, worst)


def test_the_default_on_the_paper_examples_and_reversal_cases() -> None:
    """The 27 rows of §2 (the three paper examples, Womersley 2–15, reversal 0–30 %): within
    2 % of the outlet-independent reference. A was fitted on these rows against the 'profile'
    reference and not re-fitted; this guards the wiring on the fit set."""
    worst, name = _worst(paper_rows())
    assert abs(worst) < 0.02, (name, worst)


def test_the_run_follows_the_law_of_the_pure_formula() -> None:
    """The wired closure (harmonics measured by the flow-only first pass, the Womersley wall
    shear by the core's Bessel recurrence, the Graetz law of each segment's net mean flow)
    against the same law emulated in Python (the prescribed inflow's exact harmonics, scipy's
    Bessel functions, the net-mean factor (⟨Q⟩/⟨|Q|⟩)^{1/3} on the cycle-mean Graetz law) on
    the aortic example and the two held-out vessels with the largest renewal. Tolerance 0.3 %:
    the emulation's Lévêque-scaled net-mean factor differs from the exact Graetz law of ⟨Q⟩ by
    < 0.1 % at these x* (docs/validation-oxygen.md §2), the first pass's harmonics from the
    exact ones by its time step."""
    rows = [r for r in paper_rows() if r[0].startswith("straight: example")]
    rows += [r for r in heldout_rows() if r[0].startswith(("ascending aorta at", "pulmonary"))]
    for name, case, flow in rows:
        wired = one_d(case, flow, DEFAULT)[0]
        emulated = inlet_renewal_uptake(case, flow)
        assert wired / emulated - 1 == pytest.approx(0.0, abs=3e-3), name


@pytest.mark.parametrize("method", ["generalized-alpha", "rk4"])
def test_both_integrators_keep_the_mass_balance_and_the_law(method: str) -> None:
    """The aortic example with the default closure under each integrator: the O2 mass balance
    (inflow − outflow − wall uptake − change of the stored amount, the residual the result
    reports) closes to 1e-9 of the inflow (the conservative transport is exact to round-off),
    the cycle-mean uptake is within the 2 % target of the outlet-independent reference, and
    the two integrators agree to 0.5 % (their flows differ by their truncation errors; the
    first pass is the same implicit pass for both)."""
    name, case, flow = next(r for r in paper_rows() if r[0].startswith("straight: example"))
    res = one_d_run(case, flow, DEFAULT, method=method)
    mb = res.o2_mass_balance
    inflow = np.abs(np.asarray(mb["inflow"])).max()
    assert np.abs(np.asarray(mb["residual"])).max() < 1e-9 * inflow
    up = one_d(case, flow, DEFAULT, method=method)[0]
    assert abs(up / EXTENDED[name]["womersley_extended"] - 1) < 0.02
    ref = one_d(case, flow, DEFAULT, method="generalized-alpha")[0]
    assert up / ref - 1 == pytest.approx(0.0, abs=5e-3)


def test_the_wired_law_in_a_reversing_tube_is_the_closed_form() -> None:
    """A tube carrying Q(t) = m + a sin 2πt (a > m: reversal; Womersley 4.1) with the default
    wall and a tiny enhancement (the PO2 stays at the inlet value to ~1e-6, so the uptake is
    ε Σ G_j α ΔP). Expected, independently of the core: the backward wall strain B of the
    Womersley wall shear γ̄ + Re(Q̂ s(α) e^{iωt})/(πR³) with s(α) from scipy's Bessel
    functions, G_r = A 2πR D B^{3/2}/sqrt(γ̄T), and per segment min(G_j(m)(1 + G_r/ΣG(m)),
    complete renewal 2 sqrt(D/(πT)) × area) with the Graetz θ_m of the 2-D reference's exact
    x-marching. Tolerance 2e-4:
    the first pass's harmonic (its time step 2e-4 of the period), B sampled 20,000 times, θ_m
    to 1e-7."""
    from scipy import special
    from test_oxygen_wall_flux import AREA, LENGTH, N, R, tube

    from validation.axisymmetric import ConstantPO2, Grid, Tube, richardson, steady_march
    from validation.closures import INLET_RENEWAL_A

    def _graetz_theta(xs: np.ndarray) -> np.ndarray:
        # θ_m by the reference's exact x-marching, Richardson from 400/800 cells (< 1e-7)
        runs = [steady_march(Tube(radius=R, length=LENGTH), ConstantPO2(0.0), xs, Grid(radial=n))
                for n in (400, 800)]
        return richardson(runs[0].theta, runs[1].theta)

    m_, a, d, eps, alpha, nu = 2e-6, 5e-6, 1.2e-9, 1e-3, 1.4e-3, 3.5e-3 / 1050.0
    oxygen = {"inlet": {"po2": 85.0}, "diffusivity": d, "solubility": alpha,
              "wall": {"model": "graetz", "po2": 60.0, "enhancement": eps}}
    flow = {"fourier": {"period": 1.0, "mean": m_, "sin": [a]}}
    res = oxyline.simulate(tube(oxygen=oxygen, flow=flow, cycles=2),
                           method="generalized-alpha", dt=2e-4, output_every=0.1)
    wom = R * math.sqrt(2 * math.pi / nu)
    z = wom * np.exp(0.75j * math.pi)
    j0, j1 = special.jv(0, z), special.jv(1, z)
    slope = -(z * j1 / j0) / (1.0 - 2.0 * j1 / (z * j0))
    t = np.linspace(0.0, 1.0, 20000, endpoint=False)
    gamma = 4 * m_ / (math.pi * R**3) + np.real(-1j * a / (math.pi * R**3) * slope
                                                  * np.exp(2j * math.pi * t))
    b = float(np.maximum(-gamma, 0.0).mean())
    g_r = INLET_RENEWAL_A * 2 * math.pi * R * d * b**1.5 / math.sqrt(4 * m_ / (math.pi * R**3))
    mean_abs = 2 / math.pi * (math.sqrt(a * a - m_ * m_) + m_ * math.asin(m_ / a))
    x = np.linspace(0.0, LENGTH, N + 1)

    def seg_laws(q: float) -> np.ndarray:
        theta = np.concatenate([[1.0], _graetz_theta(math.pi * d * x[1:] / (4 * q))])
        return q * -np.diff(np.log(theta))

    g_net, g_abs = seg_laws(m_), seg_laws(mean_abs)
    renewed = 2 * math.sqrt(d / math.pi) * AREA  # complete renewal every period (T = 1 s)
    g = np.minimum(g_net * (1 + g_r / g_net.sum()), np.maximum(renewed, g_abs))
    expected = eps * g.sum() * alpha * (85.0 - 60.0)
    assert g_r > 0.01 * g_net.sum()  # the renewal matters here (2 %), the cap does not bind:
    assert (g < renewed).all()
    np.testing.assert_allclose(res.wall_o2_flux[:, 0], expected, rtol=2e-4)


def test_the_previous_default_stays_selectable_by_name() -> None:
    """`flow: forward-mean` still gives the earlier law by name: on the aortic example
    −0.12 % of the outlet-independent reference (docs/validation-oxygen.md §13; ± 0.1 %: the
    1-D run is deterministic, the margin absorbs platform round-off over 12 cycles), and the
    ascending aorta at exercise still shows its −7.7 % miss there, which the default removes."""
    name, case, flow = next(r for r in paper_rows() if r[0].startswith("straight: example"))
    old = one_d(case, flow, {"model": "graetz", "flow": "forward-mean"})[0]
    assert old / EXTENDED[name]["womersley_extended"] - 1 == pytest.approx(-0.0012, abs=1e-3)
    name, case, flow = next(r for r in heldout_rows() if r[0].startswith("ascending aorta at"))
    old = one_d(case, flow, {"model": "graetz", "flow": "forward-mean"})[0]
    assert old / EXTENDED[name]["womersley_extended"] - 1 == pytest.approx(-0.0773, abs=1e-3)


def test_an_unknown_flow_name_is_a_typed_error() -> None:
    from test_oxygen_wall_flux import tube

    oxygen = {"inlet": {"po2": 85.0}, "wall": {"model": "graetz", "po2": 60.0,
                                               "flow": "inlet-renewl"}}
    with pytest.raises(oxyline.ModelError, match="flow must be one of.*inlet-renewal"):
        oxyline.load_model(tube(oxygen=oxygen, cycles=1))
