"""svZeroDSolver's calibrator drop-in (``oxyline.svzerod.calibrate``) against independent
truths: the calibrated models svZeroDSolver stored for its own test inputs
(``tests/data/svzerod/cases``: ``steadyFlow_calibration`` and the two VMR
``*_calibrate_from_0d`` cases), values recovered from observations made to satisfy the
vessel equations exactly, and (when PyPI ``svzerod`` is installed) a fresh run of the peer.

Tolerance: 1e-6 of each value's scale, the largest magnitude of that value (R_poiseuille, C,
L, stenosis_coefficient) over the model's vessels and junctions. The stored files are
written with 16-17 significant digits and both codes take the same iterates, so the
difference is the rounding of two summation orders, amplified by the conditioning of the
normal equations (measured: below 1e-9 of the scale).
"""

from __future__ import annotations

import copy
import gzip
import json
import math
from typing import Any

import numpy as np
import pytest
from conftest import data_path

from oxyline import svzerod
from oxyline.errors import ModelError

VMR = ("0104_0001", "0140_2001")
TOL = 1e-6


def _vmr(model: str) -> tuple[dict[str, Any], dict[str, Any]]:
    with gzip.open(data_path("svzerod", "cases", "vmr", "input",
                             f"{model}_calibrate_from_0d.json.gz"), "rt") as f:
        cfg = json.load(f)
    ref = json.loads(data_path("svzerod", "cases", "vmr", "reference",
                               f"{model}_optimal_from_0d.json").read_text())
    return cfg, ref


def _steady() -> dict[str, Any]:
    return json.loads(data_path("svzerod", "cases", "steadyFlow_calibration.json").read_text())


def _values(cfg: dict[str, Any]) -> dict[tuple[str, str, int], float]:
    """Every calibrated value by (block, name, outlet index)."""
    out = {}
    for v in cfg["vessels"]:
        for k, x in v["zero_d_element_values"].items():
            out[(v["vessel_name"], k, 0)] = x
    for j in cfg.get("junctions", []):
        for k, xs in j.get("junction_values", {}).items():
            for i, x in enumerate(xs):
                out[(j["junction_name"], k, i)] = x
    return out


def _scales(expected: dict[tuple[str, str, int], float],
            fallback: dict[str, float]) -> dict[str, float]:
    names = {k for _, k, _ in expected}
    return {k: max([abs(x) for (_, n, _), x in expected.items() if n == k]
                   + [fallback.get(k, 0.0)]) for k in names}


def _assert_same(got: dict[str, Any], expected: dict[str, Any],
                 fallback: dict[str, float] | None = None) -> float:
    """Every value of `expected` in `got` to TOL of its scale; returns the worst ratio."""
    exp, mine = _values(expected), _values(got)
    assert mine.keys() == exp.keys()
    scales = _scales(exp, fallback or {})
    worst = 0.0
    for key, x in exp.items():
        err = abs(mine[key] - x) / scales[key[1]]
        worst = max(worst, err)
        assert err <= TOL, f"{key}: {mine[key]!r} vs {x!r} (scale {scales[key[1]]:.3e})"
    return worst


@pytest.mark.parametrize("model", VMR)
def test_vmr_cases_reproduce_the_stored_calibrated_models(model: str) -> None:
    cfg, ref = _vmr(model)
    out = svzerod.calibrate(cfg)
    _assert_same(out, ref)
    # the rest of the file is returned as it was, without the calibrator's keys
    assert set(out) == set(cfg) - {"y", "dy", "calibration_parameters"}
    assert out["boundary_conditions"] == cfg["boundary_conditions"]
    multi = [j for j in out["junctions"] if len(j["outlet_vessels"]) > 1]
    assert multi and all(j["junction_type"] == "BloodVesselJunction" for j in multi)
    # the input is not modified
    assert "y" in cfg and cfg["junctions"][0]["junction_type"] == "NORMAL_JUNCTION"


def test_negative_stenosis_coefficients_are_kept() -> None:
    cfg, ref = _vmr("0104_0001")
    exp = {k: x for k, x in _values(ref).items() if k[1] == "stenosis_coefficient" and x < 0}
    assert len(exp) >= 3
    got = _values(svzerod.calibrate(cfg))
    scale = max(abs(x) for k, x in _values(ref).items() if k[1] == "stenosis_coefficient")
    for key, x in exp.items():
        assert got[key] < 0 and abs(got[key] - x) <= TOL * scale


