"""Every invalid model is rejected with :class:`oxyline.ModelError` (or a subclass) whose message
names the offending vessel / node / key and value; the command line reports it on stderr with
exit code 2, and a valid run writes a NetCDF file that xarray opens."""

from __future__ import annotations

import copy
import math
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import run_child

import oxyline
from oxyline import cli


def base() -> dict[str, Any]:
    """A valid Y-shaped network (SI)."""
    wall = {"wall_thickness": 7e-4, "youngs_modulus": 5e5, "poisson_ratio": 0.49}
    return {
        "name": "y",
        "period": 1.0,
        "vessels": [
            {"name": "parent", "from": "inlet", "to": "J", "length": 0.06, "radius": 0.003,
             "segments": 3, **wall},
            {"name": "left", "from": "J", "to": "out_l", "length": 0.05, "radius": 0.0025,
             "segments": 2, **wall},
            {"name": "right", "from": "J", "to": "out_r", "length": 0.05, "radius": 0.002,
             "segments": 2, **wall},
        ],
        "boundary_conditions": {
            "inlet": {"type": "flow", "time": [0.0, 0.5, 1.0], "flow": [5e-6, 8e-6, 5e-6]},
            "out_l": {"type": "resistance", "resistance": 3e9},
            "out_r": {"type": "resistance", "resistance": 5e9},
        },
    }


def vessel(d: dict[str, Any], name: str) -> dict[str, Any]:
    return next(v for v in d["vessels"] if v["name"] == name)


def test_the_base_model_is_valid() -> None:
    model = oxyline.load_model(base())
    res = oxyline.simulate(model, cycles=1, output_every=0.01)
    assert res.vessels == ["parent", "left", "right"]


def edit(f: Callable[[dict[str, Any]], object]) -> dict[str, Any]:
    d = copy.deepcopy(base())
    f(d)
    return d


def setv(name: str, key: str, value: object) -> Callable[[dict[str, Any]], object]:
    return lambda d: vessel(d, name).__setitem__(key, value)


def add_vessel(**v: object) -> Callable[[dict[str, Any]], object]:
    def f(d: dict[str, Any]) -> None:
        d["vessels"].append({"length": 0.03, "radius": 0.002, **v})
    return f


def set_bc(node: str, bc: dict[str, Any]) -> Callable[[dict[str, Any]], object]:
    return lambda d: d["boundary_conditions"].__setitem__(node, bc)


def fourier(period: float) -> dict[str, Any]:
    return {"type": "flow", "fourier": {"period": period, "mean": 5e-6, "sin": [1e-6]}}


def no_pressure_reference(d: dict[str, Any]) -> None:
    d["boundary_conditions"]["out_l"] = {"type": "flow", "value": -2e-6}
    d["boundary_conditions"]["out_r"] = {"type": "flow", "value": -3e-6}


