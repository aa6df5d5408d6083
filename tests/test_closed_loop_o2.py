"""Oxygen around a closed loop (docs/oxygen.md "Oxygen around a closed loop"):
Fick's principle and the loop's exact mass balance at periodic steady state, the lung's
complete-equilibration limit against the Hill curve, and resting physiology in documented
ranges. Coarse steps (4 ms) keep the tests fast; the balances hold for any step."""

from __future__ import annotations

import numpy as np
import pytest

import oxyline
from oxyline import closed_loop
from oxyline.closed_loop import ML_O2


def _model(**changes: object) -> dict:
    """The pool model on the prescribed flow table (the core's balances on known flows)."""
    p = closed_loop.load("closed-loop-o2")
    p["dt"] = 4e-3
    p["flows"] = "table"
    p.update(changes)
    return p


@pytest.fixture(scope="module")
def rest() -> closed_loop.ClosedLoopO2Result:
    return closed_loop.simulate_o2(_model())


def test_fick_principle_holds_at_periodic_steady_state(rest: closed_loop.ClosedLoopO2Result) -> None:
    """Σ VO2 = CO (CaO2 − CvO2) with flow-weighted contents: CaO2 of the blood the left heart
    ejects, CvO2 of the blood the right heart ejects (mixed venous), over the last cycle.
    Between the two ejections the systemic compartments store nothing over a periodic cycle;
    the periodic state is reached to ~1e-13, so Fick holds to 1e-9."""
    r = rest
    q_l = r.flow[:, r.branches.index("ejection_left")]
    q_r = r.flow[:, r.branches.index("ejection_right")]
    c_l = r.total[:, r.compartments.index("left_heart")]
    c_r = r.total[:, r.compartments.index("right_heart")]
    co = q_l.mean()
    assert q_r.mean() == pytest.approx(co, rel=1e-12)
    ca, cv = np.sum(q_l * c_l) / np.sum(q_l), np.sum(q_r * c_r) / np.sum(q_r)
    vo2 = r.vo2.sum(axis=1).mean()
    assert abs(vo2 - co * (ca - cv)) <= 1e-9 * vo2
    # and the lungs take up what the organs consume
    assert r.uptake.sum(axis=1).mean() == pytest.approx(vo2, rel=1e-9)


def test_loop_mass_balance_is_exact_per_step(rest: closed_loop.ClosedLoopO2Result) -> None:
    """No inlet: the loop's O2 changes only by lung uptake − organ consumption, each step."""
    r = rest
    n = np.concatenate([[r.amount_start], r.amount])
    rate = r.uptake.sum(axis=1) - r.vo2.sum(axis=1)
    assert np.max(np.abs(np.diff(n) - r.dt * rate)) <= 1e-13 * n.max()
    # the amount is what the compartments hold
    assert np.allclose(r.amount, np.sum(r.volume * r.total, axis=1), rtol=1e-14)


def test_resting_physiology_in_documented_ranges(rest: closed_loop.ClosedLoopO2Result) -> None:
    """Resting adult (docs/oxygen.md): SaO2 95–98 %, SvO2 70–75 %, VO2 ≈ 250 mL/min (240–260),
    PaO2 85–100 mmHg, PvO2 35–45 mmHg, coronary venous saturation 25–45 % (high extraction)."""
    s = rest.summary()
    assert 0.95 <= s["SaO2"] <= 0.98
    assert 0.70 <= s["SvO2"] <= 0.75
    assert 240 <= s["VO2"] <= 260
    assert 85 <= s["PaO2"] <= 100 and 35 <= s["PvO2"] <= 45
    heart = rest.saturation[:, rest.compartments.index("heart")].mean()
    assert 0.25 <= heart <= 0.45
    assert s["cardiac_output"] == pytest.approx(5.0, rel=1e-12)
    assert sum(s["VO2_organs"].values()) == pytest.approx(s["VO2"], rel=1e-12)


def test_complete_equilibration_gives_the_alveolar_hill_saturation() -> None:
    """With no shunt and a diffusing capacity 1000× resting, end-capillary blood is at the
    alveolar PO2: SaO2 = P_Aⁿ/(P_Aⁿ + P50ⁿ) (Hill), PaO2 = P_A."""
    p = _model()
    p["lungs"].update(shunt_fraction=0.0, diffusing_capacity=21000.0)
    s = closed_loop.simulate_o2(p).summary()
    pa, p50, n = p["lungs"]["alveolar_po2"], p["blood"]["p50"], p["blood"]["hill_n"]
    assert s["SaO2"] == pytest.approx(pa**n / (pa**n + p50**n), rel=1e-9)
    assert s["PaO2"] == pytest.approx(pa, rel=1e-9)


