"""Plausibility warnings: each unit mix-up of an input quantity warns, naming the element, the
key, the value and the mix-up; no built-in model, svZeroDSolver or openBF reference case, or
network under tests/data warns. The truth of each case is the mix-up itself: the value of the
valid model multiplied by the factor between the unit written and the unit meant."""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import oxyline
from oxyline import catalogue

DATA = Path(__file__).parent / "data"
MMHG = 133.322368


def _base() -> dict[str, Any]:
    return catalogue.load_dict("bifurcation")


def _cgs() -> dict[str, Any]:
    """The bifurcation written in cgs (cm, dyn/cm², mL/s, g/cm³, poise): the valid model a
    cgs mix-up starts from."""
    d = _base()
    d["units"] = "cgs"
    d["blood"] = {"density": 1.05, "viscosity": 0.035}
    for v in d["vessels"]:
        for k in ("length", "radius", "wall_thickness"):
            v[k] *= 100.0
        v["youngs_modulus"] *= 10.0
    f = d["boundary_conditions"]["inlet"]["fourier"]
    for k in ("mean", "cos", "sin"):
        f[k] = f[k] * 1e6 if k == "mean" else [x * 1e6 for x in f[k]]
    for node in ("ica_out", "eca_out"):
        d["boundary_conditions"][node]["resistance"] *= 1e-5
    return d


def _vessel(key: str, factor: float, units: Callable[[], dict[str, Any]] = _base
            ) -> Callable[[], dict[str, Any]]:
    def make() -> dict[str, Any]:
        d = units()
        d["vessels"][0][key] *= factor
        return d
    return make


def _blood(key: str, value: float, units: Callable[[], dict[str, Any]] = _base
           ) -> Callable[[], dict[str, Any]]:
    def make() -> dict[str, Any]:
        d = units()
        d["blood"][key] = value
        return d
    return make


def _inflow(factor: float, units: Callable[[], dict[str, Any]] = _base
            ) -> Callable[[], dict[str, Any]]:
    def make() -> dict[str, Any]:
        d = units()
        f = d["boundary_conditions"]["inlet"]["fourier"]
        f["mean"] *= factor
        f["cos"] = [x * factor for x in f["cos"]]
        f["sin"] = [x * factor for x in f["sin"]]
        return d
    return make


def _outlet(key: str, factor: float) -> Callable[[], dict[str, Any]]:
    def make() -> dict[str, Any]:
        d = _base()
        d["boundary_conditions"]["ica_out"][key] *= factor
        return d
    return make


def _rcr(capacitance: float) -> Callable[[], dict[str, Any]]:
    """An RCR outlet of the ICA with its compliance written in another unit (1e-10 m³/Pa
    meant: a carotid territory's)."""
    def make() -> dict[str, Any]:
        d = _base()
        d["boundary_conditions"]["ica_out"] = {
            "type": "rcr", "proximal_resistance": 3e8, "capacitance": capacitance,
            "distal_resistance": 2.6e9}
        return d
    return make


def _pressure_inlet(factor: float) -> Callable[[], dict[str, Any]]:
    """The bifurcation driven by a pressure of 100 ± 20 mmHg in Pa, times ``factor``."""
    def make() -> dict[str, Any]:
        d = _base()
        d["boundary_conditions"]["inlet"] = {"type": "pressure", "fourier": {
            "period": 1.0, "mean": 100 * MMHG * factor, "cos": [20 * MMHG * factor]}}
        return d
    return make


def _period_in_ms() -> dict[str, Any]:
    d = _base()
    d["period"] = 1000.0
    d["boundary_conditions"]["inlet"]["fourier"]["period"] = 1000.0
    return d


def _svzerod_flow_in_si() -> dict[str, Any]:
    """An svZeroDSolver file (cgs) whose inflow table was written in m³/s."""
    cfg = json.loads((DATA / "svzerod" / "cases" / "pulsatileFlow_R_RCR.json").read_text())
    for bc in cfg["boundary_conditions"]:
        if bc["bc_type"] == "FLOW":
            q = bc["bc_values"]["Q"]
            bc["bc_values"]["Q"] = [x * 1e-6 for x in q] if isinstance(q, list) else q * 1e-6
    return cfg


