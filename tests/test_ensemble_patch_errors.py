"""Variant patches the core cannot apply, or whose values the model refuses: only that variant
fails, with an error naming the patch path and the value; the other variants are the plain
``simulate()`` runs of their patched models (an independent run of each)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline.ensemble import apply_patch
from tests.test_ensemble import FAST, TUBE, TUBE_CGS


def _plain_summary(model: Any, patch: dict[str, Any]) -> dict[str, np.ndarray]:
    df = oxyline.simulate(apply_patch(model, patch), cycles=2).summary()
    return {c: df[c].to_numpy() for c in df.columns}


def _others_are_plain_runs(ds: Any, model: Any, patches: list[dict[str, Any]],
                           failed: int) -> None:
    for k, patch in enumerate(patches):
        if k == failed:
            continue
        for name, values in _plain_summary(model, patch).items():
            np.testing.assert_array_equal(ds[name].values[k], values, err_msg=f"{k} {name}")


# a scale-only patch of a model in CGS units, and one with a blood patch beside the scale:
# both must name the patch path
@pytest.mark.parametrize(("model", "extra"), [(TUBE_CGS, {}), (TUBE, {"blood": {"viscosity": 4e-3}})])
def test_a_compliance_factor_zero_fails_its_variant_naming_the_path(model: Any,
                                                                    extra: dict[str, Any]
                                                                    ) -> None:
    patches = [{"scale": {"compliance": 0.8}}, {**extra, "scale": {"compliance": 0}},
               {"scale": {"resistance": 1.5}}]
    ds = oxyline.simulate_ensemble(model, patches, **FAST)
    assert ds.status.values.tolist() == [0, 1, 0], ds.error.values
    error = ds.error.values[1]
    # before: "youngs_modulus must be finite, got inf" (no patch path)
    assert error.startswith("variant 1: scale.compliance: factor 0.0 "), error
    assert "= inf" in error and "vessel 'a.b'" in error
    _others_are_plain_runs(ds, model, patches, failed=1)


@pytest.mark.parametrize(("patch", "expected"), [
    ({"scale": {"resistance": "x"}}, "variant 1: scale.resistance: expected a number, got 'x'"),
    ({"scale": {"compliance": float("nan")}},
     "variant 1: scale.compliance: expected a number, got nan"),
    ({"scale": {"resistance": 1e308, "vessels": ["c"]}},
     "variant 1: scale.resistance: factor 1e+308 makes resistance of vessel 'c'"),
    # a value the model refuses: the patch paths that changed the vessel, then the model's text
    ({"vessels": {"d": {"radius": -0.001}}},
     "variant 1: vessels.d.radius = -0.001: vessel 'd'"),
    ({"scale": {"compliance": -2.0, "vessels": ["a.b"]}},
     "variant 1: scale.compliance = -2.0: vessel 'a.b'"),
    ({"boundary_conditions": {"out2": {"resistance": -5.0}}},
     "variant 1: boundary_conditions.out2.resistance = -5.0: boundary condition 'out2'"),
])
def test_refused_patch_values_fail_their_variant_only(patch: dict[str, Any], expected: str
                                                      ) -> None:
    patches = [{"vessels": {"d": {"radius": 0.0025}}}, patch, {}]
    ds = oxyline.simulate_ensemble(TUBE, patches, **FAST)
    assert ds.status.values.tolist() == [0, 1, 0], ds.error.values
    assert ds.error.values[1].startswith(expected), ds.error.values[1]
    _others_are_plain_runs(ds, TUBE, patches, failed=1)


def test_apply_patch_raises_the_refused_value() -> None:
    with pytest.raises(oxyline.ModelError, match=r"variant 0: scale\.compliance: factor 0\.0"):
        apply_patch(TUBE, {"scale": {"compliance": 0}})


def test_a_dataframe_with_a_bad_factor_fails_that_row_only() -> None:
    import pandas as pd

    frame = pd.DataFrame({"scale.compliance": pd.Series([1.2, 0.0, "0.5x"], dtype=object)})
    ds = oxyline.simulate_ensemble(TUBE, frame, **FAST)
    assert ds.status.values.tolist() == [0, 1, 1], ds.error.values
    assert "variant 1: scale.compliance: factor 0.0" in ds.error.values[1]
    assert "variant 2: scale.compliance: expected a number, got '0.5x'" in ds.error.values[2]


def test_on_a_dask_cluster_the_refused_variant_fails_alone() -> None:
    distributed = pytest.importorskip("distributed")
    patches = [{"scale": {"compliance": 0.8}}, {"scale": {"compliance": 0}}, {}]
    local = oxyline.simulate_ensemble(TUBE, patches, **FAST)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        ds = oxyline.simulate_ensemble(TUBE, patches, client=client, **FAST)
    assert ds.status.values.tolist() == [0, 1, 0]
    assert ds.error.values[1].startswith("variant 1: scale.compliance: factor 0.0")
    np.testing.assert_array_equal(ds.pressure_in_mean.values, local.pressure_in_mean.values)
