"""Every result carries the units it actually has, on every path: native files,
svZeroDSolver JSON through oxyline's own loader and through the drop-in, importers to NetCDF and
Zarr, the console table and the figures. Each path is checked against the same model run natively
(the built-in bifurcation, SI): the svZeroDSolver export of it is the same circuit (docs/io.md),
in cgs or SI numbers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import data_path

import oxyline
import oxyline.io as oio
import oxyline.svzerod as svz
from oxyline.cli import main
from oxyline.units import MMHG

CYCLES = 4
RUN = {"cycles": CYCLES, "method": "generalized-alpha", "dt": 1e-3, "output_every": 1e-3}


@pytest.fixture(scope="module")
def native() -> oxyline.Result:
    return oxyline.simulate("bifurcation", **RUN)


def _export(tmp_path: Path, units: str) -> Path:
    """The bifurcation as an svZeroDSolver file in ``units``, same step and cycles as RUN."""
    d = oio.to_svzerod(oxyline.load_model("bifurcation"), units=units, samples=2001,
                       points_per_cycle=1001, cycles=CYCLES)
    p = tmp_path / f"b_{units}.json"
    p.write_text(json.dumps(d))
    return p


# the native vessel ends in the export's blocks (docs/io.md): the inlet node pressure is block
# 0's inlet, the first segment's branch flow block 0's outflow (its L), the last segment's branch
# flow block n-1's outflow and the outlet node pressure block n's outlet (10 segments each)
BLOCKS = {"p_in": ("parent_seg0", "pressure_in"), "q_in": ("parent_seg0", "flow_out"),
          "p_out": ("daughter1_seg10", "pressure_out"), "q_out": ("daughter1_seg9", "flow_out")}
NATIVE = {"p_in": ("parent", "pressure_in"), "q_in": ("parent", "flow_in"),
          "p_out": ("daughter1", "pressure_out"), "q_out": ("daughter1", "flow_out")}


def _ends(res: oxyline.Result) -> dict[str, np.ndarray]:
    """Inlet pressure and flow of the parent, outlet pressure and flow of daughter1, in SI, for a
    native result (vessel names) or one of the export (``<vessel>_seg<k>`` blocks)."""
    where = NATIVE if "parent" in res.vessels else BLOCKS
    return {k: getattr(res.vessel(v), var) for k, (v, var) in where.items()}


def _assert_same_run(actual: dict[str, np.ndarray], expected: dict[str, np.ndarray]) -> None:
    """Time means to 1e-6 (the export samples the Fourier inflow at 2001 points; a linear
    circuit's periodic mean depends only on the mean inflow, which uniform sampling keeps to
    round-off), waveforms to 1e-3 of their range (linear interpolation of the samples). A
    unit mix-up is off by 10x (pressure) or 10^6x (flow)."""
    for k, e in expected.items():
        a = actual[k]
        assert a.shape == e.shape, k
        assert a.mean() == pytest.approx(e.mean(), rel=1e-6), k
        assert np.max(np.abs(a - e)) <= 1e-3 * np.ptp(e), k


@pytest.mark.parametrize("units", ["cgs", "SI"])
def test_svzerod_file_through_the_native_loader_is_si(tmp_path: Path, native: oxyline.Result,
                                                      units: str) -> None:
    p = _export(tmp_path, units)
    for model in (oxyline.load_model(p), oio.read_model(p)):
        res = oxyline.simulate(model)  # the file's own settings: same step, cycles, output
        _assert_same_run(_ends(res), _ends(native))
        assert res.to_xarray()["pressure_in"].attrs["units"] == "Pa"


def test_svzerod_units_key_and_override(tmp_path: Path) -> None:
    d = json.loads(_export(tmp_path, "cgs").read_text())
    assert d["units"] == "cgs"
    del d["units"]  # svZeroDSolver's convention: cgs
    assert svz.to_oxyline_dict(d)["units"] == "cgs"
    assert svz.to_oxyline_dict(d, units="SI")["units"] == "SI"
    with pytest.raises(oxyline.ModelError, match="units must be 'cgs' or 'SI', got 'furlong'"):
        svz.to_model({**d, "units": "furlong"})


@pytest.mark.parametrize("units", ["cgs", "SI"])
def test_drop_in_frame_names_its_units(tmp_path: Path, native: oxyline.Result,
                                       units: str) -> None:
    df = svz.simulate(_export(tmp_path, units))
    assert df.attrs["units_system"] == units
    to_si = {"cgs": {"pressure": 0.1, "flow": 1e-6}, "SI": {"pressure": 1.0, "flow": 1.0}}[units]
    expected_units = {"cgs": ("dyn/cm^2", "mL/s"), "SI": ("Pa", "m^3/s")}[units]
    assert (df.attrs["units"]["pressure_in"], df.attrs["units"]["flow_in"]) == expected_units
    got = {k: df.loc[df.name == v, var].to_numpy() * to_si[var.split("_")[0]]
           for k, (v, var) in BLOCKS.items()}
    _assert_same_run(got, _ends(native))


def _open(path: Path) -> oxyline.Result:
    import xarray as xr

    opener = xr.open_zarr if path.suffix == ".zarr" else xr.open_dataset
    with opener(path) as ds:
        assert ds["pressure_in"].attrs["units"] == "Pa"
        assert ds["flow_in"].attrs["units"] == "m^3/s"
        assert ds.attrs["units_system"].startswith("SI")
    return oxyline.open_result(path)


@pytest.mark.parametrize("suffix", [".nc", ".zarr"])
def test_cli_files_of_an_svzerod_input_are_si(tmp_path: Path, native: oxyline.Result,
                                              suffix: str) -> None:
    if suffix == ".zarr":
        pytest.importorskip("zarr")
    src = _export(tmp_path, "cgs")
    out = tmp_path / f"sv{suffix}"
    assert main(["run", str(src), "--quiet", "-o", str(out)]) == 0
    _assert_same_run(_ends(_open(out)), _ends(native))


def _importer_models(tmp_path: Path) -> dict[str, oxyline.Model]:
    """The bifurcation through each importer: tables (CSV), native JSON in cgs, svZeroDSolver."""
    m = oxyline.load_model("bifurcation")
    oio.write_tables(m, tmp_path / "b.csv")
    src = m.to_dict()
    cgs = dict(src, units="cgs")  # the same numbers in cgs: lengths x100, modulus x10, flow x1e6
    cgs["vessels"] = [dict(v, length=v["length"] * 100, radius=v["radius"] * 100,
                           wall_thickness=v["wall_thickness"] * 100,
                           youngs_modulus=v["youngs_modulus"] * 10) for v in src["vessels"]]
    bcs = json.loads(json.dumps(src["boundary_conditions"]))
    f = bcs["inlet"]["fourier"]
    f.update(mean=f["mean"] * 1e6, cos=[x * 1e6 for x in f["cos"]],
             sin=[x * 1e6 for x in f["sin"]])
    for k in ("ica_out", "eca_out"):
        bcs[k]["resistance"] *= 1e-5
    cgs["boundary_conditions"] = bcs
    cgs["blood"] = {"density": 1.05, "viscosity": 0.035}
    (tmp_path / "cgs.json").write_text(json.dumps(cgs))
    return {"tables": oio.read_model(tmp_path / "b.csv"),
            "native-cgs": oio.read_model(tmp_path / "cgs.json"),
            "svzerod": oio.read_model(_export(tmp_path, "cgs"))}


@pytest.mark.parametrize("suffix", [".nc", ".zarr"])
def test_importers_write_si_files(tmp_path: Path, native: oxyline.Result, suffix: str) -> None:
    if suffix == ".zarr":
        pytest.importorskip("zarr")
    for name, model in _importer_models(tmp_path).items():
        res = oxyline.simulate(model, **RUN)
        out = tmp_path / f"{name}{suffix}"
        res.to_netcdf(out) if suffix == ".nc" else res.to_zarr(out)
        _assert_same_run(_ends(_open(out)), _ends(native))


def test_openbf_import_is_si(tmp_path: Path) -> None:
    """openBF files are SI (m, Pa, m^3/s): the imported inflow equals the inlet table's and the
    NetCDF file says Pa. Mean parent inflow = mean of ibif_inlet.dat (a flow source)."""
    pytest.importorskip("oxyline.io.openbf")
    from oxyline.io.openbf import read_openbf

    src = data_path("openbf", "models/boileau2015/ibif/ibif.yaml")
    table = np.loadtxt(src.with_name("ibif_inlet.dat"))
    model = read_openbf(src)
    res = oxyline.simulate(model, cycles=2, method="generalized-alpha")
    back = _open(res.to_netcdf(tmp_path / "ibif.nc"))
    t, q = table[:, 0], table[:, 1]
    mean_in = np.trapezoid(q, t) / (t[-1] - t[0])
    q_out = back.vessel(back.vessels[0]).flow_in
    # trapezoid mean of the output samples over one period vs the table's: 1e-3 (sampling)
    assert np.trapezoid(q_out, back.time) / (back.time[-1] - back.time[0]) == pytest.approx(
        mean_in, rel=1e-3)


def test_console_table_is_in_mmhg_and_ml_per_s(tmp_path: Path, native: oxyline.Result,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    src = _export(tmp_path, "cgs")
    assert main(["run", str(src), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    assert main(["run", str(src)]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("parent_seg0 "))
    p_mmhg, q_mls = (float(x) for x in row.split()[1:3])
    # parent_seg0's inlet is the network inlet and its inflow the inflow source, mean 6 mL/s
    # (the mean of 1001 samples of a cycle is within 2e-5 of it); 3 and 4 decimals printed
    assert p_mmhg == pytest.approx(native.vessel("parent").pressure_in.mean() / MMHG, abs=2e-3)
    assert q_mls == pytest.approx(6.0, abs=2e-4)


def test_figures_show_mmhg_of_the_si_result(tmp_path: Path, native: oxyline.Result) -> None:
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    from oxyline import plot

    res = oxyline.simulate(oxyline.load_model(_export(tmp_path, "cgs")))
    fig = plot.waveforms(res, ["parent_seg0"], quantities=("pressure", "flow"))
    p_ax, q_ax = fig.axes[:2]
    assert "[mmHg]" in p_ax.get_ylabel() and "[mL/s]" in q_ax.get_ylabel()
    p = p_ax.get_lines()[0].get_ydata()
    q = q_ax.get_lines()[0].get_ydata()
    assert np.mean(p) == pytest.approx(native.vessel("parent").pressure_in.mean() / MMHG,
                                       rel=1e-6)
    # the inflow's mean is 6 mL/s (Fourier mean); the mean of the 1001 samples of a cycle,
    # both ends included, is within 1e-4 of it
    assert np.mean(q) == pytest.approx(6.0, rel=1e-3)
    import matplotlib.pyplot as plt

    plt.close(fig)