#: (case, its mix-up, the key the warning names, the words of the likely cause)
MIX_UPS: list[tuple[str, Callable[[], dict[str, Any]], str, str | None]] = [
    ("radius in cm, SI file", _vessel("radius", 100), "radius", "in cm in an SI file"),
    ("radius in mm, SI file", _vessel("radius", 1000), "radius", "in mm in an SI file"),
    ("length in cm, SI file", _vessel("length", 100), "length", "in cm in an SI file"),
    ("length in mm, SI file", _vessel("length", 1000), "length", "in mm in an SI file"),
    ("wall in mm, SI file", _vessel("wall_thickness", 1000), "wall_thickness", "mm"),
    ("E in MPa, SI file", _vessel("youngs_modulus", 1e-6), "youngs_modulus", "MPa"),
    ("E in kPa, SI file", _vessel("youngs_modulus", 1e-3), "youngs_modulus", "kPa"),
    ("flow in mL/s, SI file", _inflow(1e6), "flow", "mL/s in an SI file"),
    ("flow in L/min, SI file", _inflow(6e4), "flow", "L/min in an SI file"),
    ("R in dyn·s/cm⁵, SI file", _outlet("resistance", 1e-5), "resistance",
     "dyn·s/cm⁵ in an SI file"),
    ("R in mmHg·s/mL, SI file", _outlet("resistance", 1 / 1.33322368e8), "resistance",
     "mmHg·s/mL in an SI file"),
    ("C in cm⁵/dyn, SI file", _rcr(1e-10 * 1e5), "capacitance", "cm⁵/dyn in an SI file"),
    ("C in mL/mmHg, SI file", _rcr(1e-10 * 1.33322368e8), "capacitance",
     "mL/mmHg in an SI file"),
    ("pressure in dyn/cm², SI file", _pressure_inlet(10.0), "pressure",
     "dyn/cm² in an SI file"),
    ("inlet pressure in mmHg, SI file", _pressure_inlet(1 / MMHG), "pressure",
     "mmHg in an SI file"),
    ("inlet pressure in kPa, SI file", _pressure_inlet(1e-3), "pressure", "kPa in an SI file"),
    ("density in g/cm³, SI file", _blood("density", 1.05), "density", "g/cm³ in an SI file"),
    ("viscosity in poise, SI file", _blood("viscosity", 0.035), "viscosity", "poise"),
    ("viscosity in cP, SI file", _blood("viscosity", 3.5), "viscosity", "cP"),
    ("period in ms", _period_in_ms, "flow period", "ms"),
    ("density in kg/m³, cgs file", _blood("density", 1050.0, _cgs), "density",
     "kg/m³ in a cgs file"),
    ("viscosity in Pa·s, cgs file", _blood("viscosity", 0.0035, _cgs), "viscosity",
     "Pa·s in a cgs file"),
    ("flow in m³/s, cgs file", _inflow(1e-6, _cgs), "flow", "m³/s in a cgs file"),
    ("E in MPa, cgs file", _vessel("youngs_modulus", 1e-7, _cgs), "youngs_modulus",
     "MPa in a cgs file"),
    ("radius in mm, cgs file", _vessel("radius", 100, _cgs), "radius", None),
    ("flow in m³/s, svZeroDSolver file", _svzerod_flow_in_si, "flow", "m³/s in a cgs file"),
]


def _warnings(source: Any) -> list[oxyline.PlausibilityWarning]:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        oxyline.load_model(source)
    return [w.message for w in seen if isinstance(w.message, oxyline.PlausibilityWarning)]


def test_the_valid_models_the_mix_ups_start_from_do_not_warn() -> None:
    assert _warnings(_base()) == []
    assert _warnings(_cgs()) == []
    cfg = json.loads((DATA / "svzerod" / "cases" / "pulsatileFlow_R_RCR.json").read_text())
    assert _warnings(cfg) == []


@pytest.mark.parametrize(("case", "make", "key", "cause"), MIX_UPS, ids=[m[0] for m in MIX_UPS])
def test_a_unit_mix_up_warns_naming_the_element_key_value_and_cause(
        case: str, make: Callable[[], dict[str, Any]], key: str, cause: str | None) -> None:
    found = _warnings(make())
    assert len(found) >= 1, f"{case}: no warning"
    w = next((w for w in found if w.key == key), None)
    assert w is not None, f"{case}: warnings name {[x.key for x in found]}, not {key!r}"
    text = str(w)
    assert w.element and w.element in text and f"{key} = " in text
    assert w.unit in text and not (w.low <= abs(w.value) <= w.high)
    if cause is not None:
        assert w.likely_cause is not None and cause in w.likely_cause, text
        assert cause in text


def test_the_warning_names_the_vessel_and_the_si_value() -> None:
    [w] = _warnings(_vessel("radius", 100)())
    assert (w.element, w.key, w.unit) == ("vessel 'parent'", "radius", "m")
    assert w.value == pytest.approx(0.3)  # 3 mm written as 0.3 (cm) in an SI file
    assert "physiological range" in str(w) and "likely a value in cm" in str(w)


def test_a_whole_tree_in_the_wrong_unit_gives_a_few_warnings_that_count_the_rest() -> None:
    d = _base()
    for v in d["vessels"]:
        v["radius"] *= 1000
    found = _warnings(d)
    radius = [w for w in found if w.key == "radius"]
    assert len(radius) == 3 and sum(1 + w.more for w in radius) == 3
    # a tree of 40 vessels: the first warnings and a count of the others
    d = _base()
    d["vessels"] = [dict(d["vessels"][0], name=f"v{i}", **{"from": f"n{i}", "to": f"n{i + 1}"},
                         radius=3.0) for i in range(40)]
    d["boundary_conditions"] = {"n0": d["boundary_conditions"]["inlet"],
                                "n40": d["boundary_conditions"]["ica_out"]}
    radius = [w for w in _warnings(d) if w.key == "radius"]
    assert len(radius) == 3 and sum(1 + w.more for w in radius) == 40
    assert "37 more" in str(radius[0])


