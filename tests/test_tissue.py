"""The wall/tissue compartment (``oxygen.wall: {model: tissue}``, docs/physics.md §3.7) from the
model file: unit conversion and typed errors, outputs with units, exact wall balance in both
integrators, and a straight tube against the 2-D axisymmetric reference with a wall layer."""

from __future__ import annotations

import math

import numpy as np
import pytest

import oxyline
from oxyline._core import transport_section as canonical  # the core reads the section
from oxyline.errors import ModelError

ALPHA = 1.40e-3  # blood O2 solubility, mol m^-3 mmHg^-1
TISSUE = {"model": "tissue", "thickness": 1e-4, "diffusivity": 1.5e-9, "solubility": 1.3e-3,
          "consumption": {"rate": 8e-3}, "outer": {"po2": 20.0}, "radial_cells": 8,
          "boundary_layer": {"model": "graetz"}}


def tube_model(wall: dict, method: str = "rk4", cycles: int = 4, segments: int = 12) -> dict:
    """A rigid straight tube with steady flow (the reference solver's test tube)."""
    return {
        "period": 1.0, "blood": {"density": 1050.0, "viscosity": 3.5e-3},
        "vessels": [{"name": "tube", "from": "in", "to": "out", "length": 0.03456,
                     "radius": 1.5e-3, "segments": segments}],
        "boundary_conditions": {"in": {"type": "flow", "flow": 1.6e-6},
                                "out": {"type": "resistance", "resistance": 1e8}},
        "oxygen": {"inlet": {"po2": 85.0}, "solubility": ALPHA, "diffusivity": 1.2e-9,
                   "wall": wall},
        "simulation": {"cycles": cycles, "method": method,
                       "output": {"cycles": "all", "every": 0.05}},
    }


def test_the_model_file_converts_to_si_wall_concentrations() -> None:
    tr, _ = canonical({"oxygen": tube_model(dict(TISSUE, hypoxic_po2=15.0,
                                                 consumption={"vmax": 5e-3, "km": 2.0}))
                       ["oxygen"]}, 133.322, 1.0, None)
    sp = tr["species"][0]
    t = sp["tissue"]
    # the core works in wall concentrations u = α_t P and φ = α_t/α
    assert t["partition"] == pytest.approx(1.3e-3 / ALPHA, rel=1e-15)
    assert t["consumption"] == {"kind": "michaelis-menten", "vmax": 5e-3, "km": 2.0 * 1.3e-3}
    assert t["outer"] == {"kind": "concentration", "value": 20.0 * 1.3e-3}
    assert t["hypoxic_threshold"] == pytest.approx(15.0 * 1.3e-3, rel=1e-15)
    assert t["radial_cells"] == 8
    # the luminal closure is evaluated against a zero wall value (the wall's own PO2 replaces it)
    assert sp["wall"]["model"] == "graetz" and sp["wall"]["wall_concentration"] == 0.0
    # defaults: 4 radial cells, 10 mmHg, no-flux outer face, Lévêque boundary layer
    tr, _ = canonical({"oxygen": {"inlet": {"po2": 85}, "wall": {
        "model": "tissue", "thickness": 1e-4, "diffusivity": 1.5e-9,
        "consumption": {"rate": 1e-3}}}}, 133.322, 1.0, None)
    t = tr["species"][0]["tissue"]
    assert (t["radial_cells"], t["outer"], t["partition"]) == (4, {"kind": "no-flux"}, 1.0)
    assert t["hypoxic_threshold"] == pytest.approx(10.0 * ALPHA, rel=1e-15)
    assert tr["species"][0]["wall"]["model"] == "leveque"