# (case id, model edit, patterns that must all appear in the message)
CASES: list[tuple[str, Callable[[dict[str, Any]], object], list[str]]] = [
    ("negative radius", setv("left", "radius", -0.001), ["left", "radius", "-0.001"]),
    ("zero radius", setv("left", "radius", 0.0), ["left", "radius", r"\b0(\.0)?\b"]),
    ("negative length", setv("right", "length", -0.05), ["right", "length", "-0.05"]),
    ("zero length", setv("right", "length", 0), ["right", "length", r"\b0(\.0)?\b"]),
    ("negative wall thickness", setv("parent", "wall_thickness", -7e-4),
     ["parent", "wall_thickness", "-0.0007"]),
    ("zero Young's modulus", setv("parent", "youngs_modulus", 0.0),
     ["parent", "youngs_modulus", r"\b0(\.0)?\b"]),
    ("Poisson ratio above 0.5", setv("parent", "poisson_ratio", 0.7),
     ["parent", "poisson_ratio", "0.7"]),
    ("NaN radius", setv("left", "radius", float("nan")), ["left", "radius", "nan"]),
    ("NaN length", setv("left", "length", float("nan")), ["left", "length", "nan"]),
    ("infinite modulus", setv("left", "youngs_modulus", float("inf")),
     ["left", "youngs_modulus", "inf"]),
    ("NaN resistance", set_bc("out_l", {"type": "resistance", "resistance": float("nan")}),
     ["out_l", "resistance", "nan"]),
    ("NaN flow table entry", set_bc("inlet", {"type": "flow", "time": [0.0, 0.5, 1.0],
                                              "flow": [5e-6, float("nan"), 5e-6]}),
     ["inlet", "flow", "nan"]),
    ("NaN Fourier mean", set_bc("inlet", {"type": "flow", "fourier": {
        "period": 1.0, "mean": float("nan")}}), ["inlet", "mean", "nan"]),
    ("negative lumped resistance", lambda d: d["vessels"].__setitem__(1, {
        "name": "shunt", "from": "J", "to": "out_l", "lumped": {"resistance": -1e8}}),
     ["shunt", "resistance", r"-(1e\+08|100000000)\b"]),
    ("negative lumped capacitance", lambda d: d["vessels"].__setitem__(1, {
        "name": "shunt", "from": "J", "to": "out_l",
        "lumped": {"resistance": 1e8, "capacitance": -1e-12}}),
     ["shunt", "capacitance", r"-(1e-12|0\.0+1)\b"]),
    ("radius and radius_in", setv("left", "radius_in", 0.002),
     ["left", "radius", "radius_in"]),
    ("dangling vessel end", add_vessel(name="stub", **{"from": "J", "to": "nowhere"}),
     ["stub", "nowhere"]),
    ("dangling inlet end", add_vessel(name="feeder", **{"from": "loose", "to": "J"}),
     ["feeder", "loose"]),
    ("BC on an unknown node", set_bc("ghost", {"type": "resistance", "resistance": 1e9}),
     ["ghost"]),
    ("BC on an internal node", set_bc("J", {"type": "resistance", "resistance": 1e9}),
     ["J", "parent"]),
    ("disconnected part", lambda d: (
        d["vessels"].append({"name": "island", "from": "a", "to": "b", "length": 0.02,
                             "radius": 0.002}),
        d["boundary_conditions"].update(a={"type": "flow", "value": 1e-6},
                                        b={"type": "resistance", "resistance": 1e9})),
     ["island", "connected"]),
    ("duplicate vessel name", add_vessel(name="left", **{"from": "J", "to": "out_x"}),
     ["left", "twice"]),
    ("vessel from a node to itself", add_vessel(name="loop", **{"from": "J", "to": "J"}),
     ["loop", "J"]),
    ("non-increasing time table", set_bc("inlet", {
        "type": "flow", "time": [0.0, 0.5, 0.5, 1.0], "flow": [5e-6, 8e-6, 7e-6, 5e-6]}),
     ["inlet", "time", "increasing", "0.5"]),
    ("decreasing time table", set_bc("inlet", {
        "type": "flow", "time": [0.0, 0.6, 0.4, 1.0], "flow": [5e-6, 8e-6, 7e-6, 5e-6]}),
     ["inlet", "time", "0.4", "0.6"]),
    ("time and flow of different lengths", set_bc("inlet", {
        "type": "flow", "time": [0.0, 0.5, 1.0], "flow": [5e-6, 8e-6]}), ["inlet", "3", "2"]),
    ("period mismatch with the model", set_bc("inlet", fourier(0.8)),
     ["inlet", "period", "0.8", r"model period is 1(\.0)? s"]),
    ("period mismatch between BCs", lambda d: (
        d.pop("period"),
        d["boundary_conditions"].update(
            inlet=fourier(0.8),
            out_l={"type": "pressure", "time": [0.0, 0.5, 1.0], "pressure": [0, 10, 0]})),
     ["out_l", "period", "inlet", "0.8", r"\b1(\.0)? s"]),
    ("zero model period", lambda d: d.update(period=0.0), ["period", r"\b0(\.0)?\b"]),
    ("unknown top-level key", lambda d: d.update(vesels=[]), ["vesels"]),
    ("unknown vessel key", setv("left", "radiuss", 0.002), ["left", "radiuss"]),
    ("unknown BC key", set_bc("out_l", {"type": "resistance", "resistance": 3e9,
                                        "resistence": 1.0}), ["out_l", "resistence"]),
    ("unknown BC type", set_bc("out_l", {"type": "windkessel", "resistance": 3e9}),
     ["out_l", "windkessel"]),
    ("BC without type", set_bc("out_l", {"resistance": 3e9}), ["out_l", "type"]),
    ("rcr without capacitance", set_bc("out_l", {
        "type": "rcr", "proximal_resistance": 1e8, "distal_resistance": 1e9}),
     ["out_l", "capacitance"]),
    ("no pressure reference", no_pressure_reference, ["pressure", "inlet", "out_l", "out_r"]),
    ("negative rcr capacitance", set_bc("out_l", {
        "type": "rcr", "proximal_resistance": 1e8, "capacitance": -1e-12,
        "distal_resistance": 1e9}), ["out_l", "capacitance", r"-1e-12\b"]),
    ("zero rcr distal resistance", set_bc("out_l", {
        "type": "rcr", "proximal_resistance": 1e8, "capacitance": 1e-10,
        "distal_resistance": 0.0}), ["out_l", "distal_resistance", r"\b0\b"]),
    ("negative outlet resistance", set_bc("out_l", {"type": "resistance", "resistance": -3e9}),
     ["out_l", "resistance", r"-3e9\b"]),
    ("bad method in the file", lambda d: d.update(simulation={"method": "euler"}),
     ["method", "euler"]),
    ("unknown simulation key", lambda d: d.update(simulation={"cycle": 3}), ["cycle"]),
    ("bad arrangement", lambda d: d.update(arrangement="T"), ["arrangement", "T"]),
    ("non-integer segments", setv("left", "segments", 2.5), ["left", "segments", "2.5"]),
    ("zero segments", setv("left", "segments", 0), ["left", "segments", r"\b0\b"]),
    ("text radius", setv("left", "radius", "wide"), ["left", "radius", "wide"]),
]