def test_fixed_vo2_is_consumed_exactly() -> None:
    """Fixed-rate organs (vmax with a vanishing km): the total VO2 tends to Σ vmax."""
    p = _model(km=1e-6)
    s = closed_loop.simulate_o2(p).summary()
    target = sum(o["vo2"] for o in p["organs"].values())
    assert s["VO2"] == pytest.approx(target, rel=1e-6)
    assert s["fick_residual"] <= 1e-9
    assert ML_O2 > 0


def test_bad_input_names_the_element() -> None:
    p = _model()
    p["organs"]["brain"]["volume"] = -1.0
    with pytest.raises(oxyline.ModelError, match="compartment 'brain'.*volume"):
        closed_loop.simulate_o2(p)
    p = _model()
    p["organs"]["brain"]["flow_fraction"] = 0.5
    with pytest.raises(oxyline.ModelError, match="flow fractions"):
        closed_loop.simulate_o2(p)
    with pytest.raises(oxyline.ModelError, match="built-in"):
        closed_loop.load("no-such-loop")


def test_external_flow_table_is_balanced_and_used() -> None:
    """A flow table from elsewhere (e.g. a flow run) with small imbalances: the least-norm
    constant corrections close every compartment's volume over the cycle, and the run then
    satisfies Fick's principle as with the built-in table."""
    p = _model()
    base = closed_loop.flow_table(p)
    rng = np.random.default_rng(1)
    noisy = base * (1 + 1e-4 * rng.standard_normal(base.shape))
    res = closed_loop.simulate_o2(p, flows=noisy)
    lay, _ = closed_loop._layout(p)
    comps, branches = lay["compartments"], lay["branches"]
    net = np.zeros(len(comps))
    for b, br in enumerate(branches):
        net[br["from"]] -= res.flow[:, b].sum()
        net[br["to"]] += res.flow[:, b].sum()
    assert np.max(np.abs(net)) <= 1e-12 * base.sum(axis=0).max()
    assert np.max(np.abs(res.flow - noisy)) <= 1e-3 * base.max()  # small corrections only
    assert res.summary()["fick_residual"] <= 1e-9
    with pytest.raises(oxyline.ModelError, match="flows must be"):
        closed_loop.simulate_o2(p, flows=base[:, :3])


def test_heart_driven_loop_keeps_fick_and_the_physiology() -> None:
    """Flows from the native two-ventricle heart (chambers and valves, docs/physics.md §1.8)
    instead of the prescribed table: the heart pumps the documented cardiac output (within
    2 %), the ventricles eject what they receive over the cycle, and Fick's principle, the
    loop's mass balance and the resting ranges hold as with the prescribed flows."""
    res = closed_loop.simulate_o2(_model(heart="two-ventricle"), flows="heart")
    s = res.summary()
    assert s["cardiac_output"] == pytest.approx(5.0, rel=0.02)
    assert s["fick_residual"] <= 1e-9 and s["mass_balance_residual"] <= 1e-13
    assert 0.95 <= s["SaO2"] <= 0.98 and 0.70 <= s["SvO2"] <= 0.75 and 240 <= s["VO2"] <= 260
    q = res.flow[:, res.branches.index("ejection_left")]
    assert q.max() > 3 * q.mean()          # pulsatile ejection through the aortic valve
    assert abs(q.min()) < 0.01 * q.max()   # the valve closes (tanh: a small leak only)


@pytest.fixture(scope="module")
def block() -> tuple[dict, closed_loop.HeartRun, closed_loop.ClosedLoopO2Result]:
    p = closed_loop.load("closed-loop-o2")
    p["dt"] = 4e-3
    res = closed_loop.simulate_o2(p)
    return p, res.heart, res