def test_steady_flow_case_keeps_the_values_the_data_do_not_determine() -> None:
    """Upstream's expected result (its test suite): the generating R = 100, C = 1e-4, L = 1,
    S = 0. Steady observations determine R + S|Q| only, and neither C nor L (their columns of
    J vanish), so those two keep their start values exactly."""
    cfg = _steady()
    out = svzerod.calibrate(cfg)
    v = out["vessels"][0]["zero_d_element_values"]
    q = max(abs(x) for k, xs in cfg["y"].items() if k.startswith("flow") for x in xs)
    expected = copy.deepcopy(out)
    expected["vessels"][0]["zero_d_element_values"] = {
        "R_poiseuille": 100.0, "C": 1e-4, "L": 1.0, "stenosis_coefficient": 0.0}
    # S's scale: the stenosis coefficient that adds R's size at the observed flow
    _assert_same(out, expected, {"stenosis_coefficient": 100.0 / q})
    assert v["C"] == 1e-4 and v["L"] == 1.0


def test_set_capacitance_to_zero_writes_c_zero_and_keeps_the_fit() -> None:
    cfg, _ = _vmr("0104_0001")
    base = _values(svzerod.calibrate(cfg))
    cfg["calibration_parameters"]["set_capacitance_to_zero"] = True
    zero = _values(svzerod.calibrate(cfg))
    for key, x in zero.items():
        if key[1] == "C":
            assert x == 0.0
        else:
            assert x == base[key]


def _synthetic(r: float, c: float, ind: float, s: float, n: int = 60) -> dict[str, Any]:
    """One BloodVessel between an inflow and an outlet whose observations satisfy its two
    equations exactly for (R, C, L, S): Q_in(t) and P_in(t) chosen (flow of both signs), Q_out
    from the capacitor row, P_out from the momentum row."""
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    w = 2 * np.pi
    q = 5.0 + 20.0 * np.sin(w * t) + 4.0 * np.cos(2 * w * t)
    dq = 20.0 * w * np.cos(w * t) - 8.0 * w * np.sin(2 * w * t)
    p = 1.0e5 + 2.0e4 * np.sin(w * t + 0.4)
    dp = 2.0e4 * w * np.cos(w * t + 0.4)
    d2q = -20.0 * w * w * np.sin(w * t) - 16.0 * w * w * np.cos(2 * w * t)
    d2p = -2.0e4 * w * w * np.sin(w * t + 0.4)
    # Q_out = Q − C (Ṗ − (R + 2S|Q|) Q̇) and its rate (|Q|' = sign(Q) Q̇)
    slope = r + 2 * s * np.abs(q)
    q_out = q - c * (dp - slope * dq)
    dq_out = dq - c * (d2p - 2 * s * np.sign(q) * dq * dq - slope * d2q)
    p_out = p - (r + s * np.abs(q)) * q - ind * dq_out
    names = {"pressure:IN:v": (p, dp), "flow:IN:v": (q, dq), "pressure:v:OUT": (p_out, 0 * t),
             "flow:v:OUT": (q_out, dq_out)}
    return {
        "vessels": [{"vessel_id": 0, "vessel_name": "v", "zero_d_element_type": "BloodVessel",
                     "boundary_conditions": {"inlet": "IN", "outlet": "OUT"},
                     "zero_d_element_values": {"R_poiseuille": 0.0, "C": 0.0, "L": 0.0}}],
        "junctions": [],
        "y": {k: a.tolist() for k, (a, _) in names.items()},
        "dy": {k: b.tolist() for k, (_, b) in names.items()},
        "calibration_parameters": {"tolerance_gradient": 1e-12, "tolerance_increment": 1e-14,
                                   "maximum_iterations": 100},
    }


@pytest.mark.parametrize("s", [0.3, -0.2, 0.0])
def test_exact_observations_give_back_the_generating_values(s: float) -> None:
    truth = {"R_poiseuille": 120.0, "C": 3e-5, "L": 2.5, "stenosis_coefficient": s}
    cfg = _synthetic(truth["R_poiseuille"], truth["C"], truth["L"], s)
    got = svzerod.calibrate(cfg)["vessels"][0]["zero_d_element_values"]
    for k, x in truth.items():
        # exact data: the least-squares minimum is the truth, to rounding of the data
        assert math.isclose(got[k], x, rel_tol=1e-7, abs_tol=1e-9), (k, got[k], x)


def test_without_stenosis_calibration_the_coefficient_is_zero() -> None:
    cfg = _synthetic(120.0, 3e-5, 2.5, 0.0)
    cfg["calibration_parameters"]["calibrate_stenosis_coefficient"] = False
    cfg["vessels"][0]["zero_d_element_values"]["stenosis_coefficient"] = 7.0  # not used
    got = svzerod.calibrate(cfg)["vessels"][0]["zero_d_element_values"]
    assert got["stenosis_coefficient"] == 0.0
    assert math.isclose(got["R_poiseuille"], 120.0, rel_tol=1e-7)
    assert math.isclose(got["C"], 3e-5, rel_tol=1e-7)


