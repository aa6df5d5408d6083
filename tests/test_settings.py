"""Run settings are checked like the model: every bad value is a ModelError
naming the setting, where it came from (simulate keyword or the model's simulation section) and
the value; numpy scalars are numbers like Python's."""

from __future__ import annotations

import math

import numpy as np
import pytest

import oxyline
from oxyline.cli import main


@pytest.mark.parametrize(("options", "message"), [
    ({"until_periodic": -1}, "simulate: until_periodic must be a finite number > 0, got -1"),
    ({"until_periodic": math.nan}, "simulate: until_periodic must be a finite number > 0"),
    ({"until_periodic": 0}, "until_periodic must be a finite number > 0, got 0"),
    ({"until_periodic": 1e-3, "cycles": 5, "max_cycles": 3},
     r"simulate: max_cycles \(3\) is less than cycles \(5\)"),
    ({"cycles": "3"}, "simulate: cycles must be an integer >= 1, got '3'"),
    ({"cycles": 2.5}, "simulate: cycles must be an integer >= 1, got 2.5"),
    ({"cycles": True}, "simulate: cycles must be an integer >= 1, got True"),
    ({"dt": "fast"}, "simulate: dt must be 'auto' or a number > 0, got 'fast'"),
    ({"dt": -1e-4}, "simulate: dt must be a finite number > 0"),
    ({"output_every": "1ms"}, "simulate: output_every must be a number, got '1ms'"),
    ({"output_every": math.inf}, "simulate: output_every must be a finite number > 0"),
    ({"segments": "no"}, "simulate: segments must be true or false, got 'no'"),
    ({"transport": "off"}, "simulate: transport must be true or false"),
    ({"rho_infty": 1.5}, "simulate: rho_infty must be a finite number >= 0 and <= 1"),
    ({"rho_infty": "0.5"}, "simulate: rho_infty must be a number"),
    ({"max_iterations": 0}, "simulate: max_iterations must be an integer >= 1"),
    ({"newton_atol": -1.0}, "simulate: newton_atol must be a finite number > 0"),
    ({"start": "warm"}, "simulate: start must be one of steady, zero"),
    ({"method": 4}, "simulate: method must be one of"),
    ({"output_cycles": "first"}, "simulate: output_cycles must be 'last' or 'all'"),
    ({"progress": "yes"}, "simulate: progress must be true, false or a callback"),
])
def test_bad_settings_are_model_errors_naming_the_setting(options: dict[str, object],
                                                          message: str) -> None:
    with pytest.raises(oxyline.ModelError, match=message):
        oxyline.simulate("bifurcation", **options)


@pytest.mark.parametrize(("section", "message"), [
    ({"until_periodic": -1}, "simulation: until_periodic must be a finite number > 0"),
    ({"cycles": "ten"}, "simulation: cycles must be an integer >= 1, got 'ten'"),
    ({"output": {"segments": "no"}}, "simulation output: segments must be true or false"),
    ({"output": {"every": 0}}, "simulation output: every must be a finite number > 0"),
])
def test_bad_settings_in_the_model_file_name_its_section(section: dict[str, object],
                                                         message: str) -> None:
    src = oxyline.load_model("bifurcation").to_dict()
    src["simulation"] = section
    with pytest.raises(oxyline.ModelError, match=message):
        oxyline.simulate(src)


def test_cli_bad_setting_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "bifurcation", "--quiet", "--until-periodic", "-1"]) == 2
    assert "until_periodic must be a finite number > 0" in capsys.readouterr().err


def test_numpy_scalars_are_numbers() -> None:
    """np.int64, np.float32 and np.bool_ run exactly as the Python values they equal."""
    dt = 2.0**-13  # exact in float32
    ref = oxyline.simulate("bifurcation", cycles=2, method="rk4", dt=dt, output_every=2.0**-10,
                           segments=False, rho_infty=0.5)
    got = oxyline.simulate("bifurcation", cycles=np.int64(2), method="rk4", dt=np.float32(dt),
                           output_every=np.float32(2.0**-10), segments=np.bool_(False),
                           rho_infty=np.float16(0.5))
    assert np.array_equal(got.pressure_in, ref.pressure_in)
    assert np.array_equal(got.flow_out, ref.flow_out)
    res = oxyline.simulate("bifurcation", cycles=np.int32(3), until_periodic=np.float32(1e-3),
                           max_cycles=np.uint8(20))
    assert 3 <= res.settings["cycles_run"] <= 20

