"""Oxygen and solute transport through the Python API (docs/physics.md §2.5, §4, §5, §6).

Expected values are closed forms of the discrete upwind scheme, continuous solutions, spec
numbers or conservation laws; none is an earlier output of oxyline.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from conftest import tube
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.special import gammainc

import oxyline
from oxyline import catalogue

MMHG = 133.322368
ALPHA = 1.40e-3  # mol m^-3 mmHg^-1


# ---------------------------------------------------------------------------------------------
# second species with first-order decay in steady plug flow ("must show" 3)

@pytest.mark.parametrize("method", ["generalized-alpha", "auto"])
def test_decay_in_steady_plug_flow_converges_to_the_exponential(method: str) -> None:
    lam, r, length, q = 0.5, 3e-3, 0.1, 2e-6
    tau = math.pi * r * r * length / q  # transit time
    exact = math.exp(-lam * tau)
    errors = []
    for n in (10, 20, 40, 80):
        sp = [{"name": "drug", "decay": lam, "inlet": {"concentration": 1.0}, "initial": 1.0}]
        res = oxyline.simulate(tube(n, sp), method=method, output_every=0.1)
        ratio = res.drug_concentration_out[-1, 0] / 1.0
        # the scheme's steady state is exactly the tanks-in-series law (1 + λτ/N)^-N
        assert ratio == pytest.approx((1.0 + lam * tau / n) ** -n, rel=1e-10)
        errors.append(ratio - exact)
    assert all(e > 0 for e in errors)
    for a, b in itertools.pairwise(errors):
        assert a / b == pytest.approx(2.0, rel=0.05)  # first order
    assert errors[0] == pytest.approx(exact * (lam * tau) ** 2 / (2 * 10), rel=0.05)


def test_linearized_hemoglobin_slows_the_decay_by_the_capacity_ratio() -> None:
    """Linear binding C_t = (1 + K)c + b: the steady cell balance gives
    θ_N = (1 + St/(N (1 + K)))^-N (docs/physics.md §4.4 with E_Hb = 1, discrete form)."""
    n, r, length, q, k = 9, 1.5e-3, 0.03456, 1.6e-6, 2.456094800800854e-3
    st_number = k * 2 * math.pi * r * length / q  # 0.5
    ox = {"inlet": {"po2": 85.0}, "hemoglobin": "linearized",
          "linearized": {"p_low": 48.0, "p_high": 85.0},
          "wall": {"model": "mass-transfer", "k": k, "po2": 48.0}}
    res = oxyline.simulate(tube(n, oxygen=ox, radius=r, length=length, flow=q), output_every=0.1)
    h = 1.34 * 150 / 22.414

    def s(p: float) -> float:
        return p**2.7 / (p**2.7 + 26.8**2.7)

    kbar = h * (s(85.0) - s(48.0)) / (ALPHA * (85.0 - 48.0))
    assert kbar == pytest.approx(22.4, abs=0.05)  # docs/physics.md §3.4
    theta = (res.po2_out[-1, 0] - 48.0) / (85.0 - 48.0)
    assert theta == pytest.approx((1 + st_number / (n * (1 + kbar))) ** -n, rel=1e-9)
    # without haemoglobin the same tube gives docs/physics.md §6(b)'s discrete value
    ox["hemoglobin"] = "none"
    res = oxyline.simulate(tube(n, oxygen=ox, radius=r, length=length, flow=q), output_every=0.1)
    theta = (res.po2_out[-1, 0] - 48.0) / (85.0 - 48.0)
    assert theta == pytest.approx(0.6147098006316, abs=1e-10)


def test_hill_oxygen_content_and_po2_reporting() -> None:
    """Uniform Hill blood at 85 mmHg in a rigid tube, no wall: PO2 stays 85 mmHg through the
    Newton inversion, and the stored O2 is V0 · C_t(85), C_t(85) = 8.7061 mol/m^3 (physics
    §4.2, 5 digits)."""
    ox = {"inlet": {"po2": 85.0}, "hemoglobin": "hill"}
    m = tube(5, oxygen=ox, flow={"fourier": {"period": 1, "mean": 2e-6, "sin": [3e-6]}},
             cycles=2)
    res = oxyline.simulate(m, method="generalized-alpha", dt=1e-3, output_every=0.05)
    assert np.abs(res.segment_po2 - 85.0).max() < 1e-9
    mb = res.o2_mass_balance
    assert np.abs(mb["residual"]).max() <= 1e-12 * np.abs(mb["inflow"]).max()
    v0 = sum(oxyline.load_model(m).network.circuit()["node_volume"])
    ct = res.species["o2"].balance_data[0, 0] / v0
    assert round(ct, 4) == 8.7061


def test_hill_vessel_end_po2_inverts_the_carried_content() -> None:
    """With Hill blood losing O2 to the wall, each vessel end's PO2 is the Hill inversion of the
    total content its face carries, C_t = flux/Q (physics §4.2: C_t = αP + H S(P), checked in
    numpy). The core reads the upwind node's inversion; the tolerance 1e-10 is that of the
    inversions (1e-10 mmHg Newton, 1e-12 mmHg anchored series), far below P's 48-85 mmHg."""
    ox = {"inlet": {"po2": 85.0}, "hemoglobin": "hill",
          "wall": {"model": "mass-transfer", "k": 2e-3, "po2": 48.0}}
    res = oxyline.simulate(tube(10, oxygen=ox, cycles=2), method="generalized-alpha",
                           dt=1e-3, output_every=0.1)
    h = 1.34 * 150 / 22.414

    def content(p: np.ndarray) -> np.ndarray:
        return ALPHA * p + h * p**2.7 / (p**2.7 + 26.8**2.7)

    drop = res.po2_in[-1, 0] - res.po2_out[-1, 0]
    assert drop > 1.0  # the wall takes a visible share: the ends differ
    for po2, flux, q in ((res.po2_in, res.o2_flux_in, res.flow_in),
                         (res.po2_out, res.o2_flux_out, res.flow_out)):
        ct = flux[1:, 0] / q[1:, 0]
        np.testing.assert_allclose(content(po2[1:, 0]), ct, rtol=1e-10)