@pytest.mark.parametrize(("change", "words"), [
    ({"thickness": -1.0}, ["thickness", "-1.0"]),
    ({"consumption": {"rate": -2.0}}, ["rate", "-2.0"]),
    ({"consumption": {"speed": 1.0}}, ["consumption"]),
    ({"outer": "open"}, ["outer", "open"]),
    ({"radial_cells": 2.5}, ["radial_cells", "2.5"]),
    ({"boundary_layer": {"model": "leveque", "po2": 60}}, ["po2"]),
    ({"boundary_layer": {"model": "leveque", "shear": "relaxed"}}, ["cycle-mean"]),
    ({"boundary_layer": {"model": "flux"}}, ["boundary_layer"]),
    ({"colour": 1}, ["colour"]),
])
def test_bad_tissue_settings_are_model_errors(change: dict, words: list[str]) -> None:
    with pytest.raises(ModelError) as e:
        oxyline.load_model(tube_model(dict(TISSUE, **change)))
    for w in words:
        assert w in str(e.value), str(e.value)


def test_a_bad_value_in_a_vessel_override_names_the_vessel() -> None:
    m = tube_model({"model": "graetz", "po2": 60.0})
    m["oxygen"]["per_vessel"] = {"tube": {"wall": dict(TISSUE, diffusivity=0.0)}}
    with pytest.raises(ModelError, match=r"per_vessel 'tube'.*diffusivity"):
        oxyline.load_model(m)


@pytest.mark.parametrize("method", ["rk4", "generalized-alpha"])
def test_outputs_and_exact_wall_balance_in_both_integrators(method: str) -> None:
    res = oxyline.simulate(tube_model(TISSUE, method=method))
    nt = len(res.time)
    for key in ("wall_po2_inner", "wall_po2_outer", "wall_po2_min", "hypoxic_fraction"):
        assert getattr(res, key).shape == (nt, 1)
        assert getattr(res, f"segment_{key}").shape == (nt, 12)
    inner, outer, low = res.wall_po2_inner[-1, 0], res.wall_po2_outer[-1, 0], res.wall_po2_min[-1, 0]
    # the wall lies between its outer value (20) and the lumen (≤ 85), consuming on the way
    assert 20.0 < outer < inner < 85.0 and low <= outer
    assert 0.0 <= res.hypoxic_fraction.min() and res.hypoxic_fraction.max() <= 1.0
    wall = res.species[res.oxygen].tissue.mass_balance
    lumen = res.o2_mass_balance
    # throughput: the inflow over the run (mol); both balances close to round-off
    scale = lumen["inflow"][-1]
    assert abs(wall["residual"]).max() < 1e-9 * scale
    assert abs(lumen["residual"]).max() < 1e-9 * scale
    # what the blood loses through its wall is what the wall receives
    np.testing.assert_allclose(lumen["wall_uptake"] - lumen["wall_uptake"][0], wall["influx"],
                               rtol=0, atol=1e-9 * scale)
    ds = res.to_xarray()
    assert ds["wall_po2_min"].attrs["units"] == "mmHg"
    assert ds["hypoxic_fraction"].attrs["units"] == "1"
    assert ds["o2_wall_mass_consumed"].attrs["units"] == "mol"


def test_the_default_path_has_no_tissue_columns() -> None:
    res = oxyline.simulate(tube_model({"model": "graetz", "po2": 60.0}, cycles=1))
    assert res.species[res.oxygen].tissue is None
    with pytest.raises(AttributeError):
        _ = res.wall_po2_inner


