"""The accumulated time-error estimate beyond one in-memory run: every vessel's estimate
(`Result.time_error`) written to NetCDF/Zarr and read back by `open_result`, checked against
a converged fixed-step run; ensembles refusing a model file's request for it by name
(docs/solvers.md, "The accumulated error")."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import vessel_time_errors

import oxyline


@pytest.fixture(scope="module")
def paper_runs() -> tuple[oxyline.Result, oxyline.Result]:
    # paper-bifurcated with oxygen, two cycles from the steady start at rtol 1e-3, and its
    # reference: generalized-alpha at T/8000 (second order: its own error ~1e-3 of the
    # controlled run's, docs/solvers.md)
    model = oxyline.load_model("paper-bifurcated")
    kw = {
        "cycles": 2,
        "until_periodic": None,
        "output_every": 1e-3,
        "progress": False,
        "method": "generalized-alpha",
    }
    res = oxyline.simulate(model, rtol=1e-3, estimate_time_error=True, **kw)
    ref = oxyline.simulate(model, dt=model.period / 8000, **kw)
    return res, ref


@pytest.mark.parametrize("suffix", [".nc", ".zarr"])
def test_every_vessels_estimate_is_written_and_read_back(paper_runs, tmp_path, suffix) -> None:
    res, ref = paper_runs
    path = tmp_path / f"run{suffix}"
    if suffix == ".nc":
        res.to_netcdf(path)
    else:
        pytest.importorskip("zarr")
        res.to_zarr(path)
    back = oxyline.open_result(path)
    table = back.time_error
    assert table is not None and list(table.index) == res.vessels
    assert sorted(table.columns) == sorted(res.time_error.columns)
    assert "po2" in table.columns  # the model carries oxygen
    # the same float64 values written and read: exact equality intended (no solver involved)
    for kind in res.time_error.columns:
        assert np.array_equal(
            table[kind].to_numpy(), res.time_error[kind].to_numpy(), equal_nan=True
        ), kind
    # and the file's table is an honest estimate: within 2x of the error achieved against
    # the fixed-step reference, in every vessel whose error is not lost in the reference's
    # own (above 1 % of the worst)
    got = vessel_time_errors(back, ref)
    for kind in ("flow", "pressure", "pulse_pressure"):
        big = got[kind] > 0.01 * np.max(got[kind])
        ratio = table[kind].to_numpy()[big] / got[kind][big]
        assert big.any() and np.all((ratio >= 0.5) & (ratio <= 2.0)), (kind, np.sort(ratio))
    # the worst vessel of each kind is the file's attribute too
    for kind in ("flow", "pressure"):
        assert table[kind].idxmax() == back.settings[f"time_error_vessel_{kind}"]


def test_a_file_without_the_estimate_has_no_table(tmp_path) -> None:
    res = oxyline.simulate("bifurcation", cycles=1, rtol=1e-2, progress=False)
    assert res.time_error is None
    back = oxyline.open_result(res.to_netcdf(tmp_path / "plain.nc"))
    assert back.time_error is None
    assert not [n for n in res.to_xarray().data_vars if str(n).startswith("time_error_")]


@pytest.mark.parametrize("key", ["estimate_time_error", "meet_rtol"])
def test_an_ensemble_refuses_the_model_files_estimate_by_name(key) -> None:
    # a model file asking for an estimate of its run: the variants' runs do not compute it,
    # so the ensemble says so instead of returning variants without it
    m = oxyline.load_model("bifurcation").to_dict()
    m["simulation"] = {**m.get("simulation", {}), key: True, "cycles": 1}
    variants = [{}, {"vessels": {"parent": {"radius": 0.004}}}]
    with pytest.raises(oxyline.ModelError, match=f"simulate_ensemble: {key} .*simulation"):
        oxyline.simulate_ensemble(m, variants, progress=False)
    # the keyword False runs the variants without it, as simulate would without the option
    ds = oxyline.simulate_ensemble(m, variants, progress=False, **{key: False})
    assert ds.status.values.tolist() == [0, 0]


def test_the_explicit_pair_measures_a_stability_limited_run() -> None:
    # bifurcation with the explicit pair at rtol 1e-2: RK4's stability bound, not the
    # tolerance, sets its steps (the same steps at rtol/4: a second run at a tighter rtol
    # measured 0). The last cycle again with the step ceiling over 4^(1/5) measures it.
    # Reference: RK4 at T/32000 (fourth order; its own error ~5e-9 of the flow's amplitude,
    # from its change against T/16000, ~1/400 of the pair's ~2e-6)
    model = oxyline.load_model("bifurcation")
    kw = {"cycles": 2, "until_periodic": None, "output_every": 1e-3, "progress": False}
    plain = oxyline.simulate(model, rtol=1e-2, method="dopri5", **kw)
    res = oxyline.simulate(model, rtol=1e-2, method="dopri5", estimate_time_error=True, **kw)
    ref = oxyline.simulate(model, dt=model.period / 32000, method="rk4", **kw)
    assert res.settings["method"] == "dopri5"
    assert "step ceiling" in res.settings["time_error_from"]
    got = vessel_time_errors(res, ref)
    for kind in ("flow", "pressure", "pulse_pressure"):
        worst, estimated = float(np.max(got[kind])), res.error_estimate[kind]
        assert 0.5 * worst <= estimated <= 2.0 * worst, (kind, worst, estimated)
        ratio = res.time_error[kind].to_numpy() / got[kind]
        assert np.all((ratio >= 0.5) & (ratio <= 2.0)), (kind, np.sort(ratio))
    assert float(np.max(got["flow"])) < 1e-2  # far within rtol: the estimate says how far
    # the run itself is unchanged by it (the same solver path: exact equality intended)
    assert np.array_equal(plain.data, res.data)
    assert plain.settings["steps"] == res.settings["steps"]