def test_the_standard_warnings_filter_silences_it() -> None:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", oxyline.PlausibilityWarning)
        oxyline.load_model(_vessel("radius", 100)())
    assert not [w for w in seen if isinstance(w.message, oxyline.PlausibilityWarning)]
    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.PlausibilityWarning)
        with pytest.raises(oxyline.PlausibilityWarning, match="radius"):
            oxyline.load_model(_vessel("radius", 100)())


def test_the_warning_points_at_the_callers_line() -> None:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        oxyline.load_model(_vessel("radius", 100)())
    [w] = [w for w in seen if isinstance(w.message, oxyline.PlausibilityWarning)]
    assert w.filename == __file__


def test_a_warning_survives_pickling() -> None:
    import pickle

    [w] = _warnings(_vessel("radius", 100)())
    back = pickle.loads(pickle.dumps(w))
    assert (back.element, back.key, back.value, str(back)) == (w.element, w.key, w.value, str(w))


def _reference_sources() -> list[str]:
    cases = sorted(str(p) for p in (DATA / "svzerod" / "cases").rglob("*.json"))
    openbf = sorted(str(p) for p in (DATA / "openbf").rglob("*.yml")) + \
        sorted(str(p) for p in (DATA / "openbf").rglob("*.yaml"))
    return list(catalogue.list()) + cases + openbf


def test_no_built_in_model_or_reference_case_or_network_under_tests_data_warns() -> None:
    loaded, found = 0, {}
    for src in _reference_sources():
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            try:
                oxyline.load_model(src)
            except (oxyline.ModelError, ValueError):
                continue  # cases that test an error or an unsupported block
        loaded += 1
        w = [str(x.message) for x in seen if isinstance(x.message, oxyline.PlausibilityWarning)]
        if w:
            found[src] = w
    assert found == {}
    assert loaded >= 55  # 14 built-ins, 37 svZeroDSolver cases, the openBF models


def test_the_command_line_prints_one_line_and_can_silence_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from oxyline.cli import main

    p = tmp_path / "aorta.json"
    p.write_text(json.dumps({
        "name": "aorta", "units": "SI",
        "vessels": [{"name": "aorta", "from": "in", "to": "out", "length": 0.1, "radius": 1.2,
                     "wall_thickness": 0.002, "youngs_modulus": 4e5}],
        "boundary_conditions": {"in": {"type": "flow", "value": 1e-4},
                                "out": {"type": "resistance", "resistance": 1e8}}}))
    assert main(["validate", str(p)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err == [line for line in err if line.startswith("warning: vessel 'aorta': radius")]
    assert len(err) == 1 and "in cm in an SI file" in err[0]
    assert main(["--no-plausibility", "validate", str(p)]) == 0
    assert capsys.readouterr().err == ""


def test_an_svzerod_model_name_names_the_result() -> None:
    path = DATA / "svzerod" / "cases" / "vmr" / "reference" / "0140_2001_optimal_from_0d.json"
    name = json.loads(path.read_text())["simulation_parameters"]["model_name"]
    m = oxyline.load_model(path)
    assert m.name == name == "0140_2001"
    res = oxyline.simulate(m, cycles=1)
    assert res.model_name == name and res.to_xarray().attrs["model"] == name
    # a file without one keeps the generic name
    assert oxyline.load_model(DATA / "svzerod" / "cases" / "steadyFlow_R_R.json").name == "svzerod"


def test_the_svzerod_drop_in_of_a_cgs_file_does_not_read_its_numbers_as_si(
        tmp_path: Path) -> None:
    """The drop-in runs in a cgs file's own numbers (as svZeroDSolver does); the SI ranges do
    not apply to them, while the same file loaded as a model (converted to SI) is checked."""
    import warnings

    import oxyline.svzerod as svz
    from oxyline.io.svzerod import writer

    d = writer.to_svzerod(oxyline.load_model("bifurcation"), units="cgs", samples=201,
                          points_per_cycle=101, cycles=1)
    p = tmp_path / "b_cgs.json"
    p.write_text(json.dumps(d))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        svz.simulate(json.loads(p.read_text()))
        oxyline.load_model(p)
    assert not [w for w in seen if isinstance(w.message, oxyline.PlausibilityWarning)]


def test_load_model_can_leave_the_check_out_for_one_model() -> None:
    import warnings

    bad = oxyline.catalogue.load_dict("bifurcation")
    bad["vessels"][0]["radius"] = 0.3  # 3 mm written in cm in an SI file
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        oxyline.load_model(bad, check_plausibility=False)
        quiet = [w for w in seen if isinstance(w.message, oxyline.PlausibilityWarning)]
        oxyline.load_model(bad)
        loud = [w for w in seen if isinstance(w.message, oxyline.PlausibilityWarning)]
    assert quiet == [] and len(loud) == 1 and "radius" in str(loud[0].message)
