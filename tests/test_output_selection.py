"""Output selection (``simulation: output: {variables, vessels, segments}`` and the
``simulate()`` keywords): a selected run records exactly the selected columns of the full run
(same code path and machine, so the values are equal bit for bit) and nothing else, in memory
and in a streamed Zarr store."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import oxyline
from oxyline import _core, catalogue

FLOW_VARS = ["pressure_in", "flow_out", "segment_flow"]
O2_VARS = ["concentration_out", "wall_flux", "segment_concentration"]


@pytest.fixture(scope="module")
def full() -> oxyline.Result:
    return oxyline.simulate("paper-bifurcated", cycles=1)


def test_the_schema_comes_from_the_core() -> None:
    from oxyline.result import BALANCE, SEGMENT_VARIABLES, SPECIES_VESSEL, VESSEL_VARIABLES

    assert VESSEL_VARIABLES == tuple(_core.VESSEL_VARIABLES)
    assert SEGMENT_VARIABLES == tuple(_core.SEGMENT_VARIABLES)
    assert SPECIES_VESSEL == tuple(_core.SPECIES_VESSEL_VARIABLES)
    assert BALANCE == tuple(_core.BALANCE_VARIABLES)


def test_selected_values_equal_the_full_run_and_memory_follows_the_selection(
        full: oxyline.Result) -> None:
    vessel = full.vessels[1]
    res = oxyline.simulate("paper-bifurcated", cycles=1, variables=FLOW_VARS + O2_VARS,
                           vessels=[vessel])
    i = full.vessels.index(vessel)
    a, b = full._seg_start[i], full._seg_start[i + 1]
    ns = b - a
    # memory: 2 vessel columns + 1 per segment of the one vessel, and for O2 2 vessel columns,
    # 1 per segment and the 5 mass-balance columns
    assert res.vessels == [vessel]
    assert res.data.shape == (full.time.size, 2 + ns)
    sp, fsp = res.species["o2"], full.species["o2"]
    assert sp.vessel_data.shape == (full.time.size, 1, 2)
    assert sp.segment_data.shape == (full.time.size, ns, 1)
    assert np.array_equal(res.time, full.time)
    assert np.array_equal(res.pressure_in, full.pressure_in[:, i:i + 1])
    assert np.array_equal(res.flow_out, full.flow_out[:, i:i + 1])
    assert np.array_equal(res.segment_flow, full.segment_flow[:, a:b])
    assert np.array_equal(res.segment_position, full.segment_position[a:b])
    assert np.array_equal(sp.concentration_out, fsp.concentration_out[:, i:i + 1])
    assert np.array_equal(sp.wall_flux, fsp.wall_flux[:, i:i + 1])
    assert np.array_equal(sp.concentration, fsp.concentration[:, a:b])
    assert np.array_equal(res.po2_out, full.po2_out[:, i:i + 1])
    assert np.array_equal(sp.balance_data, fsp.balance_data)  # whole-network balance kept
    with pytest.raises(AttributeError, match="flow_in' is not in this result's output"):
        res.flow_in  # noqa: B018
    ds = res.to_xarray()
    assert "flow_in" not in ds and "segment_pressure_in" not in ds
    assert np.array_equal(ds["o2_concentration_out"].values, sp.concentration_out)


def test_segments_false_and_vessels_none(full: oxyline.Result) -> None:
    res = oxyline.simulate("paper-bifurcated", cycles=1, segments=False)
    nv = len(full.vessels)
    assert res.data.shape == (full.time.size, 4 * nv) and not res.has_segments
    assert np.array_equal(res.data, full.data[:, :4 * nv])
    assert res.species["o2"].segment_data.shape[1] == 0
    assert np.array_equal(res.species["o2"].vessel_data, full.species["o2"].vessel_data)
    none = oxyline.simulate("paper-bifurcated", cycles=1, vessels="none")
    assert none.data.shape == (full.time.size, 0) and none.vessels == []
    assert np.array_equal(none.species["o2"].balance_data, full.species["o2"].balance_data)


def test_selection_in_the_model_file_and_streamed_to_zarr(full: oxyline.Result,
                                                          tmp_path: Path) -> None:
    model = catalogue.load("paper-bifurcated").to_dict()
    vessel = full.vessels[0]
    # (a new simulation section keeps the file's paper RK4: the same run as `full`)
    model["simulation"] = {"method": "rk4",
                           "output": {"variables": ["flow_in", "concentration_in"],
                                      "vessels": [vessel], "segments": False}}
    res = oxyline.simulate(model, cycles=1)
    assert res.data.shape == (full.time.size, 1)
    assert np.array_equal(res.flow_in[:, 0], full.flow_in[:, 0])
    ds = oxyline.simulate_to_zarr(model, tmp_path / "sel.zarr", cycles=1, time_chunk=64)
    assert {"flow_in", "o2_concentration_in", "po2_in"} <= set(ds.data_vars)
    assert "pressure_in" not in ds and "segment_flow" not in ds and "flow_out" not in ds
    assert ds["flow_in"].shape == (full.time.size, 1)
    assert np.array_equal(ds["flow_in"].values, res.flow_in)
    assert np.array_equal(ds["o2_concentration_in"].values, res.species["o2"].concentration_in)
    back = oxyline.open_result(tmp_path / "sel.zarr")
    assert np.array_equal(back.flow_in, res.flow_in)


@pytest.mark.parametrize(("kw", "match"), [
    ({"variables": ["pressure"]}, "unknown variable 'pressure'"),
    ({"vessels": ["nope"]}, "unknown vessel 'nope'"),
    ({"vessels": "some"}, "unknown vessel 'some'"),
])
def test_unknown_names_are_model_errors(kw: dict, match: str) -> None:
    with pytest.raises(oxyline.ModelError, match=match):
        oxyline.simulate("bifurcation", cycles=1, **kw)
    model = catalogue.load("bifurcation").to_dict()
    model["simulation"] = {"method": "rk4", "output": kw}
    with pytest.raises(oxyline.ModelError, match=match):  # at load time too
        oxyline.load_model(model)


def test_species_variables_need_species() -> None:
    with pytest.raises(oxyline.ModelError, match="'concentration_in' needs species transport"):
        oxyline.simulate("bifurcation", cycles=1, variables=["concentration_in"])


def _output_bytes(res: oxyline.Result) -> int:
    """Bytes of the arrays a result holds its output in: the time column, the flow block and
    each species block (views share their base array: count every buffer once)."""
    bufs = {id(a): a for a in [res.time, res.data]}
    for sp in res.species.values():
        base = sp.vessel_data
        while isinstance(base.base, np.ndarray):  # up to the array the core filled
            base = base.base
        bufs[id(base)] = base
    return sum(a.nbytes for a in bufs.values())


@pytest.mark.parametrize("kw", [{}, {"segments": False},
                                {"variables": FLOW_VARS + O2_VARS, "vessels": 1}])
def test_memory_accounting_matches_the_arrays(kw: dict) -> None:
    # the estimate a run is admitted by (max_memory, OutputSizeWarning) against the nbytes of
    # the arrays the run returns: both count 8-byte numbers, so they agree exactly
    from oxyline import run

    model = oxyline.load_model("paper-bifurcated")
    if "vessels" in kw:  # one vessel, by its position
        kw = {**kw, "vessels": [model.network.output_layout()["vessels"][kw["vessels"]]]}
    s = run._settings(model, {"cycles": 1, **kw})
    need, rows, _ = run._output_size(model, s)
    res = oxyline.simulate(model, cycles=1, **kw)
    assert rows == res.time.size
    assert need == _output_bytes(res)


def test_large_model_default_output(full: oxyline.Result,
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from oxyline import run

    # the default stays complete below the threshold: no warning, every variable
    assert full.vessel_variables == tuple(_core.VESSEL_VARIABLES)
    assert full.species["o2"].vessel_variables == tuple(_core.SPECIES_VESSEL_VARIABLES)
    assert full.has_segments
    # at the threshold (lowered to the model's own segment count) still complete
    segments = int(oxyline.load_model("paper-bifurcated").network.summary()["segments"])
    monkeypatch.setattr(run, "LARGE_MODEL_SEGMENTS", segments)
    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.OutputSizeWarning)
        at = oxyline.simulate("paper-bifurcated", cycles=1, segments=False)
    assert at.vessel_variables == tuple(_core.VESSEL_VARIABLES)
    # above it (lowered so that a small model is "large"): the documented subset, said once
    monkeypatch.setattr(run, "LARGE_MODEL_SEGMENTS", segments - 1)
    with pytest.warns(oxyline.OutputSizeWarning, match="variables='all'") as rec:
        res = oxyline.simulate("paper-bifurcated", cycles=1, vessels=full.vessels)
    assert len(rec) == 1 and "no segment output" in str(rec[0].message)
    assert res.vessel_variables == run.LARGE_MODEL_VARIABLES
    sp, fsp = res.species["o2"], full.species["o2"]
    assert sp.vessel_variables == run.LARGE_MODEL_SPECIES_VARIABLES
    assert not res.has_segments and sp.segment_data.shape[1] == 0
    for name in run.LARGE_MODEL_VARIABLES:  # same run, a subset of its columns: bit-identical
        assert np.array_equal(getattr(res, name), getattr(full, name))
    for name in run.LARGE_MODEL_SPECIES_VARIABLES:
        assert np.array_equal(getattr(sp, name), getattr(fsp, name))
    assert np.array_equal(sp.balance_data, fsp.balance_data)
    # explicit segments: the segment subset too; variables='all' (keyword or model file):
    # everything, no warning
    with pytest.warns(oxyline.OutputSizeWarning, match="segment_flow, segment_concentration"):
        res = oxyline.simulate("paper-bifurcated", cycles=1, segments=True)
    assert res.segment_variables == ("segment_pressure_in", "segment_flow")
    assert res.species["o2"].segment_variables == ("concentration", "wall_flux")
    assert np.array_equal(res.segment_flow, full.segment_flow)
    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.OutputSizeWarning)
        every = oxyline.simulate("paper-bifurcated", cycles=1, variables="all")
        model = catalogue.load("paper-bifurcated").to_dict()
        model["simulation"] = {"method": "rk4", "output": {"variables": "all"}}
        from_file = oxyline.simulate(model, cycles=1)
    for r in (every, from_file):
        assert np.array_equal(r.data, full.data)
        assert np.array_equal(r.species["o2"].vessel_data, fsp.vessel_data)


@pytest.mark.parametrize("chunk_bytes", [1, 1 << 24])  # one row a chunk; the whole run at once
def test_large_model_default_is_a_summary(full: oxyline.Result, chunk_bytes: int,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Above the threshold, without a selection: every vessel's mean/min/max reduced while the
    run streams its rows, and the inlet vessels' time series; against the summary of the
    complete output of the same run (min and max: the same numbers; the mean: a trapezoidal
    sum run chunk by chunk instead of at once, equal to rounding, 1e-12 relative)."""
    from oxyline import large_output, run

    segments = int(oxyline.load_model("paper-bifurcated").network.summary()["segments"])
    monkeypatch.setattr(run, "LARGE_MODEL_SEGMENTS", segments - 1)
    monkeypatch.setattr(large_output, "CHUNK_BYTES", chunk_bytes)
    with pytest.warns(oxyline.OutputSizeWarning, match="mean, min and max") as rec:
        res = oxyline.simulate("paper-bifurcated", cycles=1)
    assert len(rec) == 1 and "inlet vessels" in str(rec[0].message)
    model = oxyline.load_model("paper-bifurcated")
    bcs = model.canonical["boundary_conditions"]
    inlets = [v["name"] for v in model.canonical["vessels"]
              if bcs.get(v["from"], {}).get("type") in ("flow", "pressure")]
    assert res.vessels == inlets and len(inlets) < len(full.vessels)
    cols = [full.vessels.index(v) for v in inlets]
    for name in run.LARGE_MODEL_VARIABLES:  # the same run's columns: bit-identical
        assert np.array_equal(getattr(res, name), getattr(full, name)[:, cols])
    sp, fsp = res.species["o2"], full.species["o2"]
    for name in run.LARGE_MODEL_SPECIES_VARIABLES:
        assert np.array_equal(getattr(sp, name), getattr(fsp, name)[:, cols])
    assert np.array_equal(sp.balance_data, fsp.balance_data)
    assert np.array_equal(res.time, full.time)
    got, want = res.summary(), full.summary()
    assert list(got.index) == full.vessels
    assert set(got.columns) < set(want.columns)
    assert {"flow_in_mean", "po2_out_min", "wall_o2_flux_max"} <= set(got.columns)
    for c in got.columns:
        assert got.attrs["units"][c] == want.attrs["units"][c]
        a, b = got[c].to_numpy(), want[c].to_numpy()
        if c.endswith("_mean"):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
        else:
            assert np.array_equal(a, b)