def test_builtin_is_driven_by_the_svzerod_heart_block(block) -> None:
    """The built-in's default heart is svZeroDSolver's ClosedLoopHeartAndPulmonary
    (docs/physics.md §1.10; docs/oxygen.md): Fick's principle to 1e-9 and the loop's exact
    mass balance on its flows, the resting ranges (SaO2 ≈ 97 %, SvO2 70–75 %, VO2 ≈ 250
    mL/min) and the documented cardiac output (5 L/min within 2 %)."""
    p, _, res = block
    s = res.summary()
    assert p["heart"] == "svzerod-block" and p["flows"] == "heart"
    assert s["fick_residual"] <= 1e-9 and s["mass_balance_residual"] <= 1e-13
    assert 0.95 <= s["SaO2"] <= 0.98 and 0.70 <= s["SvO2"] <= 0.75 and 240 <= s["VO2"] <= 260
    assert 85 <= s["PaO2"] <= 100 and 35 <= s["PvO2"] <= 45
    assert s["cardiac_output"] == pytest.approx(5.0, rel=0.02)


def test_block_flows_conserve_blood_and_its_valves_close(block) -> None:
    """The block's flows over its last (nearly periodic) cycle: each chamber ejects what it
    receives (the cycle means through the four valves, the venous return and the lungs agree
    to the flow run's periodicity, ~1e-4 after 30 cycles: 1e-3), the on/off valves carry no
    flow while closed (exactly 0, never negative), and the left ventricle ejects in a pulse
    (peak > 3× mean)."""
    _, run, _ = block
    mean = {k: float(np.mean(0.5 * (v[1:] + v[:-1]))) for k, v in run.series.items()}
    co = mean["aortic"]
    for k in ("aortic_outflow", "tricuspid", "pulmonary", "mitral", "lungs"):
        assert mean[k] == pytest.approx(co, rel=1e-3), k
    for k in ("aortic", "tricuspid", "pulmonary", "mitral"):
        q = run.series[k]
        assert q.min() >= -1e-4 * q.max() and np.any(q == 0.0), k
    assert run.series["aortic"].max() > 3 * co


def test_anderson_and_newton_shooting_find_the_same_periodic_state() -> None:
    """The periodic state is unique: Anderson acceleration of the cycle map (default) and the
    finite-difference Newton shooting are two independent solvers of Φ(x) = x; both stop when
    a cycle repeats its start to 1e-13, so their recorded cycles agree to ~1e-12 (1e-10
    allowed: the last cycle's contraction), with fewer cycles for Anderson."""
    p = _model()
    a = closed_loop.simulate_o2(p)
    n = closed_loop.simulate_o2(p, shooting="newton")
    assert np.max(np.abs(a.total - n.total)) <= 1e-10 * n.total.max()
    assert a.cycles < n.cycles
    with pytest.raises(oxyline.ModelError, match="shooting"):
        closed_loop.simulate_o2(p, shooting="secant")


def test_heart_choice_is_checked() -> None:
    with pytest.raises(oxyline.ModelError, match="heart must be one of"):
        closed_loop.heart_model(_model(heart="three-ventricle"))
    with pytest.raises(oxyline.ModelError, match="flows must be"):
        closed_loop.simulate_o2(_model(), flows="pump")


def test_heart_driven_o2_step_must_span_whole_flow_steps() -> None:
    """The core averages the heart run's recorded intervals over each O2 step: an O2 step of
    1.5 flow steps is refused as a model error naming both steps."""
    p = _model(heart="two-ventricle")
    p["dt"] = 1.5e-3
    with pytest.raises(oxyline.ModelError, match=r"closed-loop heart: the O2 step 0\.0015 s"):
        closed_loop.simulate_o2(p, flows="heart")


# --- the segment-resolved arterial tree (built-in closed-loop-o2-tree; docs/oxygen.md) ---

def _tree_model(**changes: object) -> dict:
    p = closed_loop.load("closed-loop-o2-tree")
    p["dt"] = 4e-3
    p.update(changes)
    return p


@pytest.fixture(scope="module")
def tree_rest() -> closed_loop.ClosedLoopO2Result:
    return closed_loop.simulate_o2(_tree_model())


def test_tree_fick_principle_counts_the_wall_uptake(
        tree_rest: closed_loop.ClosedLoopO2Result) -> None:
    """Σ organ VO2 + tree wall uptake = CO (CaO2 − CvO2): CaO2 the net content the left heart
    ejects into the tree's root (its O2 flux over its flow; the valve's small backflow carries
    the root's content), CvO2 the right heart's (mixed venous). Between the two ejections the
    tree, organs, veins and right heart store nothing over a periodic cycle (reached to
    ~1e-11: the tree's warm-started Hill inversions), so Fick holds to 1e-9; the lungs take
    up the same total."""
    r = tree_rest
    q = r.tree.inflow
    q_r = r.flow[:, r.branches.index("ejection_right")]
    c_r = r.total[:, r.compartments.index("right_heart")]
    ca, cv = np.sum(r.tree.in_flux) / np.sum(q), np.sum(q_r * c_r) / np.sum(q_r)
    vo2 = r.vo2.sum(axis=1).mean() + r.tree.wall.mean()
    assert r.periodic_error <= 1e-10
    assert abs(vo2 - q.mean() * (ca - cv)) <= 1e-9 * vo2
    assert r.uptake.sum(axis=1).mean() == pytest.approx(vo2, rel=1e-9)
    assert r.summary()["fick_residual"] <= 1e-9