@pytest.mark.parametrize("make,patterns", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_invalid_model_raises_a_model_error_naming_the_culprit(
        make: Callable[[dict[str, Any]], object], patterns: list[str]) -> None:
    with pytest.raises(oxyline.ModelError) as info:
        oxyline.load_model(edit(make))
    msg = str(info.value)
    for p in patterns:
        assert re.search(p, msg), f"{p!r} not in {msg!r}"


def test_nan_values_never_pass_silently() -> None:
    # every numeric field of a vessel rejects NaN
    for key in ("length", "radius", "wall_thickness", "youngs_modulus", "poisson_ratio"):
        with pytest.raises(oxyline.ModelError, match=key):
            oxyline.load_model(edit(setv("parent", key, math.nan)))


@pytest.mark.parametrize("overrides,patterns", [
    ({"method": "euler"}, ["method", "euler"]),
    ({"cycles": 0}, ["cycles", r"\b0\b"]),
    ({"cycles": -2}, ["cycles", "-2"]),
    ({"dt": -1e-4}, ["dt", "-0.0001"]),
    ({"dt": 0.0}, ["dt", r"\b0(\.0)?\b"]),
    ({"output_cycles": "first"}, ["cycles", "first"]),
    ({"start": "hot"}, ["start", "hot"]),
    ({"timestep": 1e-4}, ["timestep"]),
])
def test_invalid_run_settings_raise_a_model_error(overrides: dict[str, Any],
                                                  patterns: list[str]) -> None:
    model = oxyline.load_model(base())
    with pytest.raises(oxyline.ModelError) as info:
        oxyline.simulate(model, **overrides)
    for p in patterns:
        assert re.search(p, str(info.value)), (p, str(info.value))


def test_cycles_zero_in_the_file_is_rejected() -> None:
    d = base()
    d["simulation"] = {"cycles": 0}
    with pytest.raises(oxyline.ModelError, match="cycles"):
        oxyline.simulate(oxyline.load_model(d))


def test_unstable_time_step_is_a_model_error_subclass() -> None:
    assert issubclass(oxyline.UnstableTimeStep, oxyline.ModelError)
    model = oxyline.load_model(base())
    dt_max = model.network.rk4_stability_limit()[0]
    with pytest.raises(oxyline.ModelError, match="unstable"):
        oxyline.simulate(model, method="rk4", dt=2 * dt_max, cycles=1)


# --------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------

@pytest.fixture
def bad_yaml(tmp_path: Path) -> Path:
    d = base()
    vessel(d, "left")["radius"] = -0.001
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_cli_validate_bad_model_exits_2_with_message(bad_yaml: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["validate", str(bad_yaml)]) == 2
    err = capsys.readouterr().err
    assert "left" in err and "radius" in err and "-0.001" in err


def test_cli_validate_bad_model_subprocess(bad_yaml: Path) -> None:
    p = run_child([sys.executable, "-m", "oxyline.cli", "validate", str(bad_yaml)], timeout=120)
    assert p.returncode == 2
    assert "left" in p.stderr and "-0.001" in p.stderr
    assert "Traceback" not in p.stderr


def test_cli_validate_good_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "good.yaml"
    p.write_text(yaml.safe_dump(base()))
    assert cli.main(["validate", str(p)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"vessels\s+3", out)


def test_cli_run_writes_netcdf(tmp_path: Path) -> None:
    xr = pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    out = tmp_path / "out.nc"
    assert cli.main(["run", "bifurcation", "--cycles", "2", "-o", str(out), "--quiet"]) == 0
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert {"time", "vessel"} <= set(ds.dims)
        assert set(ds["pressure_in"].dims) == {"time", "vessel"}
        assert list(ds["vessel"].values) == ["parent", "daughter1", "daughter2"]
        assert ds.sizes["time"] == 1001
        # the mean inflow over the (last) cycle is the inlet condition's 6 mL/s, within the
        # default run's rtol 1e-3 (the inflow is an algebraic unknown of the controlled step)
        q = ds["flow_in"].sel(vessel="parent").values
        assert abs(q[:-1].mean() - 6.0e-6) < 6e-9