@pytest.mark.parametrize("where", ["blocks", "global"])
def test_calibrate_lists_fit_only_the_listed_values(where: str) -> None:
    """svZeroDSolver 3.2's input: the calibrated 0104 model with every R zeroed and only R
    listed (on every block, or once in calibration_parameters) gives back the stored R
    (upstream's own R-only check) and keeps C, L and S."""
    cfg, ref = _vmr("0104_0001")
    start = copy.deepcopy(ref)
    for v in start["vessels"]:
        v["zero_d_element_values"]["R_poiseuille"] = 0.0
        if where == "blocks":
            v["calibrate"] = ["R_poiseuille"]
    for j in start["junctions"]:
        if "junction_values" in j and where == "blocks":
            j["calibrate"] = ["R_poiseuille"]
    settings = dict(cfg["calibration_parameters"])
    if where == "global":
        settings["calibrate"] = ["R_poiseuille"]
    start.update(y=cfg["y"], dy=cfg["dy"], calibration_parameters=settings)
    out = svzerod.calibrate(start)
    _assert_same(out, ref)
    for v_out, v_ref in zip(out["vessels"], ref["vessels"]):
        for k in ("C", "L", "stenosis_coefficient"):
            assert v_out["zero_d_element_values"][k] == v_ref["zero_d_element_values"][k]


@pytest.mark.parametrize(("edit", "message"), [
    (lambda c: c.pop("y"), "no 'y'"),
    (lambda c: c["dy"].pop("flow:INFLOW:branch0_seg0"),
     "dy: no observations of 'flow:INFLOW:branch0_seg0'"),
    (lambda c: c["y"]["pressure:INFLOW:branch0_seg0"].__setitem__(3, float("nan")),
     r"y\['pressure:INFLOW:branch0_seg0'\]\[3\] is not finite"),
    (lambda c: c["y"]["pressure:INFLOW:branch0_seg0"].pop(), "same number"),
    (lambda c: c["vessels"][0].update(zero_d_element_type="BloodVesselCRL"),
     "vessel 'branch0_seg0': the calibrator fits BloodVessel"),
    (lambda c: c["vessels"][0]["zero_d_element_values"].update(C="x"),
     "vessel 'branch0_seg0': 'C' must be a finite number"),
    (lambda c: c["vessels"][0].update(calibrate=["R", "C"]),
     r"vessel 'branch0_seg0': cannot calibrate \['R'\]"),
    (lambda c: c["calibration_parameters"].update(maximum_iterations=0), "maximum_iterations"),
    (lambda c: c.update(vessels=[1]), "'vessels' must be a list of objects"),
    (lambda c: c["vessels"][0].pop("vessel_id"), "no 'vessel_id'"),
    (lambda c: c.update(junctions=[{"junction_name": "J", "inlet_vessels": [0],
                                    "outlet_vessels": [7]}]),
     "junction 'J': outlet_vessels names vessel id 7"),
    (lambda c: c["calibration_parameters"].update(tolerance=1), "unknown key"),
    (lambda c: c["vessels"][0].pop("boundary_conditions"),
     "vessel 'branch0_seg0': needs one inlet and one outlet"),
])
def test_bad_input_names_the_block_or_key(edit: Any, message: str) -> None:
    cfg = _steady()
    edit(cfg)
    with pytest.raises(ModelError, match=message):
        svzerod.calibrate(cfg)


def test_junction_with_two_inlets_and_two_outlets_is_refused() -> None:
    cfg, _ = _vmr("0104_0001")
    j = next(j for j in cfg["junctions"] if len(j["outlet_vessels"]) > 1)
    extra = copy.deepcopy(cfg["vessels"][0])
    extra.update(vessel_id=999, vessel_name="extra")
    cfg["vessels"].append(extra)
    j["inlet_vessels"] = [*j["inlet_vessels"], 999]
    with pytest.raises(ModelError, match=f"junction '{j['junction_name']}'"):
        svzerod.calibrate(cfg)


def test_against_a_live_svzerod() -> None:
    """Optional: the peer itself (3.2 needs `calibrate` lists; every value listed is the
    classic selection, and 3.2 writes the values unclipped as this mode does)."""
    peer = pytest.importorskip("svzerod")
    for cfg in (_vmr("0104_0001")[0], _steady()):
        for b in [*cfg["vessels"], *cfg["junctions"]]:
            if "vessel_name" in b:
                b["calibrate"] = ["R_poiseuille", "C", "L", "stenosis_coefficient"]
            elif len(b["outlet_vessels"]) > 1:
                b["calibrate"] = ["R_poiseuille", "L", "stenosis_coefficient"]
        theirs = peer.calibrate(copy.deepcopy(cfg))
        q = max(abs(x) for k, xs in cfg["y"].items() if k.startswith("flow") for x in xs)
        r = max(abs(v["zero_d_element_values"]["R_poiseuille"]) for v in theirs["vessels"])
        _assert_same(svzerod.calibrate(cfg), theirs, {"stenosis_coefficient": r / q,
                                                      "L": 1.0, "R_poiseuille": r})