def test_tree_loop_mass_balance_is_exact_per_step(
        tree_rest: closed_loop.ClosedLoopO2Result) -> None:
    """No inlet: the loop's O2 (compartments + the tree's cells) changes only by lung uptake −
    organ VO2 − tree wall uptake, every step; and the tree's own amount changes by exactly
    root inflow − outlet outflow − wall uptake (the transport's invariant, with the fluxes the
    compartments lose and gain)."""
    r, t = tree_rest, tree_rest.tree
    n = np.concatenate([[r.amount_start], r.amount])
    rate = r.uptake.sum(axis=1) - r.vo2.sum(axis=1) - t.wall
    assert np.max(np.abs(np.diff(n) - r.dt * rate)) <= 1e-13 * n.max()
    assert np.allclose(r.amount, np.sum(r.volume * r.total, axis=1) + t.amount, rtol=1e-14)
    tree_rate = t.in_flux - t.out_flux.sum(axis=1) - t.wall
    assert np.max(np.abs(np.diff(t.amount) - r.dt * tree_rate[1:])) <= 1e-13 * n.max()
    # the root carries in the left heart's content at the root's flow
    c_l = r.total[:, r.compartments.index("left_heart")]
    fwd = t.inflow > 0   # (a closing tanh valve leaks back a little: the tree's content)
    assert np.allclose(t.in_flux[fwd], t.inflow[fwd] * c_l[fwd], rtol=1e-12)


def test_tree_resting_physiology_and_po2_along_the_tree(
        tree_rest: closed_loop.ClosedLoopO2Result) -> None:
    """Resting ranges as for the pool model (docs/oxygen.md); the wall takes up O2 (wall PO2
    60 mmHg below the blood's ~95) but little of the arterial supply (≤ 1 % of VO2), so PO2
    falls monotonically, and only slightly, from the root to every outlet."""
    s = tree_rest.summary()
    assert 0.95 <= s["SaO2"] <= 0.98 and 0.70 <= s["SvO2"] <= 0.75
    assert 240 <= s["VO2"] <= 260 and 85 <= s["PaO2"] <= 100 and 35 <= s["PvO2"] <= 45
    assert 0 < s["VO2_tree_wall"] <= 0.01 * s["VO2"]
    assert s["cardiac_output"] == pytest.approx(5.0, rel=0.03)
    along = tree_rest.tree.po2_along()
    for name in ("thoracic_aorta", "iliac", "supra_aortic"):
        assert np.all(np.diff(along[name]) < 0)
    assert along["aortic_root"][0] > along["iliac"][-1] > along["aortic_root"][0] - 2.0
    # each organ is fed by its outlet: O2 delivery ≈ its flow share × CaO2 × CO
    co, ca = s["cardiac_output"], s["CaO2"]
    for k, o in closed_loop.load("closed-loop-o2-tree")["organs"].items():
        assert s["DO2_organs"][k] == pytest.approx(o["flow_fraction"] * co * ca, rel=0.03)


def test_po2_along_is_the_recorded_segments_cycle_mean(
        tree_rest: closed_loop.ClosedLoopO2Result) -> None:
    """The core's cycle means against numpy's mean of the recorded [step, segment] PO2, grouped
    by the segments' vessel names: the same additions in the same order (1e-12 relative allows
    any other summation order); every vessel of the tree once, its segments in flow order;
    ``vessels`` selects."""
    t = tree_rest.tree
    mean = t.po2.mean(axis=0)
    vessels = list(dict.fromkeys(s.rsplit(":", 1)[0] for s in t.segments))
    along = t.po2_along()
    assert list(along) == vessels
    for name in vessels:
        cols = [k for k, s in enumerate(t.segments) if s.rsplit(":", 1)[0] == name]
        assert np.allclose(along[name], mean[cols], rtol=1e-12, atol=0)
    assert list(t.po2_along(["iliac", "aortic_root"])) == ["aortic_root", "iliac"]
    assert t.po2_along(["nowhere"]) == {}


