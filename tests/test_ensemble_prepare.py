"""A variant prepared in one core call (``VariantReader.prepare``): what it hands the worker is
what a plain load of the patched model reads (the independent truth: every element read from
scratch by ``load_model``, not only the changed ones), and the names of every patch are
checked before anything runs, naming the variant's number in the whole ensemble."""

from __future__ import annotations

import json
from typing import Any

import pytest

import oxyline
from oxyline.ensemble import apply_patch
from oxyline.ensemble.patch import Patcher
from tests.test_ensemble import TUBE, TUBE_CGS

PATCHES: list[dict[str, Any]] = [
    {"vessels": {"a.b": {"radius": 0.005}}},
    {"boundary_conditions": {"out1": {"distal_resistance": 2e9}}},
    {"scale": {"resistance": 1.5, "vessels": ["c"]}},
    {"blood": {"viscosity": 4e-3}},
    {"vessels": {"d": {"radius": 0.0025}}, "scale": {"compliance": 0.5}},
]


@pytest.mark.parametrize("model", [TUBE, TUBE_CGS], ids=["SI", "cgs"])
@pytest.mark.parametrize("k", range(len(PATCHES)))
def test_a_prepared_variant_is_the_load_of_its_patched_model(model: dict[str, Any],
                                                             k: int) -> None:
    patch = PATCHES[k]
    if model is TUBE_CGS and "blood" in patch:
        patch = {**patch, "blood": {"viscosity": 0.04}}  # poise
    base = oxyline.load_model(model)
    v = Patcher(base).variant(patch, k)
    plain = oxyline.load_model(apply_patch(model, patch))
    assert v.model.canonical == plain.canonical
    assert v.model.period == plain.period
    # the worker gets exactly the elements that differ from the base's, in canonical form
    changed = {i for i, (a, b) in enumerate(zip(plain.canonical["vessels"],
                                                base.canonical["vessels"], strict=True))
               if a != b}
    assert set(v.vessels or {}) >= changed
    for i, vessel in (v.vessels or {}).items():
        assert vessel == plain.canonical["vessels"][i]
    for node, bc in (v.outlets or {}).items():
        assert bc == plain.canonical["boundary_conditions"][node]
    differ = {key for key in ("blood", "transport")
              if plain.canonical.get(key) != base.canonical.get(key)}
    assert set(json.loads(v.patch_json)) == differ
    for key in differ:
        assert json.loads(v.patch_json)[key] == plain.canonical[key]


def test_names_are_checked_for_every_patch_before_anything_runs() -> None:
    patcher = Patcher(oxyline.load_model(TUBE))
    good = {"vessels": {"a.b": {"radius": 0.005}}}
    patcher.check_all([good, {}, {"scale": {"compliance": 0}}])  # a refused value: not here
    with pytest.raises(oxyline.ModelError, match=r"^variant 12: vessels\.zz"):
        patcher.check_all([good, {"vessels": {"zz": {"radius": 1.0}}}], range(11, 13))


def test_a_refused_value_names_the_variant_and_the_patch_path() -> None:
    patcher = Patcher(oxyline.load_model(TUBE))
    with pytest.raises(oxyline.ModelError, match=r"^variant 4: scale\.compliance"):
        patcher.variant({"scale": {"compliance": 0}}, 4)
    # a value the schema refuses: the patch path that set it, then the schema's message
    with pytest.raises(oxyline.ModelError,
                       match=r"^variant 2: vessels\.a\.b\.radius = -0\.001: vessel 'a\.b'"):
        patcher.variant({"vessels": {"a.b": {"radius": -0.001}}}, 2)
    # a section's value (no element): the patch's scalar leaves outside the elements
    with pytest.raises(oxyline.ModelError,
                       match=r"^variant 1: period = -1\.0: model: period must be > 0"):
        patcher.variant({"period": -1.0, "scale": {"resistance": 2.0}}, 1)
