"""svZeroDSolver's closed-loop blocks through the drop-in: the
ClosedLoopHeartAndPulmonary block, ClosedLoopRCR and the closed-loop coronaries against the
stored svZeroDSolver references, the same model in the native format (SI) against the
references converted to SI, and the typed refusals (docs/physics.md §1.10, docs/svzerod.md)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pandas as pd
import pytest
from conftest import svzerod_run

import oxyline
from oxyline import svzerod as svz
from tests.conftest import data_path

CASES = ("closedLoopHeart_singleVessel", "closedLoopHeart_withCoronaries")


def case(name: str) -> Any:
    return data_path("svzerod", "cases", f"{name}.json")


def reference(name: str) -> pd.DataFrame:
    return pd.read_json(data_path("svzerod", "cases", "results", f"result_{name}.json"))


def scaled_errors(actual: pd.DataFrame, expected: pd.DataFrame,
                  scale: dict[str, float] | None = None) -> dict[str, float]:
    """max|a - e| / max|e| per column (as tests/test_svzerod.py), rows matched by name and
    time; `scale` converts the reference's columns (e.g. cgs -> SI)."""
    assert list(actual["name"]) == list(expected["name"])
    np.testing.assert_allclose(actual["time"].to_numpy(float), expected["time"].to_numpy(float),
                               atol=1e-9)
    out = {}
    for c in ("flow_in", "flow_out", "pressure_in", "pressure_out"):
        e = expected[c].to_numpy(float) * (scale or {}).get(c, 1.0)
        out[c] = float(np.max(np.abs(actual[c].to_numpy(float) - e)) / np.max(np.abs(e)))
    return out


@pytest.mark.parametrize("name", CASES)
def test_generalized_alpha_matches_reference(name: str) -> None:
    errors = scaled_errors(svz.simulate(str(case(name))), reference(name))
    # svZeroDSolver's Newton tolerance (1e-8 / 1e-9 absolute on values of order 1e5 dyn/cm²)
    # and the reference's 10 stored decimals: a faithful translation is far below 1e-6, any
    # modelling difference (a valve law, the pulmonary bed's volume bookkeeping) far above
    assert max(errors.values()) <= 1e-6, errors


#: RK4 against svzerod 20x finer, measured (max|a - e| / max|e| over the four columns), at the
#: drop-in's sub-step (the stability bound's, refined by the core's step doubling,
#: docs/physics.md §1.8): singleVessel 1.5e-4 (4x the bound's 2 sub-steps; 3.9e-4 at 2, 3.8e-4
#: of it against 320x finer: RK4's own error), withCoronaries 1.3e-4 (not refined; 9.1e-6
#: against 80x finer: the peer's error at 20x)
RK4_MEASURED = {"closedLoopHeart_singleVessel": 1.5e-4, "closedLoopHeart_withCoronaries": 1.3e-4}


@pytest.mark.parametrize("name", CASES)
def test_rk4_matches_svzerod_20x_finer(name: str) -> None:
    """The explicit valve law (docs/physics.md §1.10: open while the pressure behind exceeds
    the pressure in front or the flow is positive, a closed valve's flow held and clamped at
    zero after the step in which it would reverse) against svzerod's implicit on/off valves
    run 20x finer."""
    pytest.importorskip("svzerod")
    cfg = json.loads(case(name).read_text())
    errors = scaled_errors(svz.simulate(cfg, method="rk4"), svzerod_run(cfg, 20))
    # a valve closes at the end of the RK4 sub-step in which its flow crosses zero: the
    # switch is first order in the sub-step (the motion between switches fourth order), so
    # the agreement is the valve timing error, 2.6x the measured value as margin
    assert max(errors.values()) <= 2.6 * RK4_MEASURED[name], errors


def test_rk4_valve_timing_converges_with_the_step() -> None:
    """closedLoopHeart_singleVessel with RK4 at 16 sub-steps per output step, 8x the stability
    bound's 2, against svzerod 320x finer: 3.8e-4 → 9.2e-6 (the valve switches are resolved to
    the sub-step, docs/physics.md §1.10)."""
    pytest.importorskip("svzerod")
    name = "closedLoopHeart_singleVessel"
    cfg = json.loads(case(name).read_text())
    assert cfg["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"] == 100
    expected = svzerod_run(cfg, 320)
    errors = scaled_errors(svz.simulate(cfg, method="rk4", rk4_substeps=16), expected)
    # measured 9.2e-6 (sub-steps x2, x4: 4.6e-5, 3.0e-5)
    assert max(errors.values()) <= 3e-5, errors


