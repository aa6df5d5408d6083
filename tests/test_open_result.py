"""``oxyline.open_result``: a saved result (NetCDF, Zarr, streamed or interrupted store, or the
dataset of ``Result.to_xarray``) comes back as the identical ``Result``, and the CLI plots from
files (``run -o out.zarr --plot``, ``plot RESULT``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_cli import assert_valid_image

import oxyline
from oxyline import catalogue
from oxyline.cli import main
from oxyline.io import results

xr = pytest.importorskip("xarray")
pytest.importorskip("zarr")

DRUG = [{"name": "drug", "decay": 0.5, "inlet": {"concentration": 1.0}, "initial": 1.0}]


def tube(species: list[dict] | None = None, oxygen: dict | None = None) -> dict:
    """One rigid 5-segment tube (the shape of tests/test_oxygen.py's helper), 2 cycles."""
    return {"period": 1.0,
            "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 5,
                         "length": 0.1, "radius": 3e-3}],
            "boundary_conditions": {"in": {"type": "flow", "value": 2e-6},
                                    "out": {"type": "resistance", "resistance": 1e8}},
            "simulation": {"cycles": 2, "output": {"every": 0.01}},
            **({"species": species} if species else {}),
            **({"oxygen": oxygen} if oxygen else {})}


@pytest.fixture(scope="module")
def runs() -> dict[str, oxyline.Result]:
    return {
        "flow": oxyline.simulate("bifurcation", cycles=1, output_every=0.004),
        "oxygen": oxyline.simulate(catalogue.load("paper-bifurcated"), cycles=1,
                                   output_every=0.004),
        # oxygen and a second species: species order, shared TL elements, decay balance
        "two-species": oxyline.simulate(tube(DRUG, {"inlet": {"po2": 85.0}})),
        # a species alone (no oxygen): no PO2, species order from the variables
        "species-only": oxyline.simulate(tube(DRUG)),
    }


def assert_same(back: oxyline.Result, res: oxyline.Result, *, segments: bool = True) -> None:
    """Every array and fact the Result exposes is identical (NaN-aware)."""
    eq = np.testing.assert_array_equal  # treats NaN == NaN
    assert back.model_name == res.model_name and back.vessels == res.vessels
    assert back.complete == res.complete and back.oxygen == res.oxygen
    # the file keeps the settings that had a value
    assert back.settings == {k: v for k, v in res.settings.items() if v is not None}
    assert back.segment_count == res.segment_count
    eq(back.time, res.time)
    eq(back.data, res.data)
    eq(back.segment_position, res.segment_position)
    for name in ("pressure_in", "pressure_out", "flow_in", "flow_out", "segment_pressure_in",
                 "segment_pressure_out", "segment_flow"):
        eq(getattr(back, name), getattr(res, name), err_msg=name)
    for v in res.vessels:
        eq(back.vessel(v).segment_flow, res.vessel(v).segment_flow)
    assert list(back.species) == list(res.species)
    for name, sp in res.species.items():
        got = back.species[name]
        assert got.po2_per_concentration == sp.po2_per_concentration
        eq(got.vessel_data, sp.vessel_data, err_msg=name)
        if segments:
            eq(got.segment_data, sp.segment_data, err_msg=name)
        for key, arr in sp.mass_balance.items():  # derived: recomputed, and equal
            eq(got.mass_balance[key], arr, err_msg=f"{name} {key}")
    # every derived variable (PO2 in mmHg, wall fluxes, TL elements, mass balance columns)
    want = res.species_variables()
    got_vars = back.species_variables()
    assert list(got_vars) == list(want)
    for name, (kind, arr, unit) in want.items():
        if kind == "segment" and not segments:
            continue
        assert got_vars[name][0] == kind and got_vars[name][2] == unit
        eq(got_vars[name][1], arr, err_msg=name)
    if segments:
        xr.testing.assert_identical(back.to_xarray(), res.to_xarray())


