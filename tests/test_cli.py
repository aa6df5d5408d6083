"""The oxyline command line end to end in a temporary directory: run (-o .nc/.zarr, --summary,
--plot), validate, convert between formats, models, info, and exit code 2 with messages naming
the file, vessel and key."""

from __future__ import annotations

import json
import math
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from conftest import data_path, run_child

import oxyline
from oxyline.cli import main

EXAMPLE = Path(oxyline.__file__).parent / "examples" / "bifurcation.yaml"


def assert_valid_image(path: Path) -> None:
    """A non-trivial PNG (signature) or SVG (parsable, with content)."""
    data = path.read_bytes()
    assert len(data) > 5000, path
    if path.suffix == ".png":
        assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    else:
        root = ET.fromstring(data)
        assert root.tag.endswith("svg") and len(list(root.iter())) > 50, path


def test_run_end_to_end_writes_netcdf_summary_and_figures(tmp_path: Path) -> None:
    xr = pytest.importorskip("xarray")
    pytest.importorskip("matplotlib")
    env = {**os.environ, "MPLBACKEND": "Agg"}
    out = run_child(
        [sys.executable, "-m", "oxyline.cli", "run", "bifurcation", "--cycles", "2", "-o",
         "out.nc", "--summary", "summary.csv", "--plot", "figs"],
        cwd=tmp_path, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "results written to out.nc" in out.stdout and "6 figures written to figs" in out.stdout
    with xr.open_dataset(tmp_path / "out.nc", engine="h5netcdf") as ds:
        q = ds["flow_in"].sel(vessel="parent").values
        t = ds["time"].values
        # the Fourier mean, within the default run's rtol 1e-3 (the inflow is an algebraic
        # unknown of the error-controlled step)
        assert np.trapezoid(q, t) / t[-1] == pytest.approx(6e-6, rel=1e-3)
        assert ds.attrs["model"] == "bifurcation" and ds.attrs["solver_cycles"] == 2
    summary = (tmp_path / "summary.csv").read_text()
    assert summary.startswith("vessel,pressure_in_mean [Pa],") and "daughter2," in summary
    figs = sorted(p.name for p in (tmp_path / "figs").iterdir())
    assert figs == ["network_map.png", "network_map.svg", "profile.png", "profile.svg",
                    "waveforms.png", "waveforms.svg"]
    for f in figs:  # valid, non-trivial images (save_figures output)
        assert_valid_image(tmp_path / "figs" / f)


def test_run_zarr_and_csv_outputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("zarr")
    xr = pytest.importorskip("xarray")
    assert main(["run", str(EXAMPLE), "--cycles", "1", "-o", str(tmp_path / "r.zarr"),
                 "--quiet"]) == 0
    ds = xr.open_zarr(tmp_path / "r.zarr")
    assert list(ds["vessel"].values) == ["parent", "daughter1", "daughter2"]
    assert main(["run", "bifurcation", "--cycles", "1", "-o", str(tmp_path / "r.csv"),
                 "--quiet"]) == 0
    header = (tmp_path / "r.csv").read_text().splitlines()[0]
    # svZeroDSolver's column names, each with its unit (SI, whatever the input file's units)
    assert header == ("name,time [s],flow_in [m^3/s],flow_out [m^3/s],pressure_in [Pa],"
                      "pressure_out [Pa]")


def test_validate_prints_the_analytic_compliance(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    lines = dict(line.split(None, 1) for line in out.splitlines() if line.strip())
    assert lines["vessels"].strip() == "3" and lines["segments"].strip() == "30"
    # thin-wall compliance 2 pi r^3 (1 - nu^2) L / (E h), summed over the three vessels
    c = sum(2 * math.pi * r**3 * (1 - 0.49**2) * length / (5e5 * 7e-4)
            for r, length in ((0.003, 0.0645), (0.0025, 0.0623), (0.002, 0.062)))
    printed = float(out.split("total compliance")[1].split()[0])
    assert printed == pytest.approx(c, rel=1e-4)


def test_convert_between_all_formats(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ref = oxyline.load_model(EXAMPLE)
    steps = [(str(EXAMPLE), "a.json", []), ("a.json", "b.csv", []), ("b.csv", "c.tsv", []),
             ("c.tsv", "d.yaml", [])]
    for src, dst, extra in steps:
        src_path = src if os.path.isabs(src) else str(tmp_path / src)
        assert main(["convert", src_path, str(tmp_path / dst), *extra]) == 0
    assert oxyline.load_model(tmp_path / "d.yaml").canonical == ref.canonical
    assert (tmp_path / "b_bcs.csv").exists() and (tmp_path / "c_bcs.tsv").exists()
    # svZeroDSolver export (cgs by default) and back through oxyline's svZeroDSolver importer
    assert main(["convert", str(tmp_path / "d.yaml"), str(tmp_path / "sv.json"), "--to",
                 "svzerod"]) == 0
    sv = json.loads((tmp_path / "sv.json").read_text())
    assert len(sv["vessels"]) == 33 and sv["boundary_conditions"][1]["bc_type"] == "RESISTANCE"
    assert sv["boundary_conditions"][1]["bc_values"]["R"] == pytest.approx(2.8931e9 / 1e5)
    assert main(["convert", str(tmp_path / "sv.json"), str(tmp_path / "sv.yaml")]) == 0
    assert len(oxyline.load_model(tmp_path / "sv.yaml").vessel_names) == 33


def test_convert_openbf_input(tmp_path: Path) -> None:
    pytest.importorskip("oxyline.io.openbf")
    src = data_path("openbf", "models/boileau2015/ibif/ibif.yaml")
    assert main(["convert", str(src), str(tmp_path / "ibif.yaml")]) == 0
    m = oxyline.load_model(tmp_path / "ibif.yaml")
    assert len(m.vessel_names) == 3 and m.period == pytest.approx(1.1)
    assert main(["run", str(src), "--cycles", "1", "--quiet"]) == 0


def test_models_and_info(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models"]) == 0
    lines = capsys.readouterr().out.splitlines()
    from oxyline import catalogue, closed_loop

    # one line per built-in model, and per closed-loop O2 built-in (oxyline.closed_loop)
    assert len(lines) == len(catalogue.list()) + len(closed_loop.BUILTINS) > 0
    assert any(line.startswith("bifurcation ") for line in lines)
    assert main(["info"]) == 0
    assert oxyline.__version__ in capsys.readouterr().out
    assert main(["info", "bifurcation"]) == 0  # with a model: its summary too
    out = capsys.readouterr().out
    assert oxyline.__version__ in out and "vessels          3" in out


def test_version_is_the_installed_distributions(capsys: pytest.CaptureFixture[str]) -> None:
    """`oxyline --version` and `oxyline.__version__` (the compiled core's) name the version the
    installed distribution's metadata declares (pyproject/Cargo.toml), not a second copy."""
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"oxyline {version('oxyline')}"
    assert oxyline.__version__ == version("oxyline")


def _bad(tmp_path: Path, old: str, new: str) -> Path:
    p = tmp_path / "bad.yaml"
    text = EXAMPLE.read_text()
    assert old in text
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize("cmd", ["run", "validate", "convert"])
def test_bad_input_exits_2_naming_file_vessel_and_key(
        cmd: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = _bad(tmp_path, "length: 0.0623", "length: -0.0623")
    args = [cmd, str(bad)] + ([str(tmp_path / "o.json")] if cmd == "convert" else [])
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and str(bad) in err
    assert "vessel 'daughter1'" in err and "length" in err


def test_bad_input_messages(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = _bad(tmp_path, "radius: 0.0025,", "radius: 0.0025, colour: red,")
    assert main(["validate", str(bad)]) == 2
    assert "vessel 'daughter1': unknown key 'colour'" in capsys.readouterr().err
    table = tmp_path / "t.csv"
    table.write_text("name,from,to,length,radius\nA,in,out,0.1,0.003\nB,out,x,1 cm,0.002\n")
    assert main(["validate", str(table)]) == 2
    assert "row 2 (vessel 'B'): column 'length'" in capsys.readouterr().err
    assert main(["validate", str(tmp_path / "missing.yaml")]) == 2
    assert "missing.yaml: file not found" in capsys.readouterr().err
    assert main(["run", str(EXAMPLE), "-o", str(tmp_path / "out.xyz")]) == 2
    assert "out.xyz: output must end in" in capsys.readouterr().err
    assert main(["convert", str(EXAMPLE), str(tmp_path / "out.xyz")]) == 2
    assert "cannot tell the output format" in capsys.readouterr().err
    assert main(["run", str(EXAMPLE), "--method", "rk4", "--dt", "0.01", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {EXAMPLE}: time step") and "vessel '" in err
    with pytest.raises(SystemExit) as exc:  # argparse usage errors are exit code 2 as well
        main(["run"])
    assert exc.value.code == 2


def test_run_closed_loop_o2_builtin_writes_its_summary(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """`oxyline models` lists the closed-loop O2 built-ins and `oxyline run` solves one to its
    periodic state: the written summary obeys Fick's principle (an independent balance: VO2 =
    CO (CaO2 − CvO2)) and the resting ranges of docs/oxygen.md."""
    assert main(["models"]) == 0
    assert "closed-loop-o2-tree" in capsys.readouterr().out
    out = tmp_path / "s.json"
    assert main(["run", "closed-loop-o2", "--dt", "4e-3", "-o", str(out)]) == 0
    s = json.loads(out.read_text())
    co, vo2 = s["cardiac_output"], s["VO2"]                      # L/min, mL/min
    assert s["fick_residual"] < 1e-9
    # CaO2, CvO2 in mL O2 per L blood
    assert vo2 == pytest.approx(co * (s["CaO2"] - s["CvO2"]), rel=1e-9)
    assert 0.95 < s["SaO2"] < 0.99 and 0.70 < s["SvO2"] < 0.76 and 230 < vo2 < 260
    assert "SvO2" in capsys.readouterr().out
    assert main(["run", "closed-loop-o2", "-o", str(tmp_path / "x.nc")]) == 2
    assert main(["run", "closed-loop-o2", "--cycles", "3"]) == 2
    assert "--cycles" in capsys.readouterr().err


def test_csv_of_an_svzerod_file_says_its_si_units(tmp_path: Path) -> None:
    """`run file.json -o out.csv` converts the cgs file to SI and says so in the column names:
    the inlet pressure of the steady junction case is the file's analytical 3462.5 dyn/cm^2,
    i.e. 346.25 Pa, in a column a plain pd.read_csv finds by its unit."""
    import pandas as pd

    case = (Path(__file__).parent / "data" / "svzerod" / "cases"
            / "steadyFlow_blood_vessel_junction.json")
    out = tmp_path / "out.csv"
    assert main(["run", str(case), "-o", str(out), "--quiet"]) == 0
    df = pd.read_csv(out)
    inlet = df[df["name"] == "branch0_seg0"]
    np.testing.assert_allclose(inlet["pressure_in [Pa]"], 346.25, rtol=1e-9)  # steady: round-off
    np.testing.assert_allclose(inlet["flow_in [m^3/s]"], 5e-6, rtol=1e-9)     # 5 mL/s


def test_result_file_holds_its_model_for_plot(tmp_path: Path) -> None:
    """A result file keeps the model it was run from (attribute model_json): `oxyline plot`
    needs no --model for a model file that is not built in, and the stored model, run again,
    gives the stored pressures (same solver path: to round-off, 1e-12)."""
    case = (Path(__file__).parent / "data" / "svzerod" / "cases"
            / "steadyFlow_blood_vessel_junction.json")
    out = tmp_path / "j.nc"
    assert main(["run", str(case), "-o", str(out), "--quiet"]) == 0
    back = oxyline.open_result(out)
    assert back.model_json is not None
    again = oxyline.simulate(oxyline.load_model(json.loads(back.model_json)))
    np.testing.assert_allclose(again.pressure_in, back.pressure_in, rtol=1e-12)
    figs = tmp_path / "figs"
    figs.mkdir()
    assert main(["plot", str(out), "--plot", str(figs), "--quiet"]) == 0
    assert (figs / "profile.png").exists()


def test_validate_volume_and_species_lines(capsys: pytest.CaptureFixture[str]) -> None:
    """`validate` prints the geometric blood volume (bifurcation: sum of pi r^2 L of its three
    tubes, from the example file's numbers), no volume for a lumped-only model (never
    '0.0000 mL'), and the oxygen section of a model that has one."""
    assert main(["validate", "bifurcation"]) == 0
    out = capsys.readouterr().out
    volume = math.pi * (0.003**2 * 0.0645 + 0.0025**2 * 0.0623 + 0.002**2 * 0.062) * 1e6  # mL
    line = next(x for x in out.splitlines() if x.startswith("total volume"))
    assert float(line.split()[2]) == pytest.approx(volume, rel=1e-4)  # printed to 4 decimals
    case = (Path(__file__).parent / "data" / "svzerod" / "cases"
            / "steadyFlow_blood_vessel_junction.json")
    assert main(["validate", str(case)]) == 0
    out = capsys.readouterr().out
    assert "0.0000 mL" not in out and "no vessel geometry" in out
    assert main(["validate", "paper-bifurcated"]) == 0
    assert "species          o2 (oxygen: o2, wall graetz)" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["run", "plot", "validate", "impedance", "convert", "models",
                                     "info", "calibrate"])
def test_every_subcommand_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: oxyline {command}")
