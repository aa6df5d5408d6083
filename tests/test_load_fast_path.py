"""The load fast path (plain geometric vessels, one structural copy of the user's dict) gives the
same canonical model as the full per-key check, and the loaded model owns its description."""

from __future__ import annotations

import json
from typing import Any

import pytest

import oxyline
from oxyline import _core
from oxyline.units import factor

VESSELS: list[dict[str, Any]] = [
    {"name": "a", "from": "in", "to": "j", "length": 0.05, "radius": 0.003},
    {"name": "b", "from": "j", "to": "o", "length": 1, "radius_in": 0.003, "radius_out": 0.002,
     "wall_thickness": 3e-4, "youngs_modulus": 400000, "poisson_ratio": 0.5, "segments": 3,
     "arrangement": "pi", "output": 0, "description": "tapered"},
]


#: the canonical forms of VESSELS, written by hand (SI: the numbers as given, ints as floats)
CANONICAL: list[dict[str, Any]] = [
    {"name": "a", "from": "in", "to": "j",
     "geometry": {"length": 0.05, "radius_in": 0.003, "radius_out": 0.003}},
    {"name": "b", "from": "j", "to": "o", "segments": 3, "arrangement": "pi", "output": False,
     "geometry": {"length": 1.0, "radius_in": 0.003, "radius_out": 0.002,
                  "wall_thickness": 3e-4, "youngs_modulus": 400000.0, "poisson_ratio": 0.5}},
]


@pytest.mark.parametrize("i", [0, 1], ids=["uniform", "tapered"])
def test_the_fast_reader_takes_plain_vessels_the_schema_reads_as_written(i: int) -> None:
    assert _core.NativeParts([VESSELS[i]], "SI").slow_vessels() == []
    full = _core.read_vessels([VESSELS[i]], "SI")[0]
    assert full == CANONICAL[i]
    assert all(type(x) is float for x in full["geometry"].values())  # ints become floats


@pytest.mark.parametrize("edit", [
    {"radius": float("nan")}, {"length": "1"}, {"segments": 2.0}, {"segments": True},
    {"radius_in": 0.001}, {"wall_thickness": None}, {"poisson_ratio": float("inf")},
    {"lumped": {"resistance": 1.0}}, {"radiuss": 1.0}, {"youngs_modulus": -1.0},
])
def test_fast_vessel_leaves_anything_doubtful_to_the_full_check(edit: dict[str, Any]) -> None:
    assert _core.NativeParts([{**VESSELS[0], **edit}], "SI").slow_vessels() == [0]