def test_hill_bifurcation_keeps_mass_balance_and_the_hill_law_at_every_vessel_end() -> None:
    """A compliant bifurcation (the fused tree step's junction and its binding rows, the
    wall linearised per cell before the elimination) with Hill blood losing O2 to a
    constant-k wall, generalized-α: the stored O2 closes against the boundary, wall and decay
    fluxes to round-off (1e-12 of the inflow), and at both ends of every vessel the reported
    PO2 and the carried content C_t = flux/Q satisfy C_t = αP + H Pⁿ/(Pⁿ + P50ⁿ) (physics
    §4.2, checked in numpy) to the inversions' tolerance (1e-10 mmHg Newton, 1e-12 mmHg
    anchored series)."""
    geo = {"wall_thickness": 5e-4, "youngs_modulus": 4e5}
    vessels = [{"name": "trunk", "from": "in", "to": "j", "segments": 8, "length": 0.06,
                "radius": 3e-3, **geo},
               {"name": "a", "from": "j", "to": "out_a", "segments": 6, "length": 0.05,
                "radius": 2.4e-3, **geo},
               {"name": "b", "from": "j", "to": "out_b", "segments": 5, "length": 0.04,
                "radius": 2.0e-3, **geo}]
    m = {"period": 1.0, "vessels": vessels,
         "boundary_conditions": {
             "in": {"type": "flow", "fourier": {"period": 1, "mean": 6e-6, "sin": [3e-6]}},
             "out_a": {"type": "resistance", "resistance": 2.9e9},
             "out_b": {"type": "resistance", "resistance": 4.7e9}},
         "oxygen": {"inlet": {"po2": 95.0}, "hemoglobin": "hill",
                    "wall": {"model": "mass-transfer", "k": 2e-3, "po2": 40.0}}}
    res = oxyline.simulate(m, method="generalized-alpha", dt=1e-3, cycles=2, output_every=0.02)
    mb = res.o2_mass_balance
    assert np.abs(mb["residual"]).max() <= 1e-12 * np.abs(mb["inflow"]).max()
    h = 1.34 * 150 / 22.414

    def content(p: np.ndarray) -> np.ndarray:
        return ALPHA * p + h * p**2.7 / (p**2.7 + 26.8**2.7)

    assert (res.po2_in[-1] - res.po2_out[-1]).min() > 1.0  # every vessel loses visibly
    for po2, flux, q in ((res.po2_in, res.o2_flux_in, res.flow_in),
                         (res.po2_out, res.o2_flux_out, res.flow_out)):
        assert (q[1:] > 0).all()
        np.testing.assert_allclose(content(po2[1:]), flux[1:] / q[1:], rtol=1e-10)


