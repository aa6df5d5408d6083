"""Hostile inputs aimed at the run, its files and its paths: each gives a typed error whose
message names the argument (or a clean run), never a raw exception, a Rust panic, a hang or a
file written where it does not belong."""

from __future__ import annotations

import copy
import io
import json
import os
import threading
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import bifurcation, raises, stenosed_inductor
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import oxyline
from oxyline.cli import main
from oxyline.errors import CheckpointError, ModelError, ResourceError

EXAMPLE = Path(oxyline.__file__).parent / "examples" / "bifurcation.yaml"
FAST = {"cycles": 1, "progress": False}

# a minimal svZeroDSolver file: a flow into one resistive vessel and a resistance
SVZ: dict[str, Any] = {
    "simulation_parameters": {"number_of_cardiac_cycles": 2,
                              "number_of_time_pts_per_cardiac_cycle": 11},
    "boundary_conditions": [
        {"bc_name": "INFLOW", "bc_type": "FLOW", "bc_values": {"Q": [5.0, 5.0],
                                                               "t": [0.0, 1.0]}},
        {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 0.0}}],
    "vessels": [{"vessel_id": 0, "vessel_length": 10.0, "vessel_name": "branch0_seg0",
                 "zero_d_element_type": "BloodVessel",
                 "zero_d_element_values": {"R_poiseuille": 100.0},
                 "boundary_conditions": {"inlet": "INFLOW", "outlet": "OUT"}}],
    "junctions": [],
}


# ---- durations and counts against representable ranges ------------------------------------

@pytest.mark.parametrize("every", [1e20, 10**30, "1e20 s", "10000000000000000000000 cycles",
                                   -1.0, float("nan")])
def test_checkpoint_every_out_of_range_is_a_model_error(tmp_path: Path, every: Any) -> None:
    with raises(ModelError, "checkpoint_every"):
        oxyline.simulate("bifurcation", checkpoint=tmp_path / "c.ckpt", checkpoint_every=every,
                         **FAST)


def test_checkpoint_every_beyond_a_duration_never_panics_in_the_core() -> None:
    # the binding itself (below the Python check): a ModelError, not a Rust panic
    net = oxyline.load_model("bifurcation").network
    with raises(ModelError, "checkpoint_every"):
        net.simulate(period=1.0, output_every=0.01, checkpoint_sink=lambda d: None,
                     checkpoint_every_seconds=1e20, cycles=1)


def test_cli_checkpoint_every_huge_exits_2(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["run", "bifurcation", "--cycles", "1", "--quiet", "--checkpoint",
               str(tmp_path / "c.ckpt"), "--checkpoint-every", "1e20"])
    assert rc == 2 and "checkpoint_every" in capsys.readouterr().err


@pytest.mark.parametrize(("key", "value"), [("cycles", 10**30), ("max_cycles", 2**64),
                                            ("max_iterations", 10**400)])
def test_huge_integer_counts_are_model_errors(key: str, value: int) -> None:
    with raises(ModelError, key):
        oxyline.simulate("bifurcation", **{**FAST, key: value})


@pytest.mark.parametrize("key", ["dt", "output_every", "until_periodic"])
def test_huge_integer_durations_are_model_errors(key: str) -> None:
    with raises(ModelError, key):
        oxyline.simulate("bifurcation", **{**FAST, key: 10**400})


def test_huge_integer_radius_is_a_model_error_naming_it() -> None:
    m = bifurcation()
    m["vessels"][0]["radius"] = 10**400
    with raises(ModelError, "radius"):
        oxyline.load_model(m)


def test_output_every_denormal_is_a_resource_error() -> None:
    with raises(ResourceError, "output_every"):
        oxyline.simulate("bifurcation", output_every=5e-324, **FAST)


def test_tiny_dt_plans_no_endless_run() -> None:
    with raises(ResourceError, "steps per cycle", "dt"):
        oxyline.simulate("bifurcation", dt=1e-15, method="generalized-alpha", **FAST)


@pytest.mark.parametrize("freq", [[1.0 + 2.0j], ["5 Hz"], [None], [10**400], [[1.0], [1.0, 2.0]]])
def test_impedance_frequencies_not_real_numbers_are_model_errors(freq: Any) -> None:
    with raises(ModelError, "frequencies"):
        oxyline.impedance("bifurcation", "inlet", freq)


@pytest.mark.parametrize(("freq", "shown"), [(-1.0, "-1"), (float("nan"), "NaN"),
                                             (float("inf"), "inf")])
def test_impedance_frequencies_outside_zero_to_infinity_are_named_in_hz(freq: float,
                                                                        shown: str) -> None:
    with raises(ModelError, "frequencies must be finite and >= 0 Hz", shown):
        oxyline.impedance("bifurcation", "inlet", [1.0, freq])