def test_the_model_owns_its_description() -> None:
    d = {"name": "t", "period": 1.0, "vessels": [dict(v) for v in VESSELS],
         "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                 "o": {"type": "resistance", "resistance": 1e9}}}
    m = oxyline.load_model(d)
    d["vessels"][0]["radius"] = 1.0
    d["boundary_conditions"]["o"]["resistance"] = 2.0
    assert m.to_dict()["vessels"][0]["radius"] == 0.003
    assert m.to_dict()["boundary_conditions"]["o"]["resistance"] == 1e9


def test_a_large_models_packed_description_reads_back_as_given(monkeypatch: Any) -> None:
    """Above the packing threshold the model keeps its description packed: every read of it
    (``source``, ``to_dict``, a pickled copy, a run's recorded description) gives back the
    dict the user handed over, and an edit of one read does not reach the model."""
    import pickle

    from oxyline import model as model_module

    monkeypatch.setattr(model_module, "PACKED_SOURCE_SEGMENTS", 3)  # this model: 4 segments
    d = {"name": "t", "period": 1.0, "vessels": [dict(v) for v in VESSELS],
         "boundary_conditions": {"in": {"type": "flow", "value": 1e-6},
                                 "o": {"type": "resistance", "resistance": 1e9}}}
    m = oxyline.load_model(d)
    assert m._packed is not None and m._source is None  # packed, no dicts kept
    assert m.source == d and m.to_dict() == d
    m.source["vessels"][0]["radius"] = 1.0  # a read is a copy
    assert m.to_dict()["vessels"][0]["radius"] == 0.003
    assert pickle.loads(pickle.dumps(m)).to_dict() == d
    res = oxyline.simulate(m, cycles=1, dt=1e-3)
    assert res.model_json is not None and json.loads(res.model_json) == d
    monkeypatch.setattr(model_module, "PACKED_SOURCE_SEGMENTS", 4)  # at the threshold: as is
    assert oxyline.load_model(d)._packed is None


def test_a_description_large_by_its_own_count_is_packed_without_a_copy(monkeypatch: Any) -> None:
    """A description whose vessels' own ``segments`` already pass the packing threshold is
    read by the core from the caller's dict and packed as read, never copied as dicts (the
    copy would sit under the network build's peak); one that passes it only once segmented
    (``segmentation``) is copied and packed after the build, as before. Either way the
    model's description is the dict as handed over, untouched by later edits of it."""
    from oxyline import model as model_module

    copied: list[Any] = []
    copy = model_module.copy_description

    def recording_copy(data: Any) -> Any:
        if isinstance(data, dict) and "vessels" in data:
            copied.append(data)
        return copy(data)

    monkeypatch.setattr(model_module, "copy_description", recording_copy)
    monkeypatch.setattr(model_module, "PACKED_SOURCE_SEGMENTS", 3)
    bcs = {"in": {"type": "flow", "value": 1e-6}, "o": {"type": "resistance", "resistance": 1e9}}
    # a: 1 (no count), b: 3 -> 4 segments by the description itself
    d = {"name": "t", "period": 1.0, "vessels": [dict(v) for v in VESSELS],
         "boundary_conditions": bcs}
    m = oxyline.load_model(d)
    assert copied == [] and m._packed is not None and m._source is None
    as_given = json.loads(json.dumps(d))
    d["vessels"][0]["radius"] = 1.0  # the caller's dict is the caller's
    assert m.source == as_given
    # 1 + 1 segments by the description, 20 mm segments give more than 3
    d = {"name": "t", "period": 1.0, "segmentation": {"max_length": 0.02},
         "vessels": [{k: v for k, v in dict(w).items() if k != "segments"} for w in VESSELS],
         "boundary_conditions": bcs}
    m = oxyline.load_model(d)
    assert m.summary()["segments"] > 3
    assert len(copied) == 1 and m._packed is not None and m.source == d


OUTLETS: list[dict[str, Any]] = [
    {"type": "rcr", "proximal_resistance": 1e8, "capacitance": 1e-10, "distal_resistance": 9e8},
    {"type": "rcr", "proximal_resistance": 1, "capacitance": 1e-10, "distal_resistance": 9,
     "pressure": 1000},
    {"type": "resistance", "resistance": 3e9},
    {"type": "resistance", "resistance": 3e9, "pressure": 0},
]


@pytest.mark.parametrize("bc", OUTLETS, ids=["rcr", "rcr-pressure", "resistance", "resistance-p"])
@pytest.mark.parametrize("units", ["SI", "cgs"])
def test_the_fast_reader_takes_plain_outlets(bc: dict[str, Any], units: str) -> None:
    parts = _core.NativeParts([VESSELS[0]], units)
    assert parts.read_outlets({"x": bc}, units) == []
    # the schema's full check: every number times its unit factor, the pressure a constant
    full = _core.read_conditions({"x": bc}, units)[0]["x"]
    scale = {"resistance": "resistance", "proximal_resistance": "resistance",
             "distal_resistance": "resistance", "capacitance": "capacitance"}
    for k, q in scale.items():
        if k in bc:
            assert full[k] == factor(units, q) * bc[k]
    assert full["pressure"] == {"kind": "constant",
                                "value": factor(units, "pressure") * bc.get("pressure", 0.0)}


@pytest.mark.parametrize("edit", [
    {"capacitance": float("nan")}, {"pressure": {"time": [0, 1], "pressure": [0, 1]}},
    {"pressure": None}, {"type": "RCR"}, {"distal_resistance": "9"}, {"resistence": 1.0},
])
def test_fast_outlet_leaves_anything_doubtful_to_the_full_check(edit: dict[str, Any]) -> None:
    parts = _core.NativeParts([VESSELS[0]], "SI")
    assert parts.read_outlets({"x": {**OUTLETS[0], **edit}}, "SI") == ["x"]


def _handover_model() -> oxyline.Model:
    d = {"name": "t", "period": 1.0,
         "vessels": [dict(v) for v in VESSELS] + [
             {"name": "c", "from": "j", "to": "o2", "segments": 2, "arrangement": "RCL",
              "lumped": {"resistance": 1e8, "capacitance": 1e-10, "inductance": 1e5,
                         "stenosis_coefficient": -3e11}}],
         "boundary_conditions": {"in": {"type": "flow", "value": 1e-6}, 
             "o": OUTLETS[1], "o2": OUTLETS[3]}}
    return oxyline.load_model(d)


def test_the_dict_handover_builds_the_network_the_json_text_builds() -> None:
    """Vessels and plain outlets go to the core as the dicts themselves; the whole model as JSON
    text is the independent reference. The floats are the same numbers either way (Python's
    repr round-trips, and the core reads a Python float exactly), so the assembled segment
    table and the steady state must agree to the last bit."""
    import json

    import numpy as np

    from oxyline import _core

    m = _handover_model()
    ref = _core.Network(json.dumps(m.canonical))
    a, b = m.network.segment_table(), ref.segment_table()
    assert a["vessel_names"] == b["vessel_names"] == ["a", "b", "c"]
    for k in ("resistance", "inductance", "compliance", "stenosis", "volume", "radius_in"):
        np.testing.assert_array_equal(a[k], b[k])
    np.testing.assert_array_equal(m.network.steady_state()["state"], ref.steady_state()["state"])
    assert m.network.unknown_names() == ref.unknown_names()
    assert "flow in vessel 'b' segment 2" in ref.unknown_names()


@pytest.mark.parametrize("edit, message", [
    ({"radius_in": 1.0}, "vessel 'a': unknown field `radius_in`"),
    ({"segments": -1}, "vessel 'a': 'segments' must be an integer"),
    ({"name": 3}, "'name' must be a string"),
    ({"geometry": {"length": "1", "radius_in": 1e-3, "radius_out": 1e-3}},
     r"vessel 'a': 'geometry.length' must be a number, got '1'"),
])
def test_a_bad_canonical_vessel_dict_is_a_model_error_naming_it(edit: dict[str, Any],
                                                                 message: str) -> None:
    """A canonical model edited by hand still gets typed errors from the dict hand-over."""
    from oxyline.model import _network

    canon = _handover_model().canonical
    canon["vessels"][0] = {**canon["vessels"][0], **edit}
    with pytest.raises(oxyline.ModelError, match=message):
        _network(canon)


def test_a_bad_canonical_condition_is_a_model_error_naming_it() -> None:
    """Every canonical condition (tagged by its type) is read by the core from the dict; a
    bad value is named with its condition (serde reads a tagged variant from its own buffer,
    so the key is not named)."""
    from oxyline.model import _network

    canon = _handover_model().canonical
    canon["boundary_conditions"]["o"] = {**canon["boundary_conditions"]["o"],
                                         "capacitance": "1e-10"}
    with pytest.raises(oxyline.ModelError,
                       match="boundary condition 'o': must be a number, got string \"1e-10\""):
        _network(canon)
    canon["boundary_conditions"]["o"] = {"type": "windkessel"}
    with pytest.raises(oxyline.ModelError, match="boundary condition 'o': .*windkessel"):
        _network(canon)


def test_a_released_canonical_is_written_again_as_it_was() -> None:
    """`load_model` releases the canonical dicts once the core has the model;
    asking for them writes them again from `source`. Truth: the description of the same dict
    converted before any release, and the core's segment table of a network built from the
    rewritten description (a different path: the JSON text, not the first hand-over)."""
    import json
    import pickle

    from oxyline.ensemble.patch import variant_model

    d = oxyline.catalogue.load("bifurcation").to_dict()
    d["oxygen"] = {"inlet": {"po2": 95.0}, "wall": {"model": "graetz", "po2": 50.0}}
    first = variant_model(json.loads(json.dumps(d))).canonical
    m = oxyline.load_model(d)
    assert m.__dict__["_canonical"] is None  # released
    assert m.vessel_names == [v["name"] for v in first["vessels"]]
    assert m.transport_spec == first["transport"]
    assert m.__dict__["_canonical"] is None  # neither wrote it again
    again = pickle.loads(pickle.dumps(m))
    assert m.canonical == first and again.canonical == first
    net = oxyline._core.Network(json.dumps(m.canonical))
    a, b = net.segment_table(), m.network.segment_table()
    assert all((a[k] == b[k]).all() for k in ("resistance", "compliance", "volume"))


def _mixed_model(units: str) -> dict[str, Any]:
    """Plain vessels and outlets (read by the core's binding) around elements it leaves to
    the full Python check: a lumped vessel in the middle of the list, a vessel name that is
    an int, a table-driven outlet pressure and an outlet type spelled in capitals."""
    return {"name": "mixed", "units": units, "period": 1.0,
            "vessels": [dict(VESSELS[0]),
                        {"name": 7, "from": "j", "to": "k", "segments": 2,
                         "lumped": {"resistance": 1e3, "capacitance": 1e-6}},
                        dict(VESSELS[1]),
                        {"name": "d", "from": "k", "to": "o3", "length": 2, "radius": 0.2,
                         "wall_thickness": 0.02, "youngs_modulus": 4e6, "segments": 4},
                        {"name": "e", "from": "k", "to": "o4", "length": 2, "radius": 0.1}],
            "boundary_conditions": {
                "in": {"type": "flow", "value": 1.0},
                "o": {"type": "rcr", "proximal_resistance": 100, "capacitance": 1e-4,
                      "distal_resistance": 900, "pressure": 10},
                "o3": {"type": "RCR", "proximal_resistance": 100, "capacitance": 1e-4,
                       "distal_resistance": 900},
                "o4": {"type": "resistance", "resistance": 1e3,
                       "pressure": {"time": [0.0, 1.0], "pressure": [5.0, 5.0]}}}}


@pytest.mark.parametrize("units", ["SI", "cgs"])
def test_the_native_reader_builds_the_network_the_json_text_builds(units: str) -> None:
    """`load_model` hands the user's plain vessels and outlets to the core's binding, which
    checks and converts them itself; the rest go through Python's full check. The reference is
    the canonical model as JSON text (the core's serde parser, no dict read at all): the same
    multiplications by the same unit factors, so the same bits."""
    import json

    import numpy as np

    from oxyline import _core
    from oxyline.ensemble.patch import variant_model

    d = _mixed_model(units)
    m = oxyline.load_model(d)
    ref = _core.Network(json.dumps(variant_model(_mixed_model(units)).canonical))
    a, b = m.network.segment_table(), ref.segment_table()
    assert a["vessel_names"] == b["vessel_names"] == ["a", "7", "b", "d", "e"]
    for k in ("resistance", "inductance", "compliance", "stenosis", "volume", "radius_in",
              "radius_out", "length"):
        np.testing.assert_array_equal(a[k], b[k])
    np.testing.assert_array_equal(m.network.steady_state()["state"], ref.steady_state()["state"])
    assert m.network.unknown_names() == ref.unknown_names()
    assert m.vessel_names == ["a", "7", "b", "d", "e"]
    # an independent check of the conversion: Poiseuille's R = 8 mu L / (pi r^4) of the rigid
    # uniform vessel 'e' (2 length units, radius 0.1, one segment; docs/physics.md §1.1)
    f = factor(units, "length")
    mu = 3.5e-3
    r_e = a["resistance"][np.asarray(a["vessel"]) == 4]
    assert r_e == pytest.approx([8 * mu * 2 * f / (np.pi * (0.1 * f) ** 4)], rel=1e-12)


@pytest.mark.parametrize("edit, message", [
    ({"length": -1.0}, "vessel 'a': length must be a finite number > 0"),
    ({"length": True}, "vessel 'a': 'length' must be a number"),
    ({"radius_in": 0.001}, "vessel 'a': give 'radius' or 'radius_in'/'radius_out', not both"),
    ({"valve": {"law": "piecewise", "min_resistance": 1.0, "max_resistance": 1e9}},
     "vessel 'a': give one of valve, chamber, through_rc, lumped or geometry"),
    ({"segments": 0}, "vessel 'a': 'segments' must be an integer >= 1"),
])
def test_a_vessel_the_native_reader_refuses_gets_the_full_checks_error(
        edit: dict[str, Any], message: str) -> None:
    """The binding's reader never decides an error itself: a vessel it does not take goes to
    Python's full check, whose message names the vessel and the value. (A valve beside a
    geometry used to pass the Python fast path with its valve dropped.)"""
    d = _mixed_model("SI")
    d["vessels"][0] = {**d["vessels"][0], **edit}
    with pytest.raises(oxyline.ModelError, match=message):
        oxyline.load_model(d)


def test_an_outlet_the_native_reader_refuses_gets_the_full_checks_error() -> None:
    d = _mixed_model("SI")
    d["boundary_conditions"]["o"]["capacitance"] = "1e-4x"
    with pytest.raises(oxyline.ModelError,
                       match="boundary condition 'o': 'capacitance' must be a number"):
        oxyline.load_model(d)


def test_the_copy_shares_no_container_with_the_users_dict() -> None:
    """`load_model`'s private copy (lists of plain dicts are copied in C) is equal to the
    user's dict and shares none of its dicts or lists, nested ones included."""
    from oxyline.description import copy_description

    d = {"vessels": [{"name": "a", "length": 1.0}, {"name": "b", "lumped": {"r": [1, 2]}},
                     {"name": "c"}],
         "boundary_conditions": {"in": {"type": "flow", "time": [0, 1], "flow": (1, 2)},
                                 "o": {"type": "resistance", "resistance": 1.0}},
         "plain": [{"x": 1}, {"y": 2}], "table": ({"t": 0},)}
    c = copy_description(d)
    assert c == {**d, "boundary_conditions": {**d["boundary_conditions"],
                                              "in": {**d["boundary_conditions"]["in"],
                                                     "flow": [1, 2]}},
                 "table": [{"t": 0}]}

    def containers(x: Any) -> list[int]:
        if isinstance(x, dict):
            return [id(x)] + [i for v in x.values() for i in containers(v)]
        if isinstance(x, (list, tuple)):
            return [id(x)] + [i for v in x for i in containers(v)]
        return []

    assert not set(containers(c)) & set(containers(d))