@pytest.mark.parametrize("case", ["flow", "oxygen", "two-species", "species-only"])
def test_open_result_inverts_to_xarray(runs: dict[str, oxyline.Result], case: str) -> None:
    res = runs[case]
    assert_same(oxyline.open_result(res.to_xarray()), res)


@pytest.mark.parametrize("case", ["flow", "oxygen", "two-species"])
@pytest.mark.parametrize("suffix", [".nc", ".zarr"])
def test_open_result_reads_netcdf_and_zarr_files(runs: dict[str, oxyline.Result], case: str,
                                                 suffix: str, tmp_path: Path) -> None:
    res = runs[case]
    path = tmp_path / f"r{suffix}"
    res.to_netcdf(path) if suffix == ".nc" else res.to_zarr(path, time_chunk=100)
    back = oxyline.open_result(path)
    assert_same(back, res)
    assert oxyline.open_result(str(path)).model_name == res.model_name
    # the rebuilt result writes the same file again, and summarises the same
    xr.testing.assert_identical(results.dataset(back), results.dataset(res))
    pd = pytest.importorskip("pandas")
    pd.testing.assert_frame_equal(back.summary(), res.summary())


def test_without_segment_output_the_species_segment_arrays_stay_absent() -> None:
    res = oxyline.simulate(catalogue.load("paper-bifurcated"), cycles=1, segments=False)
    back = oxyline.open_result(res.to_xarray())
    assert_same(back, res, segments=False)
    assert not back.has_segments and back.species["o2"].segment_data.shape[1] == 0


def test_a_streamed_store_opens_as_the_in_memory_result(tmp_path: Path) -> None:
    model = tube(DRUG, {"inlet": {"po2": 85.0}})
    oxyline.simulate_to_zarr(model, tmp_path / "s.zarr", time_chunk=64)
    assert_same(oxyline.open_result(tmp_path / "s.zarr"), oxyline.simulate(model))


def test_an_interrupted_store_opens_as_a_partial_result(tmp_path: Path) -> None:
    # Ctrl-C at the first progress call past t = 0.3 s of simulated time: by then the core has
    # handed over at least one chunk (75 rows > 64). The core calls back at most every 0.1 s of
    # wall time and always at the end, so where the run stops depends on the machine; the
    # checks below hold wherever it stops (at the latest at the end of its 3 cycles).
    settings = {"cycles": 3, "method": "rk4", "output_cycles": "all", "output_every": 0.004}

    def stop(t: float, t_end: float) -> None:
        if t > 0.3:
            raise KeyboardInterrupt

    with pytest.raises(oxyline.SimulationInterrupted):
        oxyline.simulate_to_zarr("bifurcation", tmp_path / "s.zarr", time_chunk=64,
                                 progress=stop, **settings)
    back = oxyline.open_result(tmp_path / "s.zarr")
    assert not back.complete
    with xr.open_zarr(tmp_path / "s.zarr") as ds:
        n = ds.sizes["time"]
        assert n >= 64 and len(back.time) == n
        np.testing.assert_array_equal(back.flow_out, ds["flow_out"].values)
    # the rows of the same run uninterrupted, up to there: the same code path (streamed vs in
    # memory) on the same machine, hence bit-identical
    full = oxyline.simulate("bifurcation", **settings)
    assert n <= len(full.time)
    np.testing.assert_array_equal(back.data, full.data[:n])


def test_not_an_oxyline_result_names_the_missing_variable(tmp_path: Path) -> None:
    path = tmp_path / "other.nc"
    xr.Dataset({"temperature": ("time", np.zeros(3))},
               coords={"time": np.arange(3.0)}).to_netcdf(path, engine="h5netcdf")
    with pytest.raises(ValueError, match=r"other\.nc is not an oxyline result: no variable "
                                         r"'vessel'"):
        oxyline.open_result(path)
    ds = oxyline.simulate("bifurcation", cycles=1).to_xarray().drop_vars("pressure_out")
    with pytest.raises(ValueError, match="no variable 'pressure_out'"):
        oxyline.open_result(ds)
    with pytest.raises(FileNotFoundError):
        oxyline.open_result(tmp_path / "missing.nc")
    with pytest.raises(TypeError):
        oxyline.open_result(42)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------
