"""The physical-bounds monitor (docs/physics.md §2.8): maximum principle and
mass balance of the recorded species output, and the validity range of tl-quasisteady."""

from __future__ import annotations

import copy
import re
import warnings

import numpy as np
import pytest

import oxyline
from oxyline import catalogue
from oxyline.monitor import species_bounds


def _with_formulation(name: str, formulation: str) -> dict:
    m = copy.deepcopy(catalogue.load(name).source)
    m["oxygen"]["formulation"] = formulation
    return m


def test_tl_quasisteady_on_the_curved_example_warns_naming_vessel_time_value() -> None:
    """The literal paper form gives 97.4 mmHg from an 85 mmHg inlet (wall 48 mmHg): outside
    the maximum-principle range [48, 85] mmHg, and out of its validity range (the coronary
    stores ~12 % of its flow, which the literal form neglects)."""
    with pytest.warns(oxyline.PhysicalBoundsWarning) as rec:
        res = oxyline.simulate(_with_formulation("paper-curved", "tl-quasisteady"), cycles=4)
    msgs = [str(w.message) for w in rec]
    bounds = next(m for m in msgs if "outside the physical range" in m)
    assert "vessel 'coronary'" in bounds and "[48, 85] mmHg" in bounds
    value = float(re.search(r"has ([0-9.]+) mmHg", bounds).group(1))
    t = float(re.search(r"at t = ([0-9.e-]+) s", bounds).group(1))
    # the reported value is the recorded maximum, at the reported time (independent read-out)
    assert value == pytest.approx(np.nanmax(res.segment_po2), rel=1e-5)
    assert value == pytest.approx(97.4, abs=0.05)
    it = int(np.argmin(np.abs(res.time - t)))
    assert np.nanmax(res.segment_po2[it]) == pytest.approx(value, rel=1e-5)
    validity = next(m for m in msgs if "validity range" in m)
    assert "criterion 2" in validity and "'coronary'" in validity
    assert any("mass balance is off" in m for m in msgs)


def test_the_default_formulation_does_not_warn_on_the_paper_examples() -> None:
    for name in ("paper-curved", "paper-straight", "paper-bifurcated"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", oxyline.PhysicalBoundsWarning)
            oxyline.simulate(catalogue.load(name), cycles=3)


def test_tl_quasisteady_aorta_names_flow_reversal() -> None:
    with pytest.warns(oxyline.PhysicalBoundsWarning, match="criterion 1 .*'aorta'"):
        oxyline.simulate(_with_formulation("paper-straight", "tl-quasisteady"), cycles=3)


def test_tl_quasisteady_in_steady_flow_through_a_rigid_tube_is_silent() -> None:
    """Inside its validity range (steady forward flow, no storage) the literal form equals the
    conservative one (docs/physics.md §2.7) and nothing is reported."""
    m = {"period": 1.0,
         "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 5,
                      "length": 0.05, "radius": 2e-3}],
         "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                 "out": {"type": "resistance", "resistance": 1e8}},
         "oxygen": {"inlet": {"po2": 85}, "wall": {"model": "graetz", "po2": 50},
                    "formulation": "tl-quasisteady"},
         "simulation": {"cycles": 3}}
    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.PhysicalBoundsWarning)
        oxyline.simulate(m)


def test_bounds_come_from_inlet_initial_wall_and_backflow_values() -> None:
    sp = {"name": "x", "inlet": {"kind": "table", "time": [0, 1], "value": [2.0, 3.0]},
          "initial": 1.5,
          "wall": {"model": "permeability", "permeability": 1e-6, "tissue_concentration": 0.5},
          "backflow": {"out": {"kind": "constant", "value": 4.0}}}
    assert species_bounds(sp) == (0.5, 4.0)
    # a prescribed flux is a source: no maximum principle
    assert species_bounds(dict(sp, wall={"model": "flux", "flux": 1e-6})) is None
    # decay pulls towards zero
    assert species_bounds(dict(sp, decay=0.1)) == (0.0, 4.0)