def test_native_model_matches_reference_in_si() -> None:
    """The drop-in's native dict (cgs numbers, ``units: cgs``) built as an oxyline model: the
    ``heart_pulmonary`` keys converted to SI by the model layer, run in SI. Against the
    reference converted to SI (dyn/cm² -> Pa x 0.1, mL/s -> m³/s x 1e-6). The on/off valves make
    the discrete solution depend on where Newton stops (docs/physics.md §1.10): svZeroDSolver's
    1e-8 absolute residual in cgs is about 1e-10 in SI for these rows; oxyline's own
    scaled-increment rule ends 0.9 % away (another valve timing)."""
    name = "closedLoopHeart_singleVessel"
    native = svz.to_oxyline_dict(str(case(name)))
    assert native["units"] == "cgs"
    model = oxyline.load_model(native)
    heart = next(v for v in model.canonical["vessels"] if v["name"] == "CLH")["heart_pulmonary"]
    # 1 mL = 1e-6 m³; 1 mL/(dyn/cm²) = 1e-5 m³/Pa
    assert heart["initial_left_ventricle_volume"] == pytest.approx(96.07e-6, rel=1e-12)
    assert heart["aortic_capacitance"] == pytest.approx(0.556854e-5, rel=1e-12)
    result = oxyline.simulate(model, newton_atol=1e-10)
    e = reference(name)
    r = result.vessel("branch0_seg0")
    np.testing.assert_allclose(r.time, e["time"].to_numpy(float), atol=1e-9)
    errors = {}
    for c, f in (("flow_in", 1e-6), ("flow_out", 1e-6), ("pressure_in", 0.1),
                 ("pressure_out", 0.1)):
        ev = e[c].to_numpy(float) * f
        errors[c] = float(np.max(np.abs(getattr(r, c) - ev)) / np.max(np.abs(ev)))
    # measured 6e-11: the same equations and stopping point in other units
    assert max(errors.values()) <= 1e-6, errors


def test_unknown_heart_of_a_coronary_bed_is_a_model_error() -> None:
    d = json.loads(case("closedLoopHeart_withCoronaries").read_text())
    native = svz.to_oxyline_dict(d)
    for v in native["vessels"]:
        if "coronary_bed" in v:
            v["coronary_bed"]["heart"] = "nowhere"
    with pytest.raises(oxyline.ModelError, match="heart 'nowhere' is not a heart_pulmonary"):
        oxyline.simulate(native)


@pytest.mark.parametrize("key, value, match", [
    ("Cp", -1.0, "pulmonary_capacitance"),
    ("Rla_v", -0.1, "mitral_resistance"),
])
def test_bad_heart_parameter_names_the_element(key: str, value: float, match: str) -> None:
    d = json.loads(case("closedLoopHeart_singleVessel").read_text())
    d["closed_loop_blocks"][0]["parameters"][key] = value
    with pytest.raises(oxyline.ModelError, match=f"heart_pulmonary 'CLH'.*{match}"):
        svz.simulate(d)


def test_unsupported_heart_initial_condition_is_named() -> None:
    d = json.loads(case("closedLoopHeart_singleVessel").read_text())
    d["initial_condition"]["Q_LV:CLH"] = 1.0
    with pytest.raises(oxyline.UnsupportedElement, match="Q_LV:CLH"):
        svz.simulate(d)


@pytest.mark.parametrize("name", CASES)
def test_variable_table_matches_a_fresh_svzerod_run(name: str) -> None:
    """With ``output_variable_based`` (the stored references are vessel tables): the same
    variables in svZeroDSolver's order, the heart block's 12, the closed-loop conditions' P_c
    and volume_im and the heart's outlet into each of its outlet_blocks among them, and the
    same values (measured ≤ 2.2e-13 of each variable's range)."""
    svzerod = pytest.importorskip("svzerod")
    cfg = json.loads(case(name).read_text())
    cfg["simulation_parameters"]["output_variable_based"] = True
    ours, fresh = svz.simulate(json.loads(json.dumps(cfg))), svzerod.simulate(cfg)
    names = list(dict.fromkeys(fresh["name"]))
    assert list(dict.fromkeys(ours["name"])) == names
    assert {"V_LV:CLH", "P_pul:CLH", "flow:J_heart_outlet:branch0_seg0"} <= set(names)
    for n in names:
        e = fresh[fresh["name"] == n]["y"].to_numpy(float)
        a = ours[ours["name"] == n]["y"].to_numpy(float)
        scale = max(float(np.ptp(e)), 1e-9 * float(np.max(np.abs(e))), 1e-300)
        assert float(np.max(np.abs(a - e))) <= 1e-9 * scale, n