# ---- svZeroDSolver files ---------------------------------------------------------------------

@pytest.mark.parametrize(("key", "value", "cls"), [
    ("number_of_cardiac_cycles", 1e9, ResourceError),
    ("number_of_cardiac_cycles", 10**30, ModelError),
    ("number_of_time_pts_per_cardiac_cycle", 1e9, ResourceError),
    ("number_of_time_pts_per_cardiac_cycle", 10**400, ModelError),
])
def test_svzerod_counts_beyond_any_run_are_refused_at_once(key: str, value: Any,
                                                           cls: type[Exception]) -> None:
    cfg = copy.deepcopy(SVZ)
    cfg["simulation_parameters"][key] = value
    start = time.perf_counter()
    with raises(cls, key):
        oxyline.load_model(cfg)
    assert time.perf_counter() - start < 30  # refused before any run (bounds a hang only)


@pytest.mark.parametrize("percent", [0, 0.0, -5.0, 100.0])
def test_svzerod_cycle_error_percent_out_of_range(percent: float) -> None:
    cfg = copy.deepcopy(SVZ)
    cfg["simulation_parameters"].update(use_cycle_to_cycle_error=True,
                                        sim_cycle_to_cycle_percent_error=percent)
    with raises(ModelError, "sim_cycle_to_cycle_percent_error"):
        oxyline.load_model(cfg)


def test_svzerod_huge_integer_value_is_a_model_error() -> None:
    cfg = copy.deepcopy(SVZ)
    cfg["boundary_conditions"][1]["bc_values"]["R"] = 10**400
    with raises(ModelError, "'R'"):
        oxyline.load_model(cfg)


# ---- structured trees: counted in closed form first ------------------------------------------

def test_structured_tree_near_one_is_refused_in_closed_form() -> None:
    start = time.perf_counter()
    with raises(ModelError, "max_vessels", "alpha"):
        oxyline.structured_tree("out", root_radius=1e-3, alpha=0.999999, beta=0.999999,
                                min_radius=1e-5)
    assert time.perf_counter() - start < 5  # the count would run for hours


def _enumerated(alpha: float, beta: float, r: float, rmin: float) -> int:
    """Vessels below a node of radius r, by the growth rule written out (independent of the
    core's count)."""
    return sum(1 + _enumerated(alpha, beta, k * r, rmin) for k in (alpha, beta) if k * r >= rmin)


def test_structured_tree_bound_is_a_lower_bound_of_the_count() -> None:
    from oxyline import _core

    for a, b, r0, rmin in [(0.9, 0.6, 1e-3, 1e-4), (0.8, 0.8, 1e-3, 5e-5), (0.95, 0.3, 1, 0.01),
                           (0.5, 0.5, 1.0, 0.5), (0.5, 0.5, 1.0, 0.4999)]:
        bound = _core.structured_tree_count_bound(a, b, r0, rmin)
        count = _enumerated(a, b, r0, rmin)
        assert bound <= count
        grown = oxyline.structured_tree("out", root_radius=r0, alpha=a, beta=b, min_radius=rmin)
        assert len(grown) == count
        if a == b and count > 10:  # a full binary tree: the bound is within rounding of it
            assert bound >= count / 4


@pytest.mark.parametrize("value", [6e6 * 1e3, 10**400, 0])
def test_structured_tree_max_vessels_out_of_range(value: Any) -> None:
    with raises(ModelError, "max_vessels"):
        oxyline.structured_tree("out", root_radius=1e-3, max_vessels=value)


# ---- nesting and self-reference ----------------------------------------------------------------

def test_self_referencing_model_is_a_model_error() -> None:
    m = bifurcation()
    m["blood"]["self"] = m
    with raises(ModelError, "refers to itself"):
        oxyline.load_model(m)


def test_deeply_nested_model_is_a_model_error() -> None:
    m = bifurcation()
    deep: dict[str, Any] = {}
    node = deep
    for _ in range(5000):
        node["x"] = {}
        node = node["x"]
    m["blood"]["deep"] = deep
    with raises(ModelError, "nested deeper"):
        oxyline.load_model(m)


def test_yaml_alias_cycle_is_a_model_error(tmp_path: Path) -> None:
    p = tmp_path / "m.yaml"
    p.write_text(EXAMPLE.read_text() + "\nloop: &a [*a]\n")
    with raises(ModelError):
        oxyline.load_model(p)


# ---- paths ---------------------------------------------------------------------------------------