def test_flow_only_results_are_unchanged_by_transport() -> None:
    m = catalogue.load("paper-bifurcated")
    with_o2 = oxyline.simulate(m, cycles=2, method="generalized-alpha", dt=1e-3)
    plain = oxyline.simulate(m, cycles=2, method="generalized-alpha", dt=1e-3, transport=False)
    assert np.array_equal(with_o2.data, plain.data)
    assert not plain.species


@pytest.mark.parametrize("name", ["paper-straight", "paper-curved", "paper-bifurcated"])
def test_paper_examples_run_with_exact_mass_balance(name: str) -> None:
    m = catalogue.load(name)
    res = oxyline.simulate(m, cycles=3)
    mb = res.o2_mass_balance
    assert abs(mb["residual"][-1]) <= 1e-12 * mb["inflow"][-1]
    # PO2 stays between the wall and the inlet values; uptake is positive
    p_in = m.source["oxygen"]["inlet"]["po2"]
    p_w = m.source["oxygen"]["wall"]["po2"]
    assert np.all(res.segment_po2 <= p_in + 1e-9) and np.all(res.segment_po2 >= p_w)
    assert np.all(res.wall_o2_flux > 0)
    ds = res.to_xarray()
    for v in ("po2_in", "po2_out", "o2_flux_in", "o2_flux_out", "wall_o2_flux",
              "tl_resistance", "tl_inductance", "o2_mass_residual"):
        assert v in ds


def test_straight_vessel_bulk_drop_matches_the_leveque_estimate() -> None:
    """docs/physics.md §3.5: with the cycle-mean flow of 20 mL/s, the aortic bulk PO2 drop is 0.072 mmHg
    (no-Hb Lévêque, 85 → 60 mmHg wall)."""
    res = oxyline.simulate(catalogue.load("paper-straight"))
    drop = 85.0 - res.po2_out[:, 0].mean()
    assert drop == pytest.approx(0.072, rel=0.06)


def test_tl_elements_follow_the_paper_definitions() -> None:
    """L_i = −dx/v and the identity L_i J_i = −N_i for forward flow (docs/physics.md §2.6)."""
    m = tube(10, oxygen={"inlet": {"po2": 85}}, compliant=True,
             flow={"fourier": {"period": 1, "mean": 2e-6, "sin": [1e-6]}}, cycles=4)
    res = oxyline.simulate(m, method="rk4", output_every=2e-3)
    seg_v = res.segment_flow / (math.pi * 3e-3**2)
    rel = np.abs(res.tl_inductance / (-0.01 / seg_v) - 1)
    assert np.nanmax(rel) < 0.02  # A(t) = V(t)/dx differs from π r0² by C·P/V0 only
    # R = dL/dt: compare with the finite difference of the recorded L
    L = res.tl_inductance[:, 4]
    dLdt = np.gradient(L, res.time)
    R = res.tl_resistance[:, 4]
    # (the start-up LC ringing has decayed after 3 cycles; centred differences are O(h²))
    assert np.allclose(R[2:-2], dLdt[2:-2], rtol=1e-3, atol=1e-3 * np.abs(R).max())


def test_model_errors_name_the_key() -> None:
    with pytest.raises(oxyline.ModelError, match="oxygen.*unknown key 'inlett'"):
        oxyline.load_model(tube(3, oxygen={"inlett": {"po2": 85}}))
    with pytest.raises(oxyline.ModelError, match="unknown wall model"):
        oxyline.load_model(tube(3, oxygen={"inlet": {"po2": 85}, "wall": {"model": "magic"}}))
    with pytest.raises(oxyline.ModelError, match="vessel 'nope'"):
        oxyline.load_model(tube(3, oxygen={"inlet": {"po2": 85},
                                           "per_vessel": {"nope": {"wall": "none"}}}))
    with pytest.raises(oxyline.ModelError, match="decay"):
        oxyline.load_model(tube(3, species=[{"name": "x", "inlet": {"concentration": 1},
                                             "decay": -1}]))