def test_bounds_read_a_species_as_the_model_reads_it() -> None:
    # a permeability wall needs its permeability in the canonical transport section: the
    # bounds read the species with the model's own types and name the missing key
    sp = {"name": "x", "inlet": {"kind": "constant", "value": 2.0},
          "wall": {"model": "permeability", "tissue_concentration": 0.5}}
    with pytest.raises(oxyline.ModelError, match="transport species.*permeability"):
        species_bounds(sp)
    # the canonical section of a model with oxygen gives each species' bounds
    model = oxyline.load_model(_with_formulation("paper-straight", "conservative"))
    assert all(species_bounds(s) is not None for s in model.transport_spec["species"])


def test_bounds_of_a_fourier_inlet_are_its_extremes() -> None:
    # 90 + 10 cos(2πt/T) + 5 sin(4πt/T): extremes of the closed form found on a fine grid
    # (1e6 points, ~1e-9 of the range); the monitor samples 4097 points of one period (its
    # extremes within ~1e-6 of the range)
    inlet = {"kind": "fourier", "period": 0.8, "mean": 90.0, "cos": [10.0], "sin": [0.0, 5.0]}
    t = np.linspace(0.0, 0.8, 1_000_001)
    f = 90.0 + 10.0 * np.cos(2 * np.pi * t / 0.8) + 5.0 * np.sin(4 * np.pi * t / 0.8)
    lo, hi = species_bounds({"name": "x", "inlet": inlet, "wall": {"model": "none"}})
    assert abs(lo - f.min()) < 1e-4 and abs(hi - f.max()) < 1e-4


def _bounds_messages(run) -> list[str]:
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        run()
    return [str(w.message) for w in rec if w.category is oxyline.PhysicalBoundsWarning]


def test_simulate_to_zarr_checks_the_streamed_chunks_like_simulate(tmp_path) -> None:
    """The monitor runs on the chunks simulate_to_zarr streams (97 rows each, so the worst
    value, the largest imbalance and the validity criterion are found across chunks) and
    reports exactly what simulate reports for the whole in-memory output."""
    pytest.importorskip("zarr")
    pytest.importorskip("xarray")
    model = _with_formulation("paper-curved", "tl-quasisteady")
    settings = {"cycles": 4, "output_cycles": "all"}
    whole = _bounds_messages(lambda: oxyline.simulate(model, **settings))
    streamed = _bounds_messages(lambda: oxyline.simulate_to_zarr(
        model, tmp_path / "run.zarr", time_chunk=97, **settings))
    assert len(whole) == 3  # bounds, mass balance, validity
    assert streamed == whole
    assert any("vessel 'coronary'" in m and "[48, 85] mmHg" in m for m in streamed)


def test_simulate_ensemble_records_the_monitor_per_variant_and_runs_on() -> None:
    """Per variant: the literal-paper variant records what simulate of that model warns
    (summary output: no segment columns, as the ensemble runs it), the conservative variant
    nothing; both finish, and one warning names the variant."""
    pytest.importorskip("xarray")
    model = _with_formulation("paper-curved", "tl-quasisteady")
    variants = [{}, {"oxygen": {"formulation": "conservative"}}]
    alone = _bounds_messages(lambda: oxyline.simulate(model, cycles=3, segments=False))
    with pytest.warns(oxyline.PhysicalBoundsWarning, match=r"1 variant\(s\).*variants 0;") as rec:
        ds = oxyline.simulate_ensemble(model, variants, cycles=3, progress=False)
    assert len([w for w in rec if w.category is oxyline.PhysicalBoundsWarning]) == 1
    assert ds.status.values.tolist() == [0, 0]
    assert alone and str(ds.warning.values[0]) == "; ".join(alone)[:400]
    assert str(ds.warning.values[1]) == ""
