"""A streamed Zarr store chunked by time and by segment, read lazily with Dask: the O2 delivered
to each region of a binary tree (wall uptake summed over the region's segments) equals the
region's O2 mass balance read from the same store, and the store's chunks are those asked for."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import oxyline

pytest.importorskip("zarr")
pytest.importorskip("dask")
xr = pytest.importorskip("xarray")

DEPTH, PER_VESSEL = 5, 4  # 31 vessels, 124 segments
FIRST_REGION, LAST_REGION = 3, 6  # heap indices of the third generation: four regions


def _tree() -> dict[str, Any]:
    """Symmetric binary tree in heap order (v{i} feeds v{2i+1}, v{2i+2}), RCR outlets,
    a pulsatile inflow, O2 taken up through mass-transfer walls."""
    vessels: list[dict[str, Any]] = []
    bcs: dict[str, Any] = {"in": {"type": "flow", "time": [0.0, 0.2, 0.4, 1.0],
                                  "flow": [2e-5, 1.5e-4, 2e-5, 2e-5]}}
    leaves = 2 ** (DEPTH - 1)
    for i in range(2 ** DEPTH - 1):
        level = int(math.log2(i + 1))
        r = 0.008 * 2.0 ** (-level / 3.0)
        vessels.append({"name": f"v{i}", "from": "in" if i == 0 else f"n{(i - 1) // 2}",
                        "to": f"n{i}", "length": 12 * r, "radius": r,
                        "wall_thickness": 0.1 * r, "youngs_modulus": 5e5,
                        "segments": PER_VESSEL})
        if level == DEPTH - 1:
            bcs[f"n{i}"] = {"type": "rcr", "proximal_resistance": 1.5e7 * leaves,
                            "capacitance": 1e-8 / leaves, "distal_resistance": 1.1e8 * leaves}
    return {"name": "regions", "period": 1.0, "vessels": vessels, "boundary_conditions": bcs,
            "oxygen": {"inlet": {"po2": 95.0}, "hemoglobin": "none",
                       "wall": {"model": "mass-transfer", "k": 1e-4, "po2": 20.0}}}


def _subtree(root: int) -> list[int]:
    out, todo = [], [root]
    while todo:
        i = todo.pop()
        if i < 2 ** DEPTH - 1:
            out.append(i)
            todo += [2 * i + 1, 2 * i + 2]
    return sorted(out)


def _cycle_mean(a: Any, t: np.ndarray) -> float:
    return float(np.trapezoid(np.asarray(a, dtype=float), t, axis=0) / (t[-1] - t[0]))


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("regions") / "tree.zarr"
    oxyline.simulate_to_zarr(_tree(), path, cycles=8, time_chunk=200, segment_chunk=16,
                             variables=["flux_in", "flux_out", "segment_flow",
                                        "segment_wall_flux"], segments=True)
    return path


def test_the_store_is_chunked_by_time_and_segment(store: Path) -> None:
    import dask
    import zarr

    ds = xr.open_zarr(store, chunks={})
    n_time = ds.sizes["time"]
    assert ds.sizes["segment"] == (2 ** DEPTH - 1) * PER_VESSEL
    assert zarr.open_array(store / "segment_wall_o2_flux", mode="r").chunks == (200, 16)
    assert zarr.open_array(store / "o2_flux_in", mode="r").chunks == (200, 16)  # 31 vessels
    chunks = ds["segment_wall_o2_flux"].data.chunks
    assert chunks[0][0] == 200 and sum(chunks[0]) == n_time
    assert chunks[1] == (16,) * 7 + (12,)
    # one region's segments: the dask graph reads only the chunks holding them
    seg_vessel = [str(v) for v in ds["segment_vessel"].values]
    last = np.flatnonzero(np.isin(seg_vessel, [f"v{i}" for i in range(15, 19)]))
    sel = ds["segment_wall_o2_flux"].isel(segment=last).data
    (culled,) = dask.optimize(sel)
    read = {k for k in dict(culled.__dask_graph__()) if isinstance(k, tuple)
            and str(k[0]).startswith("open_dataset")}
    assert read and {k[-1] for k in read} == {int(s) // 16 for s in last}


def test_lazy_regional_uptake_equals_the_regional_mass_balance(store: Path) -> None:
    """Cycle-mean uptake of a region, summed lazily with Dask over its segments, against the
    O2 flux into its first vessel minus the flux out of its terminal vessels (trapezoidal means
    of the same output rows). What separates them is the O2 stored in the region, which the
    store does not hold per region: the tolerance is the whole tree's change of stored O2 over
    the cycle (the store's balance record) relative to its uptake, plus 1e-3 for the
    trapezoidal means of fluxes ~100x the uptake (an in - out difference)."""
    ds = xr.open_zarr(store, chunks={})
    t = np.asarray(ds["time"].values, dtype=float)
    seg_vessel = [str(v) for v in ds["segment_vessel"].values]
    region_of = {f"v{i}": f"v{root}" for root in range(FIRST_REGION, LAST_REGION + 1)
                 for i in _subtree(root)}
    labels = [region_of.get(v, "trunk") for v in seg_vessel]
    per_region = ds["segment_wall_o2_flux"].assign_coords(region=("segment", labels)) \
        .groupby("region").sum()
    uptake = (per_region.integrate("time") / (t[-1] - t[0])).compute()
    stored = ds["o2_mass_stored"].values
    drift = abs(stored[-1] - stored[0]) / (t[-1] - t[0]) / float(uptake.sum())
    assert drift < 0.02  # eight cycles: near periodic
    tol = drift + 1e-3
    flux_in = ds["o2_flux_in"].load()
    flux_out = ds["o2_flux_out"].load()
    leaves = range(2 ** (DEPTH - 1) - 1, 2 ** DEPTH - 1)
    for root in range(FIRST_REGION, LAST_REGION + 1):
        ends = [f"v{i}" for i in _subtree(root) if i in leaves]
        balance = _cycle_mean(flux_in.sel(vessel=f"v{root}"), t) \
            - _cycle_mean(flux_out.sel(vessel=ends).sum("vessel"), t)
        got = float(uptake.sel(region=f"v{root}"))
        print(f"v{root}: uptake {got:.6e} mol/s, in - out {balance:.6e} mol/s, "
              f"rel {abs(got - balance) / got:.2e} (tolerance {tol:.2e})")
        assert got > 0
        assert got == pytest.approx(balance, rel=tol)


def test_segment_chunk_must_be_a_positive_integer(tmp_path: Path) -> None:
    for bad in (0, -3, 2.5, True):
        with pytest.raises(oxyline.ModelError, match="segment_chunk"):
            oxyline.simulate_to_zarr("bifurcation", tmp_path / "x.zarr", segment_chunk=bad)


def _region_codes(vessels: Any) -> tuple[np.ndarray, list[str]]:
    """Integer region of each vessel of the store (in its order): 0..3 for the subtrees of
    v3..v6, 4 for the trunk above them."""
    code_of = {f"v{i}": root - FIRST_REGION for root in range(FIRST_REGION, LAST_REGION + 1)
               for i in _subtree(root)}
    names = [f"v{root}" for root in range(FIRST_REGION, LAST_REGION + 1)] + ["trunk"]
    return np.array([code_of.get(str(v), len(names) - 1) for v in vessels], dtype=np.int32), names


def test_delivery_by_region_codes_is_conserved_and_meets_each_regions_balance(store: Path
                                                                             ) -> None:
    """The lazy reduction by integer region codes (`oxyline.io.regions.region_sum`): the
    regions' delivery sums to the whole tree's wall uptake, both as the sum over the segment
    axis without any grouping (to rounding: 1e-12) and as the core's own record of the O2
    taken through the walls over the cycle, integrated by the transport scheme over every
    step, which the trapezoidal mean of the 1 ms output rows approximates (measured 8e-5;
    tolerance 3e-4, the two quadratures of the same flux); and each region's delivery meets
    its mass balance, as the grouping by name above."""
    from oxyline.io.regions import region_sum

    ds = xr.open_zarr(store, chunks={})
    t = np.asarray(ds["time"].values, dtype=float)
    period = t[-1] - t[0]
    codes, names = _region_codes(ds["vessel"].values)
    per_region = region_sum(ds, "segment_wall_o2_flux", codes, names)
    assert per_region.dims == ("time", "region") and per_region.chunks is not None  # lazy
    delivery = (per_region.integrate("time") / period).compute()
    whole = float((ds["segment_wall_o2_flux"].sum("segment").integrate("time") / period)
                  .compute())
    uptake = ds["o2_mass_wall_uptake"].values
    recorded = float(uptake[-1] - uptake[0]) / period
    total = float(delivery.sum())
    print(f"regions {total:.9e}, segments {whole:.9e}, balance record {recorded:.9e} mol/s")
    assert total == pytest.approx(whole, rel=1e-12)
    assert total == pytest.approx(recorded, rel=3e-4)
    # each region against its own mass balance (tolerance as above: the stored-O2 drift)
    stored = ds["o2_mass_stored"].values
    tol = abs(stored[-1] - stored[0]) / period / total + 1e-3
    flux_in, flux_out = ds["o2_flux_in"].load(), ds["o2_flux_out"].load()
    leaves = range(2 ** (DEPTH - 1) - 1, 2 ** DEPTH - 1)
    for root in range(FIRST_REGION, LAST_REGION + 1):
        ends = [f"v{i}" for i in _subtree(root) if i in leaves]
        balance = _cycle_mean(flux_in.sel(vessel=f"v{root}"), t) \
            - _cycle_mean(flux_out.sel(vessel=ends).sum("vessel"), t)
        assert float(delivery.sel(region=f"v{root}")) == pytest.approx(balance, rel=tol)


def test_region_sum_reads_each_chunk_once_and_only_those_needed(store: Path) -> None:
    """The graph of the reduction reads every stored chunk of the variable, each by one task
    (its block's sums: a chunk is freed once reduced, memory bounded by chunks), and a time
    window only its own time chunks."""
    from dask.core import flatten, get_dependencies

    from oxyline.io.regions import region_sum

    ds = xr.open_zarr(store, chunks={})
    codes, names = _region_codes(ds["vessel"].values)

    def readers(arr: Any) -> dict[tuple[int, ...], int]:
        """Stored chunk (time, segment block) -> the number of tasks reading it."""
        graph = dict(arr.__dask_graph__().cull(set(flatten(arr.__dask_keys__()))))
        out = {k[1:]: 0 for k in graph if isinstance(k, tuple)
               and str(k[0]).startswith("open_dataset-segment_wall_o2_flux")}
        for key in graph:
            for dep in get_dependencies(graph, key):
                if isinstance(dep, tuple) and dep[1:] in out and str(dep[0]).startswith(
                        "open_dataset-segment_wall_o2_flux"):
                    out[dep[1:]] += 1
        return out

    per_region = region_sum(ds, "segment_wall_o2_flux", codes, names)
    n_t, n_s = (len(c) for c in ds["segment_wall_o2_flux"].data.chunks)
    assert n_t > 1 and n_s > 1
    full = readers(per_region.data)
    assert sorted(full) == [(i, j) for i in range(n_t) for j in range(n_s)]
    assert set(full.values()) == {1}
    window = readers(per_region.isel(time=slice(0, 150)).data)  # the first of 200-row chunks
    assert sorted(window) == [(0, j) for j in range(n_s)]


def test_region_sum_refuses_codes_not_one_per_vessel(store: Path) -> None:
    from oxyline.io.regions import region_sum

    ds = xr.open_zarr(store, chunks={})
    with pytest.raises(oxyline.ModelError, match="one integer region code per vessel"):
        region_sum(ds, "segment_wall_o2_flux", np.zeros(3, dtype=int))
    with pytest.raises(oxyline.ModelError, match="no variable 'segment_nope'"):
        region_sum(ds, "segment_nope", np.zeros(ds.sizes["vessel"], dtype=int))