def test_bolus_front_travels_at_the_mean_velocity() -> None:
    """A gamma-variate bolus: the outlet curve's first moment is the inlet's plus the transit
    time (upwind cells conserve the first moment of a passive tracer in steady flow)."""
    r, length, q = 3e-3, 0.1, 2e-6
    tau = math.pi * r * r * length / q
    sp = [{"name": "dye", "initial": 0.0,
           "inlet": {"bolus": {"gamma_variate": {"k": 1.0, "t0": 1.0, "a": 2.0, "b": 0.5}}}}]
    m = tube(20, sp)
    res = oxyline.simulate(m, method="generalized-alpha", dt=2e-3, output_cycles="all",
                           output_every=2e-3, cycles=20)
    t = res.time
    c_in, c_out = res.dye_concentration_in[:, 0], res.dye_concentration_out[:, 0]
    m_in = np.trapezoid(t * c_in, t) / np.trapezoid(c_in, t)
    m_out = np.trapezoid(t * c_out, t) / np.trapezoid(c_out, t)
    # c_in is the value at the inlet face (the prescribed bolus), so the curve passes all 20
    # cells of the tube: the shift is the whole transit time V/Q (it read 19/20 of it while
    # c_in was the first cell's value)
    assert m_out - m_in == pytest.approx(tau, rel=2e-2)


# ---------------------------------------------------------------------------------------------
# property test: random trees/loops, reversing pulsatile inflow, random closures

WALLS = ["none", "mass-transfer", "leveque", "leveque-inst", "graetz", "permeability"]


def wall_spec(kind: str, po2: float) -> dict:
    if kind == "none":
        return {"model": "none"}
    if kind == "mass-transfer":
        return {"model": "mass-transfer", "k": 2e-5, "po2": po2}
    if kind == "leveque":
        return {"model": "leveque", "po2": po2, "enhancement": 50.0}
    if kind == "leveque-inst":
        return {"model": "leveque", "po2": po2, "shear": "instantaneous", "enhancement": 50.0}
    if kind == "graetz":
        return {"model": "graetz", "po2": po2, "enhancement": 50.0}
    return {"model": "permeability", "permeability": 1e-4, "po2": po2}


@st.composite
def networks(draw: st.DrawFn) -> dict:
    n_vessels = draw(st.integers(1, 6))
    vessels = []
    nodes = ["n0"]
    internal = []

    def geometric(name: str, a: str, b: str) -> dict:
        return {"name": name, "from": a, "to": b, "length": draw(st.floats(0.02, 0.08)),
                "radius": draw(st.floats(1.5e-3, 4e-3)), "wall_thickness": 5e-4,
                "youngs_modulus": draw(st.floats(5e5, 2e6)), "segments": draw(st.integers(1, 3))}

    vessels.append(geometric("v0", "in", "n0"))
    leaves = {"n0"}
    for i in range(1, n_vessels):
        parent = draw(st.sampled_from(sorted(set(nodes))))
        child = f"n{i}"
        vessels.append(geometric(f"v{i}", parent, child))
        nodes.append(child)
        leaves.discard(parent)
        if parent not in internal:
            internal.append(parent)
        leaves.add(child)
    # loops: extra vessels between distinct internal nodes (anastomoses)
    n_loops = draw(st.integers(0, 2)) if len(internal) >= 2 else 0
    for k in range(n_loops):
        a, b = draw(st.permutations(internal))[:2]
        kind = draw(st.sampled_from(["geometric", "resistor"]))
        if kind == "geometric":
            vessels.append(geometric(f"loop{k}", a, b))
        else:  # a pure resistor: both its ends are shared, so no mixing-only node appears
            vessels.append({"name": f"loop{k}", "from": a, "to": b,
                            "lumped": {"resistance": draw(st.floats(1e7, 1e9))}})
    mean = draw(st.floats(1e-6, 8e-6))
    amp = draw(st.floats(0.5, 2.0)) * mean  # > mean: reversal
    bcs: dict = {"in": {"type": "flow", "fourier": {"period": 1.0, "mean": mean,
                                                    "sin": [amp], "cos": [0.3 * amp]}}}
    for leaf in sorted(leaves):
        if draw(st.booleans()):
            bcs[leaf] = {"type": "resistance", "resistance": draw(st.floats(5e8, 3e9))}
        else:
            bcs[leaf] = {"type": "rcr", "proximal_resistance": draw(st.floats(1e8, 5e8)),
                         "capacitance": draw(st.floats(1e-10, 1e-9)),
                         "distal_resistance": draw(st.floats(5e8, 2e9))}
    p_w = draw(st.floats(10.0, 80.0))
    oxygen = {"inlet": {"fourier": {"period": 1.0, "mean": 85.0, "sin": [5.0]}},
              "hemoglobin": draw(st.sampled_from(["none", "hill", "linearized"])),
              "wall": wall_spec(draw(st.sampled_from(WALLS)), p_w),
              "reference_pressure": 60.0}
    if len(vessels) > 1 and draw(st.booleans()):
        oxygen["per_vessel"] = {"v1": {"wall": wall_spec(draw(st.sampled_from(WALLS)), p_w)}}
    backflow_c = draw(st.sampled_from([None, 0.5]))
    species = [{"name": "tracer", "decay": draw(st.sampled_from([0.0, 0.3])),
                "inlet": {"concentration": 1.0}, "initial": 0.0,
                "binding": draw(st.sampled_from(["none", {"kind": "linear", "partition": 1.5}]))}]
    if backflow_c is not None:
        species[0]["backflow"] = {leaf: {"concentration": backflow_c} for leaf in sorted(leaves)}
    method = draw(st.sampled_from(["rk4", "generalized-alpha"]))
    return {"period": 1.0, "vessels": vessels, "boundary_conditions": bcs, "oxygen": oxygen,
            "species": species,
            "simulation": {"cycles": 2, "method": method,
                           "dt": 1e-3 if method == "generalized-alpha" else "auto"}}


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(networks())
def test_property_mass_balance_and_positivity(model: dict) -> None:
    check_mass_balance_and_positivity(oxyline.simulate(model, output_every=0.01))