def test_cli_refuses_a_checkpoint_on_the_input_model(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "m.yaml"
    model.write_text(EXAMPLE.read_text())
    before = model.read_bytes()
    rc = main(["run", str(model), "--quiet", "--checkpoint", str(model)])
    assert rc == 2 and "--checkpoint" in capsys.readouterr().err
    assert model.read_bytes() == before
    link = tmp_path / "link.yaml"
    os.link(model, link)  # the same file under another name
    rc = main(["run", str(model), "--quiet", "--checkpoint", str(link)])
    assert rc == 2 and model.read_bytes() == before


def test_cli_refuses_checkpoint_equal_to_output_and_output_on_input(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out.nc"
    rc = main(["run", "bifurcation", "--quiet", "-o", str(out), "--checkpoint",
               str(tmp_path / "sub" / ".." / "out.nc")])
    assert rc == 2 and "--checkpoint" in capsys.readouterr().err and not out.exists()
    model = tmp_path / "m.csv"
    model.write_text("x")
    rc = main(["run", str(model), "--quiet", "-o", str(model)])
    assert rc == 2 and "-o" in capsys.readouterr().err and model.read_text() == "x"


def test_cli_unwritable_checkpoint_fails_before_the_run(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["run", "bifurcation", "--quiet", "-o", str(tmp_path / "o.nc"), "--checkpoint",
               str(tmp_path / "missing" / "c.ckpt")])
    assert rc == 2 and "c.ckpt" in capsys.readouterr().err


def test_api_refuses_a_checkpoint_on_the_model_file(tmp_path: Path) -> None:
    model = tmp_path / "m.yaml"
    model.write_text(EXAMPLE.read_text())
    with raises(ModelError, "checkpoint"):
        oxyline.simulate(model, checkpoint=model, **FAST)


@pytest.mark.parametrize("node", ["../escaped", "/tmp/abs", "a/b", "..", "c:\\x", ""])
def test_write_tables_keeps_node_file_names_inside_the_output_directory(
        tmp_path: Path, node: str) -> None:
    from oxyline.io import write_tables

    m = bifurcation()
    old = next(iter(m["boundary_conditions"]))
    m["boundary_conditions"] = {node if k == old else k: v
                                for k, v in m["boundary_conditions"].items()}
    for v in m["vessels"]:
        v["from"] = node if v["from"] == old else v["from"]
    m["boundary_conditions"][node] = {"type": "flow", "time": [0.0, 0.5, 1.0],
                                      "flow": [1e-6, 2e-6, 1e-6]}
    try:
        model = oxyline.load_model(m)
    except ModelError:
        return  # a name the model itself refuses: nothing to write
    out = tmp_path / "out" / "t.csv"
    with raises(ModelError, "node"):
        write_tables(model, out)
    inside = {p.resolve() for p in tmp_path.rglob("*")}
    assert all(str(p).startswith(str(tmp_path.resolve())) for p in inside)
    assert not (tmp_path / "escaped.csv").exists() and not Path("/tmp/abs.csv").exists()


@pytest.mark.parametrize("target", ["fifo", "/dev/zero", "/dev/urandom", "dir",
                                    "/proc/self/status"])
def test_waveform_tables_must_be_regular_files(tmp_path: Path, target: str) -> None:
    if target == "fifo":
        path = tmp_path / "wave.csv"
        os.mkfifo(path)
    elif target == "dir":
        path = tmp_path / "wave.csv"
        path.mkdir()
    else:
        path = Path(target)
    vessels = tmp_path / "v.csv"
    vessels.write_text("name,from,to,length,radius,wall_thickness,youngs_modulus\n"
                       "a,in,out,0.1,0.003,0.0003,4e5\n")
    (tmp_path / "v_bcs.csv").write_text(f"node,type,waveform,resistance\nin,flow,{path},\n"
                                        "out,resistance,,1e8\n")
    done: list[BaseException] = []

    def load() -> None:
        try:
            oxyline.io.read_tables(vessels)
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            done.append(exc)

    t = threading.Thread(target=load, daemon=True)
    t.start()
    t.join(timeout=60)  # a FIFO opened for reading would block here forever
    assert done, "reading a waveform table blocked"
    assert isinstance(done[0], ModelError), repr(done[0])
    assert "regular file" in str(done[0]) and str(path) in str(done[0])


def test_table_size_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from oxyline.io import _common

    monkeypatch.setattr(_common, "MAX_TABLE_BYTES", 100)
    vessels = tmp_path / "v.csv"
    vessels.write_text("name,from,to,length,radius,wall_thickness,youngs_modulus\n"
                       + "a,in,out,0.1,0.003,0.0003,4e5\n" * 10)
    with raises(ModelError, "100"):
        oxyline.io.read_tables(vessels)


# ---- checkpoints: validated field by field ------------------------------------------------------

@pytest.fixture(scope="module")
def good_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    p = tmp_path_factory.mktemp("ckpt") / "run.ckpt"
    oxyline.simulate("bifurcation", cycles=2, checkpoint=p, checkpoint_every="1 cycle",
                     progress=False)
    return p.read_bytes()


def _rewrite(data: bytes, meta_change: Any) -> bytes:
    """The archive with its JSON meta record changed by ``meta_change(meta)``."""
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as dst:
        for name in src.namelist():
            raw = src.read(name)
            if name == "meta.npy":
                meta = json.loads(bytes(np.load(io.BytesIO(raw))).decode())
                meta_change(meta)
                buf = io.BytesIO()
                np.save(buf, np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
                raw = buf.getvalue()
            dst.writestr(name, raw)
    return out.getvalue()


def _set(path: list[str], value: Any) -> Any:
    def change(meta: dict[str, Any]) -> None:
        d = meta
        for k in path[:-1]:
            d = d[k]
        if value is _DELETE:
            del d[path[-1]]
        else:
            d[path[-1]] = value
    return change


_DELETE = object()


@pytest.mark.parametrize(("path", "value", "field"), [
    (["state", "dt"], "0.001", "state/dt"),
    (["state", "dt"], -1.0, "state/dt"),
    (["state", "cycles_run"], 1.5, "state/cycles_run"),
    (["state", "steps"], _DELETE, "state/steps"),
    (["settings"], [1, 2], "settings"),
    (["settings"], {"cycles": "many"}, "settings"),
    (["model"], _DELETE, "model"),
    (["model"], "bifurcation", "model"),
    (["checkpoint_every"], {"s": 1}, "checkpoint_every"),
    (["version"], "1", "version"),
    (["state"], None, "state"),
])
def test_checkpoint_field_of_the_wrong_type_is_named(tmp_path: Path, good_checkpoint: bytes,
                                                     path: list[str], value: Any,
                                                     field: str) -> None:
    p = tmp_path / "bad.ckpt"
    p.write_bytes(_rewrite(good_checkpoint, _set(path, value)))
    with raises(CheckpointError, str(p), field):
        oxyline.resume(p, progress=False)


@pytest.mark.parametrize("damage", ["truncate", "npy", "empty", "directory", "fifo"])
def test_damaged_checkpoints_are_checkpoint_errors(tmp_path: Path, good_checkpoint: bytes,
                                                   damage: str) -> None:
    p = tmp_path / "bad.ckpt"
    if damage == "truncate":
        p.write_bytes(good_checkpoint[: len(good_checkpoint) // 2])
    elif damage == "npy":
        np.save(p.open("wb"), np.arange(5.0))
    elif damage == "empty":
        p.write_bytes(b"")
    elif damage == "directory":
        p.mkdir()
    else:
        os.mkfifo(p)
    with raises(CheckpointError, str(p)):
        oxyline.resume(p, progress=False)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_bit_flipped_checkpoints_are_refused_or_resume(tmp_path: Path, good_checkpoint: bytes,
                                                       data: st.DataObject) -> None:
    """Any byte of the file changed: a CheckpointError (or the run resumes, where the byte was
    one the zip format does not check), never another exception."""
    i = data.draw(st.integers(0, len(good_checkpoint) - 1), label="byte")
    flip = data.draw(st.integers(1, 255), label="xor")
    raw = bytearray(good_checkpoint)
    raw[i] ^= flip
    p = tmp_path / "flipped.ckpt"
    p.write_bytes(bytes(raw))
    try:
        oxyline.resume(p, progress=False)
    except (CheckpointError, ModelError):
        pass


_JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                     lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=5), c,
                                                                         max_size=3),
                     max_leaves=8)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(["state", "settings", "model", "checkpoint_every", "format",
                            "version", "oxyline"]),
       sub=st.sampled_from([None, "dt", "cycles_run", "steps", "periodic_error", "version"]),
       value=_JSON)
def test_mutated_checkpoint_metadata_is_refused_or_resumes(tmp_path: Path,
                                                           good_checkpoint: bytes, key: str,
                                                           sub: str | None, value: Any) -> None:
    def change(meta: dict[str, Any]) -> None:
        if sub is not None and key == "state" and isinstance(meta.get("state"), dict):
            meta["state"][sub] = value
        else:
            meta[key] = value

    p = tmp_path / "mutated.ckpt"
    p.write_bytes(_rewrite(good_checkpoint, change))
    try:
        oxyline.resume(p, progress=False)
    except (CheckpointError, ModelError) as exc:
        assert str(p) in str(exc) or "checkpoint" in str(exc)


# ---- cancellation in every phase ---------------------------------------------------------------

def test_cancel_acts_during_the_automatic_step_estimate() -> None:
    """RK4's stability estimate of a 6,000-segment model (Krylov, seconds on a large model)
    asks the run's progress check between its matrix-vector products: a cancel set at the
    first check (t = 0, before any step) stops the run there, with no rows computed."""
    m = bifurcation()
    for v in m["vessels"]:
        v["segments"] = 10000  # an estimate of ~1 s: longer than the 0.1 s between checks
    model = oxyline.load_model(m)
    ev = threading.Event()
    calls: list[float] = []

    def first_check_cancels(t: float, t_end: float) -> None:
        calls.append(t)
        ev.set()

    with pytest.raises(oxyline.SimulationCancelled) as info:
        oxyline.simulate(model, cycles=1000, method="rk4", cancel=ev,
                         progress=first_check_cancels)
    assert calls[0] == 0.0  # asked during the estimate, before the first step
    assert info.value.result is None or len(info.value.result.time) == 0


_PHASES = {
    "generalized-alpha steps": ("bifurcation", lambda t: t > 0,
                                {"cycles": 10**4, "method": "generalized-alpha"}),
    "RK4 steps": ("bifurcation", lambda t: t > 0, {"cycles": 10**4, "method": "rk4"}),
    "until_periodic cycles": ("bifurcation", lambda t: t > 2.0,
                              {"until_periodic": 1e-14, "max_cycles": 10**4}),
    "O2 transport": ("paper-bifurcated", lambda t: t > 0, {"cycles": 10**4}),
    "Zarr stream": ("bifurcation", lambda t: t > 0, {"cycles": 10**4}),
    "before the start": ("bifurcation", None, {"cycles": 10**4}),
}


@pytest.mark.parametrize("phase", list(_PHASES))
def test_cancel_acts_at_the_next_check_in_every_phase(tmp_path: Path, phase: str) -> None:
    """A cancel set in any phase of a 10,000-cycle run (minutes) stops it at the run's next
    progress check (checks are 0.1 s of wall time apart): the progress callback that set it
    is the last one, or one more at most, and the run raises SimulationCancelled."""
    name, when, settings_ = _PHASES[phase]
    ev = threading.Event()
    calls_after: list[float] = []

    def progress(t: float, t_end: float) -> None:
        if ev.is_set():
            calls_after.append(t)
        elif when is not None and when(t):
            ev.set()

    if when is None:
        ev.set()
    run = (oxyline.simulate if phase != "Zarr stream" else
           lambda m, **kw: oxyline.simulate_to_zarr(m, tmp_path / "r.zarr", **kw))
    with pytest.raises(oxyline.SimulationCancelled) as info:
        run(name, cancel=ev, progress=progress, **settings_)
    assert len(calls_after) <= 1, calls_after
    res = info.value.result
    if res is not None and len(res.time):
        assert float(res.time[-1]) < 10.0  # a partial result: far from the 10,000 cycles


# ---- a panic of the core never reaches the caller as one ---------------------------------------

def test_a_core_panic_becomes_a_solver_error() -> None:
    from oxyline.errors import core_errors

    panic = type("PanicException", (BaseException,), {"__module__": "pyo3_runtime"})
    with raises(oxyline.SolverError, "simulate", "boom"), core_errors("simulate"):
        raise panic("boom")
    with pytest.raises(KeyboardInterrupt), core_errors("simulate"):
        raise KeyboardInterrupt


def test_a_panic_at_a_binding_entry_is_a_solver_error_naming_it() -> None:
    """The binding's own guard (not only the package's ``core_errors`` blocks): a panic at
    any entry of ``oxyline._core`` is a SolverError with the entry and the panic's message,
    never pyo3's PanicException (a BaseException ``except Exception`` lets through)."""
    from oxyline import _core

    with raises(oxyline.SolverError, "_panic_probe", "a Rust panic", "probe 42"):
        _core._panic_probe("probe 42")
    try:
        _core._panic_probe("again")
    except Exception as exc:  # noqa: BLE001 - the point: an ordinary Exception
        assert isinstance(exc, oxyline.SolverError)


BINDING = Path(__file__).parents[1] / "rust" / "oxyline-py" / "src"


@pytest.mark.skipif(not BINDING.is_dir(), reason="needs the binding's sources")
def test_every_binding_entry_is_guarded_against_panics() -> None:
    """Every ``#[pyfunction]`` and ``#[pymethods]`` block of the binding carries
    ``#[oxyline_py_guard::guard]`` among its attributes (the guard the test above proves)."""
    import re

    unguarded, entries = [], 0
    for src in sorted(BINDING.rglob("*.rs")):
        lines = src.read_text().splitlines()
        for k, line in enumerate(lines):
            if re.match(r"\s*#\[(pyfunction|pymethods)\b", line):
                entries += 1
                j = k - 1
                while j >= 0 and lines[j].strip().startswith(("#[", "///")) \
                        and "oxyline_py_guard::guard" not in lines[j]:
                    j -= 1
                if j < 0 or "oxyline_py_guard::guard" not in lines[j]:
                    unguarded.append(f"{src.name}:{k + 1}")
    assert entries >= 20 and not unguarded, unguarded


def test_structured_tree_memory_estimate_refuses_before_growing() -> None:
    from oxyline import _core

    with raises(ResourceError, "'out'", "memory"):
        oxyline.structured_tree("out", root_radius=1e-3, min_radius=5e-5, memory_limit=1e6)
    # the estimate is the core's bytes per one-segment vessel times the enumerated count
    need = _enumerated(0.9, 0.6, 1e-3, 5e-5) * (_core.BYTES_PER_ELEMENT
                                                 + _core.FLOW_BYTES_PER_SEGMENT)
    with raises(ResourceError, "'out'", "memory"):
        oxyline.structured_tree("out", root_radius=1e-3, min_radius=5e-5,
                                memory_limit=0.999 * need)
    assert oxyline.structured_tree("out", root_radius=1e-3, min_radius=5e-5,
                                   memory_limit=1.001 * need)


# ---- a process at the end of its address space ---------------------------------------------

_NEAR_LIMIT = """
import resource, signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
import oxyline
model = oxyline.load_model("bifurcation")
with open("/proc/self/status") as f:
    vm = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (vm + int(float(sys.argv[1]) * 1e6),
                                        resource.RLIM_INFINITY))
try:
    # RK4's automatic step: its stability estimate's dense scratch is the allocation at stake
    # (an error-controlled run of this model needs far less)
    res = oxyline.simulate(model, cycles=1, progress=False, method="rk4")
    print("ran", len(res.time))
except (oxyline.ResourceError, MemoryError) as exc:
    print("refused", type(exc).__name__, exc)
"""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc (Linux)")
@pytest.mark.parametrize("left_mb", [2.0, 3.0, 4.0, 400.0])
def test_a_first_run_near_the_address_space_limit_raises_instead_of_aborting(
        left_mb: float) -> None:
    """With 2-4 MB of address space left (RLIMIT_AS in a child), the first run raises a typed
    error (before: the linear algebra's scratch allocation aborted the process, SIGABRT);
    with room left it runs (the same child, so the refusal is the limit's doing)."""
    import subprocess
    import sys

    # the child resets SIGINT itself (the script's first lines)
    child = subprocess.Popen([sys.executable, "-c", _NEAR_LIMIT, str(left_mb)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = child.communicate(timeout=120)
    finally:
        child.kill()
        child.wait()
    assert child.returncode == 0, (child.returncode, err[-2000:])
    if left_mb < 10:
        assert out.startswith("refused"), out + err[-2000:]
        assert "MemoryError" in out or "out of memory" in out, out
    else:
        assert out.startswith("ran 1001"), out + err[-2000:]


# ---- more hostile numbers -------------------------------------------------------------------

@pytest.mark.parametrize(("key", "value"), [("compliance", 0), ("compliance", -2.0),
                                            ("resistance", -1.0)])
def test_an_ensemble_scale_factor_of_zero_or_below_fails_its_variant(key: str,
                                                                      value: float) -> None:
    # before: ZeroDivisionError (compliance 0 divides Young's modulus) for the whole ensemble;
    # now that variant fails with its error (status 1), the others run
    ds = oxyline.simulate_ensemble("bifurcation", [{"scale": {key: value}}, {}], cycles=1,
                                   progress=False)
    assert ds.status.values.tolist() == [1, 0]
    assert "variant 0" in ds.error.values[0] and ("vessel" in ds.error.values[0]
                                                 or "boundary condition" in ds.error.values[0])


@pytest.mark.parametrize("coefficient", [-1e12, -1e14])
def test_rk4_with_a_negative_stenosis_coefficient_plans_no_endless_run(
        coefficient: float) -> None:
    """A negative stenosis coefficient below -R/(2|Q|) makes the branch's incremental
    resistance negative and feeds a growing mode (Re λ > 0; before: a run of 6e17 steps per
    cycle started, then a refusal by step count): refused at once as a model error naming
    the stenosis and its coefficient."""
    model = stenosed_inductor(coefficient)
    with pytest.raises(ModelError) as info:
        oxyline.simulate(model, method="rk4", cycles=1, start="zero", progress=False)
    msg = str(info.value)
    value = f"{coefficient:.3e}".replace("e+", "e")  # as the core writes it: -1.000e12
    assert "growing mode" in msg and "'s'" in msg and f"stenosis_coefficient {value}" in msg, msg


@pytest.mark.parametrize("segments", [1e7, 10**7])
def test_an_ensemble_variant_of_ten_million_segments_never_allocates_them(
        segments: Any) -> None:
    """``segments: 1e7`` (a float) is refused as a model error of its variant; 10**7 is
    above the memory allowed (status 6, estimated before it runs); the other variant runs."""
    ds = oxyline.simulate_ensemble("bifurcation", [{}, {"vessels": {"parent": {
        "segments": segments}}}], cycles=1, progress=False, max_memory="2 GB")
    assert ds.status.values.tolist() == [0, 1 if isinstance(segments, float) else 6]
    assert "segments" in ds.error.values[1] or "max_memory" in ds.error.values[1]


def test_an_output_callable_the_dask_workers_cannot_receive_is_a_model_error() -> None:
    distributed = pytest.importorskip("distributed")
    lock = threading.Lock()

    def holds_a_lock(res: Any) -> dict[str, float]:  # a closure over an unpicklable lock
        with lock:
            return {"p": float(res.pressure_in.max())}

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client, \
            raises(ModelError, "output", "holds_a_lock", "Dask"):
        oxyline.simulate_ensemble("bifurcation", [{}], client=client, output=holds_a_lock,
                                  cycles=1, progress=False)


# ---- ensembles ----------------------------------------------------------------------------------

def test_ensemble_full_output_is_estimated_before_any_variant_runs() -> None:
    with raises(ResourceError, "output='full'", "max_memory"):
        oxyline.simulate_ensemble("bifurcation", [{}] * 2500, output="full", cycles=1,
                                  progress=False, max_memory="1 MB")


def test_ensemble_variant_timeout_fails_the_slow_variants_only() -> None:
    slow = oxyline.simulate_ensemble("bifurcation", [{}, {}], cycles=2000, progress=False,
                                     variant_timeout=1e-3)
    assert slow.status.values.tolist() == [3, 3]
    assert all("variant_timeout" in e for e in slow.error.values)
    ok = oxyline.simulate_ensemble("bifurcation", [{}, {}], cycles=1, progress=False,
                                   variant_timeout=1e6)
    assert ok.status.values.tolist() == [0, 0]


@pytest.mark.parametrize("value", [0, -1.0, float("inf"), "10 s", 10**400, True])
def test_ensemble_variant_timeout_out_of_range(value: Any) -> None:
    with raises(ModelError, "variant_timeout"):
        oxyline.simulate_ensemble("bifurcation", [{}], cycles=1, progress=False,
                                  variant_timeout=value)


def test_ensemble_cancel_returns_what_finished_with_per_variant_status() -> None:
    ev = threading.Event()

    def stop_after_first(done: int, total: int) -> None:
        if done >= 1:
            ev.set()

    variants = [{"vessels": {"parent": {"radius": 0.003 + 1e-5 * k}}} for k in range(40)]
    with pytest.raises(oxyline.SimulationCancelled) as info:
        oxyline.simulate_ensemble("bifurcation", variants, cycles=3, workers=1,
                                  progress=stop_after_first, cancel=ev)
    ds = info.value.result
    status = ds.status.values
    assert (status == 0).sum() >= 1 and set(status.tolist()) <= {0, 5, -1}
    assert (status == -1).sum() >= 1  # the rest never started
    with raises(ModelError, "cancel"):
        oxyline.simulate_ensemble("bifurcation", [{}], cancel=object(), progress=False)


_CELL = (st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10**30, 10**30)
         | st.sampled_from(["", "x", "1e400", "nan", None, "0"]))


@settings(max_examples=15, deadline=None)
@given(column=st.sampled_from(["vessels.parent.radius", "vessels.daughter1.length",
                               "boundary_conditions.ica_out.resistance", "blood.viscosity",
                               "scale.compliance", "scale.resistance", "period",
                               "vessels.parent.segments"]),
       cells=st.lists(_CELL, min_size=1, max_size=3))
def test_mutated_ensemble_patch_tables_give_statuses_or_model_errors(column: str,
                                                                     cells: list[Any]) -> None:
    """Any values in a patch table's column: each variant runs or fails with its status and
    error (6: above the memory allowed, estimated before it runs), or the table is refused
    with a ModelError naming the column; nothing else."""
    import pandas as pd

    df = pd.DataFrame({column: pd.Series(cells, dtype=object)})
    try:
        # max_memory: a variant of 1e5+ segments is refused (status 6) instead of run
        ds = oxyline.simulate_ensemble("bifurcation", df, cycles=1, progress=False, workers=1,
                                       max_memory="100 MB")
    except ModelError as exc:
        assert column.split(".")[-1] in str(exc) or "variant" in str(exc), str(exc)
        return
    assert len(ds.status) == len(cells)
    failed = ds.status.values != 0
    assert all(ds.error.values[failed]), "a failed variant without its error"


def test_max_memory_of_a_run_bounds_the_model_state_too() -> None:
    m = bifurcation()
    for v in m["vessels"]:
        v["segments"] = 2000
    model = oxyline.load_model(m)
    # the output of one cycle every 0.1 s is tiny; the 6,000-segment state is not
    with raises(ResourceError, "max_memory", "state"):
        oxyline.simulate(model, cycles=1, output_every=0.1, segments=False, progress=False,
                         max_memory="1 MB")


def test_overflowing_stiffness_law_is_a_model_error() -> None:
    with raises(ModelError, "stiffness"):
        oxyline.structured_tree("out", root_radius=1e-3, min_radius=5e-4,
                                stiffness={"k1": 1.0, "k2": 1e300, "k3": 0.0})


def test_ensemble_variant_above_max_memory_fails_before_it_runs() -> None:
    ds = oxyline.simulate_ensemble("bifurcation", [{}, {"vessels": {"parent": {
        "segments": 400_000}}}], cycles=1, progress=False, max_memory="100 MB")
    assert ds.status.values.tolist() == [0, 6]
    assert "max_memory" in ds.error.values[1] and "variant 1" in ds.error.values[1]


def test_svzerod_output_table_is_estimated_before_it_is_allocated() -> None:
    from oxyline import svzerod  # the public drop-in

    cfg = copy.deepcopy(SVZ)
    cfg["simulation_parameters"].update(number_of_cardiac_cycles=1,
                                        number_of_time_pts_per_cardiac_cycle=int(1e9))
    with raises(ResourceError, "number_of_time_pts_per_cardiac_cycle"):  # ~190 GB
        svzerod.simulate(cfg)


def test_a_second_writer_of_a_zarr_store_is_refused(tmp_path: Path) -> None:
    pytest.importorskip("zarr")
    from oxyline.errors import OutputError
    from oxyline.io.results import _StoreLock

    path = tmp_path / "run.zarr"
    held = _StoreLock(path)  # another writer holds the store
    try:
        with raises(OutputError, "another process is writing"):
            oxyline.simulate_to_zarr("bifurcation", path, cycles=1, overwrite=True,
                                     progress=False)
    finally:
        held.release()
    ds = oxyline.simulate_to_zarr("bifurcation", path, cycles=1, overwrite=True,
                                  progress=False)
    assert ds.attrs["complete"] == 1
    assert not list(tmp_path.glob(".*"))  # no lock or temporary left


_ZARR_WRITER = """
import signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
import oxyline
from oxyline.errors import OutputError
print("ready", flush=True)
sys.stdin.readline()  # both start together
try:
    ds = oxyline.simulate_to_zarr("bifurcation", sys.argv[1], cycles=3, overwrite=True,
                                  progress=False)
    print("wrote", int(ds.attrs["complete"]), flush=True)
except OutputError as exc:
    print("refused", exc, flush=True)
"""


def test_two_processes_writing_one_zarr_store_leave_it_whole(tmp_path: Path) -> None:
    """Two processes start ``simulate_to_zarr(path, overwrite=True)`` on the same path at
    once (before: both ended with broken stores): each writes a whole store or is refused with
    OutputError, at least one writes, and the store left opens complete."""
    pytest.importorskip("zarr")
    import subprocess
    import sys

    import xarray as xr

    path = tmp_path / "run.zarr"
    children = [subprocess.Popen([sys.executable, "-c", _ZARR_WRITER, str(path)],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True) for _ in range(2)]
    try:
        for c in children:
            assert c.stdout is not None and c.stdout.readline().strip() == "ready"
        for c in children:  # the go signal, to both as close together as possible
            assert c.stdin is not None
            c.stdin.write("go\n")
            c.stdin.flush()
        outs = [c.communicate(timeout=300) for c in children]
    finally:
        for c in children:
            c.kill()
            c.wait()
    said = [out.strip().splitlines()[-1] if out.strip() else "" for out, _ in outs]
    for c, (out, err), last in zip(children, outs, said, strict=True):
        assert c.returncode == 0 and (last == "wrote 1" or last.startswith("refused")), \
            (last, err[-2000:])
    assert "wrote 1" in said
    with xr.open_zarr(path) as ds:
        assert ds.attrs["complete"] == 1 and ds.sizes["time"] >= 2
        assert np.isfinite(ds["pressure_in"].values).all()
    assert not [p.name for p in tmp_path.iterdir() if p.name != "run.zarr"]