def test_zero_wall_tree_matches_the_pool_on_the_same_flows() -> None:
    """Limit: a tree whose wall takes up nothing, with fixed organ VO2 (vanishing km), against
    the pool model driven by the same flows (root inflow → the pool's ejection, outlet flows →
    its organ inflows). Both conserve O2 exactly and consume the same Σ VO2 at the same
    cardiac output, so Fick fixes CaO2 − CvO2 identically (to the two runs' 1e-9 Fick
    residuals). The tree only delays the arterial blood (plug flow) where the pool mixes it,
    and the 3 L of veins average the organs' outflow: SvO2 agrees to 1e-8 (measured < 1e-9).
    SaO2 is weighted by the ejection, which includes the valve's small backflow carrying the
    root's (tree) or the pool's content: 1e-6 (measured 4e-7; a wall leak of 0.01 % of VO2
    would move it by ~1e-5)."""
    p = _tree_model(km=1e-6)
    p["tree"] = {**p["tree"], "wall": {"model": "none"}}
    r = closed_loop.simulate_o2(p)
    flows = np.column_stack([r.tree.inflow, r.tree.outflow, r.flow])
    rp = closed_loop.simulate_o2(_model(km=1e-6), flows=flows)
    s, sp = r.summary(), rp.summary()
    assert s["VO2_tree_wall"] == 0.0
    assert s["cardiac_output"] == pytest.approx(sp["cardiac_output"], rel=1e-12)
    assert s["VO2"] == pytest.approx(sp["VO2"], rel=1e-6)
    # Fick with the pool's VO2 and cardiac output (mL O2 per L of blood)
    assert s["CaO2"] - s["CvO2"] == pytest.approx(sp["VO2"] / sp["cardiac_output"], rel=1e-8)
    assert abs(s["SaO2"] - sp["SaO2"]) <= 1e-6 and abs(s["SvO2"] - sp["SvO2"]) <= 1e-8
    assert s["fick_residual"] <= 1e-9 and s["mass_balance_residual"] <= 1e-13


def test_tree_input_errors_name_the_element() -> None:
    p = _tree_model()
    p["tree"] = {**p["tree"], "vessels": [("aortic_root", "aorta_in", "x", 0.02, -0.01)]}
    with pytest.raises(oxyline.ModelError, match="aortic_root"):
        closed_loop.simulate_o2(p)
    with pytest.raises(oxyline.ModelError, match="flows='heart'"):
        closed_loop.simulate_o2(_tree_model(), flows=np.zeros((200, 11)))


def test_heart_block_values_are_given_in_mmhg_ml_and_the_core_converts_them() -> None:
    """The built-in's heart block is handed over in its published units (`units: mmHg-mL`);
    the core's SI values are 1 mmHg = 133.322368 Pa and 1 mL = 1e-6 m³ applied per quantity.
    A unit system the section does not know is a ModelError naming the element and value."""
    p = closed_loop.load("closed-loop-o2")
    native = closed_loop.heart_model(p)
    given = next(v["heart_pulmonary"] for v in native["vessels"] if "heart_pulmonary" in v)
    assert given["units"] == "mmHg-mL"
    si = next(v["heart_pulmonary"] for v in oxyline.load_model(native).canonical["vessels"]
              if "heart_pulmonary" in v)
    mmhg, ml = 133.322368, 1e-6
    expected = {"left_ventricle_elastance": mmhg / ml, "aortic_valve_resistance": mmhg / ml,
                "mitral_inductance": mmhg / ml, "pulmonary_capacitance": ml / mmhg,
                "left_atrium_passive_pressure": mmhg, "left_ventricle_rest_volume": ml,
                "left_atrium_passive_volume_coefficient": 1 / ml,
                "initial_pulmonary_pressure": mmhg, "atrial_systole_fraction": 1.0}
    for key, factor in expected.items():
        assert si[key] == pytest.approx(given[key] * factor, rel=1e-15), key
    assert si["period"] == p["period"] and "units" not in si
    given["units"] = "mmHg-L"
    with pytest.raises(oxyline.ModelError,
                       match=r"vessel 'heart_pulmonary'.*heart_pulmonary units must be .*"
                             r"'mmHg-mL', got 'mmHg-L'"):
        oxyline.load_model(native)