def check_mass_balance_and_positivity(res: oxyline.Result) -> None:
    """Every species: balance residual <= 1e-10 of the inflow (or initial amount), and no
    negative concentration beyond round-off."""
    for name, sp in res.species.items():
        mb = sp.mass_balance
        scale = max(abs(mb["inflow"]).max(), sp.initial_stored, 1e-300)
        assert np.abs(mb["residual"]).max() <= 1e-10 * scale, (name, mb["residual"][-1], scale)
        c = sp.concentration
        cmax = np.nanmax(np.abs(c))
        assert np.nanmin(c) >= -1e-12 * max(cmax, 1e-300), (name, np.nanmin(c))


@pytest.mark.parametrize("binding", ["none", "hill"])
def test_instantaneous_shear_equals_cycle_mean_in_steady_flow(binding: str) -> None:
    """With a constant inflow |Q(t)| is its cycle mean, so both Lévêque shear options give the
    same field (they are evaluated by different code paths)."""
    out = []
    for shear in ("cycle-mean", "instantaneous"):
        ox = {"inlet": {"po2": 85.0}, "hemoglobin": binding,
              "wall": {"model": "leveque", "po2": 48.0, "shear": shear, "enhancement": 20.0}}
        res = oxyline.simulate(tube(9, oxygen=ox, radius=1.5e-3, length=0.0346, flow=1.6e-6,
                                    cycles=20), output_every=0.1)
        out.append(res.segment_po2[-1])
    assert np.allclose(out[0], out[1], rtol=1e-12, atol=0)
    assert out[0][-1] < (84.0 if binding == "none" else 84.9)  # a visible uptake


def _mean_abs_flow(model: dict, **overrides: object) -> np.ndarray:
    from oxyline.run import _settings

    m = oxyline.load_model(model)
    raw = m.network.simulate(progress=None, **_settings(m, overrides))
    return np.asarray(raw["transport"]["mean_abs_flow"])