def test_straight_tube_against_the_2d_reference_with_a_wall_layer() -> None:
    """Steady Poiseuille flow into a tube whose consuming wall (zero order, outer PO2 fixed)
    is coupled to the lumen: the 1-D model (Graetz boundary layer in series with the radial
    wall column) against the 2-D axisymmetric solution with the same wall layer. Both at
    their steady state; uptake through the lumen wall and the wall PO2 at the inner face."""
    pytest.importorskip("scipy")
    from validation.axisymmetric import (
        AxisymmetricSolver,
        Grid,
        PeriodicFlow,
        Tube,
        WallLayer,
    )

    tube = Tube(radius=1.5e-3, length=0.03456)
    layer = WallLayer(thickness=1e-4, diffusivity=1.5e-9, solubility=1.3e-3, rate=8e-3,
                      outer_po2=20.0, cells=8)
    ref = AxisymmetricSolver(tube, PeriodicFlow(1.0, 1.6e-6), layer, 85.0,
                             Grid(32, 48, steps_per_period=10)).periodic(tol=1e-9)
    # the wall's diffusion time h²/D ≈ 7 s: 30 s reach the steady state
    res = oxyline.simulate(tube_model(TISSUE, method="generalized-alpha", cycles=30, segments=24))
    uptake = res.wall_o2_flux[-1, 0]
    # consumption alone: rate × wall volume, the same in both (the wall is above 0 everywhere)
    consumed = 8e-3 * math.pi * ((1.5e-3 + 1e-4) ** 2 - 1.5e-3**2) * 0.03456
    print(f"uptake 1-D {uptake:.6e}, 2-D {ref.uptake:.6e} mol/s "
          f"({uptake / ref.uptake - 1:+.2%}); consumption {consumed:.6e}")
    # measured: uptake −0.8 %, inner wall PO2 −0.4 mmHg (49.54 vs 49.96); before the conjugate
    # correction of the boundary layer (docs/physics.md §3.7) −5.1 % and −2.6 mmHg. The 2-D
    # solution is converged (64×96 cells: +0.06 %), the 1-D one too (48 segments: −0.06 %).
    # The tolerances bound the closure's model error (the issue's 2 %), not round-off.
    assert uptake == pytest.approx(ref.uptake, rel=0.02)
    # the innermost wall cell's PO2, averaged along the tube (both: 8 equal wall cells)
    inner_2d = float(np.average(ref.state[32], weights=np.diff(ref.x_faces)))
    inner_1d = float(res.wall_po2_inner[-1, 0])
    print(f"inner wall PO2 1-D {inner_1d:.3f}, 2-D {inner_2d:.3f} mmHg")
    assert inner_1d == pytest.approx(inner_2d, abs=0.02 * (85.0 - 20.0))
    # at the steady state the flux into the wall is its consumption plus what leaves outward
    wall = res.species[res.oxygen].tissue.mass_balance
    assert uptake > consumed
    assert wall["consumed"][-1] > 0.0
    assert res.wall_po2_min[-1, 0] > 20.0 - 1e-9


def test_tissue_outputs_survive_a_selection_and_a_file_round_trip(tmp_path) -> None:
    model = tube_model(TISSUE, method="generalized-alpha", cycles=1)
    # an output selection records the tissue columns whole
    sel = oxyline.simulate(model, variables=["concentration_out", "segment_concentration"])
    full = oxyline.simulate(model)
    np.testing.assert_array_equal(sel.wall_po2_min, full.wall_po2_min)
    np.testing.assert_array_equal(sel.segment_hypoxic_fraction.shape, (len(sel.time), 12))
    back = oxyline.open_result(full.to_netcdf(tmp_path / "t.nc"))
    for key in ("wall_po2_inner", "wall_po2_min", "hypoxic_fraction", "segment_wall_po2_outer"):
        np.testing.assert_array_equal(getattr(back, key), getattr(full, key))
    a = full.species[full.oxygen].tissue.mass_balance
    b = back.species[back.oxygen].tissue.mass_balance
    np.testing.assert_array_equal(a["residual"], b["residual"])