def test_species_segment_output_alone_reaches_the_files(tmp_path: Path) -> None:
    """A species segment variable selected without any flow segment variable keeps its
    segments' coordinates: it is in the dataset, the NetCDF file and the Zarr store, equal to
    the same column of a run that also records the segments' flow (the same run: a selection
    changes what is recorded, not the arithmetic, so the arrays are equal to the bit)."""
    kw = {"cycles": 1, "dt": 1e-3, "method": "generalized-alpha", "segments": True}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = oxyline.simulate("paper-bifurcated", variables=["flow_in", "segment_wall_flux"],
                                 **kw)
        both = oxyline.simulate("paper-bifurcated",
                                variables=["flow_in", "segment_flow", "segment_wall_flux"], **kw)
    want = both.to_xarray()["segment_wall_o2_flux"].values
    assert np.isfinite(want).all() and np.abs(want).max() > 0
    ds = alone.to_xarray()
    np.testing.assert_array_equal(ds["segment_wall_o2_flux"].values, want)
    np.testing.assert_array_equal(ds["segment_position"].values,
                                  both.to_xarray()["segment_position"].values)
    alone.to_netcdf(tmp_path / "alone.nc")
    back = oxyline.open_result(tmp_path / "alone.nc")
    np.testing.assert_array_equal(back.to_xarray()["segment_wall_o2_flux"].values, want)
    store = oxyline.simulate_to_zarr("paper-bifurcated", tmp_path / "alone.zarr",
                                     variables=["flow_in", "segment_wall_flux"], **kw)
    np.testing.assert_array_equal(store["segment_wall_o2_flux"].values, want)