# command line

def _check_figures(outdir: Path, names: list[str]) -> None:
    files = sorted(p.name for p in outdir.iterdir())
    assert files == sorted(f"{n}.{ext}" for n in names for ext in ("png", "svg"))
    for f in files:
        assert_valid_image(outdir / f)


FIGURES = ["network_map", "profile", "waveforms"]


@pytest.fixture
def headless(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("matplotlib")
    monkeypatch.setenv("MPLBACKEND", "Agg")


@pytest.mark.usefixtures("headless")
def test_cli_run_streams_the_store_and_plots_from_it(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    def no_in_memory_run(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("--plot with -o out.zarr must stream, not run in memory")

    monkeypatch.setattr(oxyline, "simulate", no_in_memory_run)
    out, figs = tmp_path / "out.zarr", tmp_path / "figs"
    assert main(["run", "bifurcation", "--cycles", "1", "-o", str(out), "--plot", str(figs)]) == 0
    assert f"6 figures written to {figs}" in capsys.readouterr().out
    _check_figures(figs, FIGURES)
    back = oxyline.open_result(out)
    assert back.complete and back.model_name == "bifurcation" and back.settings["cycles"] == 1


@pytest.mark.usefixtures("headless")
def test_cli_plot_makes_the_figures_of_a_saved_result(runs: dict[str, oxyline.Result],
                                                      tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    runs["flow"].to_netcdf(tmp_path / "r.nc")
    assert main(["plot", str(tmp_path / "r.nc"), "-o", str(tmp_path / "figs")]) == 0
    assert "6 figures written to" in capsys.readouterr().out
    _check_figures(tmp_path / "figs", FIGURES)


def test_cli_plot_errors_exit_2(runs: dict[str, oxyline.Result], tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    xr.Dataset({"x": ("t", np.zeros(2))}).to_netcdf(tmp_path / "other.nc", engine="h5netcdf")
    assert main(["plot", str(tmp_path / "other.nc"), "--plot", str(tmp_path / "f")]) == 2
    assert "not an oxyline result: no variable 'time'" in capsys.readouterr().err
    assert main(["plot", str(tmp_path / "none.nc"), "--plot", str(tmp_path / "f")]) == 2
    assert "none.nc: file not found" in capsys.readouterr().err
    # a file without its model (an older file, or a tree above MAX_MODEL_JSON) of a model
    # that is not built in needs --model, and the model must hold the result's vessels
    import dataclasses

    dataclasses.replace(runs["two-species"], model_json=None).to_netcdf(tmp_path / "tube.nc")
    assert main(["plot", str(tmp_path / "tube.nc"), "--plot", str(tmp_path / "f")]) == 2
    assert "is not a built-in model and the file does not hold it" in capsys.readouterr().err
    assert main(["plot", str(tmp_path / "tube.nc"), "--model", "bifurcation", "--plot",
                 str(tmp_path / "f")]) == 2
    assert "vessel 'tube' is not in model 'bifurcation'" in capsys.readouterr().err
    assert not (tmp_path / "f").exists()


@pytest.mark.usefixtures("headless")
def test_cli_plot_with_a_model_file(runs: dict[str, oxyline.Result], tmp_path: Path) -> None:
    import yaml

    (tmp_path / "tube.yaml").write_text(yaml.safe_dump(tube(DRUG)))
    runs["species-only"].to_zarr(tmp_path / "tube.zarr")
    assert main(["plot", str(tmp_path / "tube.zarr"), "--model", str(tmp_path / "tube.yaml"),
                 "--plot", str(tmp_path / "f"), "--quiet"]) == 0
    _check_figures(tmp_path / "f", FIGURES)