# (tissue override, WallLayer override, flow factor): no-flux outer face (the zero-order wall
# then fixes the flux: the constant-flux limit of the conjugate closure), a thick
# Michaelis–Menten wall, four times the flow (a thinner layer, so the wall's share of the
# resistance grows), a thin wall against a higher outer PO2
CONJUGATE_CASES = {
    "no-flux": ({"outer": "no-flux"}, {"outer_po2": None}, 1.0),
    "thick-mm": ({"thickness": 3e-4, "consumption": {"vmax": 8e-3, "km": 2.0}},
                 {"thickness": 3e-4, "rate": 8e-3, "km": 2.0}, 1.0),
    "flow-x4": ({}, {}, 4.0),
    "thin": ({"thickness": 3e-5, "consumption": {"rate": 2e-3}, "outer": {"po2": 40.0}},
             {"thickness": 3e-5, "rate": 2e-3, "outer_po2": 40.0}, 1.0),
}


@pytest.mark.parametrize("case", sorted(CONJUGATE_CASES))
@pytest.mark.parametrize("layer", ["graetz", "leveque"])
def test_conjugate_closure_against_the_2d_reference(case: str, layer: str) -> None:
    """The conjugate boundary-layer closure (docs/physics.md §3.7) against the 2-D solution
    with the same wall layer, in walls that take from part to all (no-flux) of the series
    resistance: steady uptake within the issue's 2 % and the innermost wall PO2 within 2 %
    of the PO2 span.
    Measured (Graetz / Lévêque): no-flux −0.01/−0.01 %, thick-mm +0.16/+0.76 %, flow-x4
    −0.43/−0.05 %, thin −1.17/+0.16 %."""
    pytest.importorskip("scipy")
    from validation.axisymmetric import (
        AxisymmetricSolver,
        Grid,
        PeriodicFlow,
        Tube,
        WallLayer,
    )

    tissue_over, layer_over, qf = CONJUGATE_CASES[case]
    kw = {"thickness": 1e-4, "diffusivity": 1.5e-9, "solubility": 1.3e-3, "rate": 8e-3,
          "outer_po2": 20.0, "cells": 8, **layer_over}
    ref = AxisymmetricSolver(Tube(radius=1.5e-3, length=0.03456), PeriodicFlow(1.0, 1.6e-6 * qf),
                             WallLayer(**kw), 85.0,
                             Grid(32, 48, steps_per_period=10)).periodic(tol=1e-9)
    wall = {**TISSUE, **tissue_over, "boundary_layer": {"model": layer}}
    model = tube_model(wall, method="generalized-alpha", cycles=60, segments=24)
    model["boundary_conditions"]["in"]["flow"] = 1.6e-6 * qf
    res = oxyline.simulate(model)
    assert res.wall_o2_flux[-1, 0] == pytest.approx(ref.uptake, rel=0.02)
    inner_2d = float(np.average(ref.state[32], weights=np.diff(ref.x_faces)))
    assert res.wall_po2_inner[-1, 0] == pytest.approx(inner_2d, abs=0.02 * (85.0 - 20.0))


def test_the_constant_flux_leveque_ratio_is_the_similarity_solution() -> None:
    """The conjugate closure's constant-flux limit (closure.rs LEVEQUE_FLUX_RATIO = 1.2092)
    re-derived independently: the Lévêque constant-flux similarity problem F'' = 3η(F − ηF'),
    F'(0) = −1, F(∞) = 0 solved with scipy; the local Sherwood ratio to the constant-wall
    layer is Γ(4/3)/F(0). Tolerance: the BVP's own (1e-8)."""
    scipy_integrate = pytest.importorskip("scipy.integrate")
    x = np.linspace(0.0, 8.0, 2000)
    y0 = np.vstack([np.exp(-x), -np.exp(-x)])
    sol = scipy_integrate.solve_bvp(
        lambda e, y: np.vstack([y[1], 3.0 * e * (y[0] - e * y[1])]),
        lambda a, b: np.array([a[1] + 1.0, b[0]]), x, y0, tol=1e-10, max_nodes=100000)
    assert sol.status == 0
    ratio = math.gamma(4.0 / 3.0) / float(sol.sol(0.0)[0])
    assert ratio == pytest.approx(1.209199576, abs=1e-8)