def test_cycle_mean_shear_uses_the_exact_mean_absolute_flow() -> None:
    """The Lévêque cycle-mean closure takes <|Q|> from a flow-only first pass. In a rigid tube
    every branch carries the prescribed inflow Q(t) = m + a sin(2πt) with reversal (a > m),
    whose mean modulus is exactly (2/π)(sqrt(a² − m²) + m asin(m/a))."""
    m_, a = 2e-6, 5e-6
    oxygen = {"inlet": {"po2": 85.0}, "wall": {"model": "leveque", "po2": 60.0}}
    flow = {"fourier": {"period": 1.0, "mean": m_, "sin": [a]}}
    mean_abs = _mean_abs_flow(tube(5, oxygen=oxygen, flow=flow, cycles=2),
                              method="generalized-alpha", dt=2e-4)
    exact = 2 / math.pi * (math.sqrt(a * a - m_ * m_) + m_ * math.asin(m_ / a))
    assert len(mean_abs) == 5
    np.testing.assert_allclose(mean_abs, exact, rtol=1e-6)
    # RK4 runs measure it with an implicit pass at period/2000: compared with a 20x finer
    # implicit pass on a compliant tube (where segment flows differ from the inflow)
    compliant = tube(5, oxygen=oxygen, flow=flow, cycles=3, compliant=True)
    rk4 = _mean_abs_flow(compliant, method="rk4")
    fine = _mean_abs_flow(compliant, method="generalized-alpha", dt=2.5e-5)
    assert np.abs(rk4 / fine - 1).max() < 1e-5
    assert np.abs(rk4 / exact - 1).max() > 1e-4  # the compliance is visible


def test_coarse_first_pass_keeps_the_mean_absolute_flow() -> None:
    """A generalized-α run at the usual step (dt = period/1000) measures <|Q|> in a coarser
    first pass (period/125, run/two_pass.rs `MEAN_FLOW_COARSE_STEPS`). Against independent
    truths: the closed-form mean modulus of the rigid tube's reversing sinusoid (the rectangle
    rule over 125 samples of a smooth |Q| with two kinks: error 2.6e-4, tolerance 1e-3), and on
    the compliant tube a first pass 40× finer than the coarse one (the step's own error, 2.1e-4
    here; the stated bound for the sharper half-sine bench trees is 1.2e-2).
    k ∝ <|Q|>^{1/3}, so k moves by a third of these."""
    m_, a = 2e-6, 5e-6
    oxygen = {"inlet": {"po2": 85.0}, "wall": {"model": "leveque", "po2": 60.0}}
    flow = {"fourier": {"period": 1.0, "mean": m_, "sin": [a]}}
    exact = 2 / math.pi * (math.sqrt(a * a - m_ * m_) + m_ * math.asin(m_ / a))
    rigid = _mean_abs_flow(tube(5, oxygen=oxygen, flow=flow, cycles=2),
                           method="generalized-alpha", dt=1e-3)
    assert np.abs(rigid / exact - 1).max() < 1e-3
    compliant = tube(5, oxygen=oxygen, flow=flow, cycles=3, compliant=True)
    coarse = _mean_abs_flow(compliant, method="generalized-alpha", dt=1e-3)
    fine = _mean_abs_flow(compliant, method="generalized-alpha", dt=2e-4)
    assert np.abs(coarse / fine - 1).max() < 1e-3
    # the coarse pass is not the run's own step: a 1 ms pass would agree with `fine` to ~1e-6
    assert np.abs(coarse / fine - 1).max() > 1e-6


def test_step_response_of_a_rigid_tube_with_rk4_on_the_full_model() -> None:
    """docs/physics.md §6(d) through the whole model: a rigid tube fed by a flow condition is index 2
    as written (the inflow fixes every inductor flow); RK4 makes those flows algebraic and
    integrates the species alone. Outlet = regularised incomplete gamma P(10, v t/dx) to 1e-12
    with dt = 1e-3 s."""
    r, dx, n, v = 8e-3, 0.02, 10, 0.1
    sp = [{"name": "dye", "inlet": {"concentration": 1.0}, "initial": 0.0}]
    m = tube(n, sp, radius=r, length=n * dx, flow=v * math.pi * r * r, cycles=3)
    res = oxyline.simulate(m, method="rk4", dt=1e-3, output_every=0.5, output_cycles="all")
    assert res.settings["method"] == "rk4"
    out = dict(zip(np.round(res.time, 9), res.dye_concentration_out[:, 0], strict=True))
    for t, expected in ((1.0, 0.0318280573), (2.0, 0.5420702855), (3.0, 0.9301463393)):
        assert out[t] == pytest.approx(expected, abs=1e-10)
        assert out[t] == pytest.approx(gammainc(n, v * t / dx), abs=1e-12)