class _CountingNetwork:
    """A network that counts its output-layout resolutions (the core resolves a selection
    against every vessel's name: ~2 s per million vessels)."""

    def __init__(self, network: object) -> None:
        self._network, self.layouts = network, 0

    def output_layout(self, **kw: object) -> dict:
        self.layouts += 1
        return self._network.output_layout(**kw)

    def __getattr__(self, name: str) -> object:
        return getattr(self._network, name)


def test_a_run_resolves_its_output_selection_once(full: oxyline.Result,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A summarized large-model run asks for its layout in five places (the default, its size,
    the summary stream, the chunks' and the final result): the core resolves it once per
    selection. The same model then run with other selections records exactly those (the
    reused layout is a copy: the result's own edits do not reach the next run)."""
    from oxyline import run

    model = oxyline.load_model("paper-bifurcated")
    segments = int(model.network.summary()["segments"])
    counting = _CountingNetwork(model.network)
    model._network = counting
    monkeypatch.setattr(run, "LARGE_MODEL_SEGMENTS", segments - 1)
    with pytest.warns(oxyline.OutputSizeWarning, match="mean, min and max"):
        summarized = oxyline.simulate(model, cycles=1)
    # the run's selection, and the inlet vessels' time series the result keeps
    assert counting.layouts == 2
    assert summarized.vessel_variables == run.LARGE_MODEL_VARIABLES
    monkeypatch.setattr(run, "LARGE_MODEL_SEGMENTS", 10 * segments)
    flows = oxyline.simulate(model, cycles=1, variables=["flow_in"], segments=False)
    every = oxyline.simulate(model, cycles=1)
    assert flows.vessel_variables == ("flow_in",) and not flows.has_segments
    assert np.array_equal(flows.flow_in, full.flow_in)  # same run, a subset: bit-identical
    assert every.vessel_variables == full.vessel_variables and every.has_segments
    assert np.array_equal(every.data, full.data)
    assert set(every.species) == set(full.species)
