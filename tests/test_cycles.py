"""How many cycles a run takes: `cycles` exactly, or `until_periodic` between `cycles` and
`max_cycles`, a keyword over the model file, and a run that ends at `max_cycles` above its
tolerance says so (warning, result flag, CLI line)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

import oxyline
from oxyline.cli import main


def _asks_periodicity() -> dict:
    """The bifurcation example with `until_periodic` in its model file."""
    d = oxyline.load_model("bifurcation").to_dict()
    d["simulation"] = {**d.get("simulation", {}), "until_periodic": 1e-15, "cycles": 2,
                       "max_cycles": 4}
    return d


def test_explicit_until_periodic_none_runs_exactly_cycles() -> None:
    model = _asks_periodicity()
    # the model's own rule: up to its max_cycles to a change below 1e-15 (round-off level)
    with pytest.warns(oxyline.PeriodicityWarning):
        from_file = oxyline.simulate(model)
    assert from_file.settings["cycles_run"] == 4
    # a keyword wins over the file: exactly N cycles, no periodicity test, no flag
    res = oxyline.simulate(model, cycles=3, until_periodic=None)
    assert res.settings["cycles_run"] == 3
    assert "periodic_reached" not in res.settings


def test_max_cycles_above_tolerance_warns_and_flags() -> None:
    with pytest.warns(oxyline.PeriodicityWarning, match=r"not periodic after 3 cycles"):
        res = oxyline.simulate("bifurcation", cycles=2, until_periodic=1e-14, max_cycles=3,
                               output_every=0.01)
    assert res.settings["cycles_run"] == 3
    assert res.settings["periodic_reached"] is False
    assert res.settings["periodic_error"] >= 1e-14
    # reached: no warning, flag True
    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.PeriodicityWarning)
        ok = oxyline.simulate("bifurcation", cycles=1, until_periodic=1e-2, max_cycles=30,
                              output_every=0.01)
    assert ok.settings["periodic_reached"] is True
    assert ok.settings["periodic_error"] < 1e-2


def test_cli_cycle_and_output_flags(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    xr = pytest.importorskip("xarray")
    out = tmp_path / "r.nc"
    # the command line shows the PeriodicityWarning as one `warning:` line on stderr
    code = main(["run", "bifurcation", "--cycles", "1", "--until-periodic", "1e-14",
                 "--max-cycles", "2", "--output-every", "0.02", "-o", str(out)])
    assert code == 0
    captured = capsys.readouterr()
    assert "2 cycles" in captured.out and "not periodic" in captured.out
    assert "warning: " in captured.err and "periodic" in captured.err
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.attrs["solver_periodic_reached"] == 0
        assert ds.sizes["time"] == 51  # 0 .. 1 s every 20 ms
    # 'none' drops the tolerance: exactly --cycles
    assert main(["run", "bifurcation", "--cycles", "2", "--until-periodic", "none",
                 "--output-every", "0.05", "--quiet", "-o", str(out)]) == 0
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.attrs["solver_cycles_run"] == 2 and ds.sizes["time"] == 21
        assert "solver_periodic_reached" not in ds.attrs
