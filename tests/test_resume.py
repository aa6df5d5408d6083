"""Stops and resumption: checkpoints and ``resume`` (bit-identical to the
uninterrupted run), the cancel handle, Ctrl-C in worker threads, SIGTERM and solver failures in
the command line."""

from __future__ import annotations

import copy
import json
import os
import signal
import sys
import textwrap
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import run_child, signal_cli_run

import oxyline
from oxyline import cli

# bit-identity: a resumed run repeats the same floating-point operations in the same order as
# the uninterrupted one, so every output array must be equal bit for bit (NaN where NaN)


def _same(a: oxyline.Result, b: oxyline.Result) -> list[str]:
    """The arrays of two results that are not bit-identical."""
    diff = []
    if not (np.array_equal(a.time, b.time) and np.array_equal(a.data, b.data, equal_nan=True)):
        diff.append("flow")
    if a.species.keys() != b.species.keys():
        return [*diff, "species names"]
    for name, sp in a.species.items():
        for attr in ("vessel_data", "segment_data", "balance_data"):
            if not np.array_equal(getattr(sp, attr), getattr(b.species[name], attr),
                                  equal_nan=True):
                diff.append(f"{name} {attr}")
    for key in ("cycles_run", "dt", "method", "periodic_error"):
        if not (a.settings[key] == b.settings[key]
                or (a.settings[key] != a.settings[key] and b.settings[key] != b.settings[key])):
            diff.append(key)
    return diff


def _oxygen_hill() -> dict[str, Any]:
    """The paper's bifurcation with Hill binding: a two-pass run (cycle-mean |Q| closure),
    mixing at the junction, warm-started binding inversions."""
    d = oxyline.load_model("paper-bifurcated").to_dict()
    d["oxygen"]["hemoglobin"] = "hill"
    return d


def _reversing_renewal() -> dict[str, Any]:
    """A tube whose inflow reverses (mean 1e-5, amplitude 3e-5 m³/s) with the default Graetz
    wall: its law reads the first pass's forward means and inlet-renewal harmonics, which a
    resumed run must get again (the checkpoint's mean |Q| alone gives a different law)."""
    return {
        "period": 1.0,
        "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 10,
                     "length": 0.1, "radius": 0.01}],
        "boundary_conditions": {
            "in": {"type": "flow", "fourier": {"period": 1.0, "mean": 1e-5, "cos": [0.0],
                                               "sin": [3e-5]}},
            "out": {"type": "resistance", "resistance": 1e7}},
        "oxygen": {"inlet": {"po2": 90.0}, "wall": {"model": "graetz", "po2": 50.0}},
    }


# checkpoints need a fixed step: generalized-α gets its dt (RK4 its automatic fixed step), so
# that the uninterrupted run (error-controlled by default) is the same fixed-step run
CASES = [
    ("reversing-renewal", {"method": "generalized-alpha", "dt": 1e-3, "cycles": 3}),
    ("reversing-renewal", {"method": "rk4", "cycles": 3}),
    ("bifurcation", {"method": "rk4", "cycles": 3, "output_cycles": "all"}),
    ("bifurcation", {"method": "generalized-alpha", "dt": 1e-3, "cycles": 3,
                     "output_cycles": "all"}),
    ("oxygen-hill", {"method": "rk4", "cycles": 3}),
    ("oxygen-hill", {"method": "generalized-alpha", "dt": 1e-3, "cycles": 3,
                     "output_cycles": "all"}),
    # until_periodic: the cycle-to-cycle changes are 4.5e-7, 1.2e-12 (cycles 2, 3) with
    # generalized-α and 2.4e-7, 2.3e-8 (cycles 4, 5) with RK4: the runs stop at cycle 3 and 5,
    # each after the checkpoint of the cycle before
    ("oxygen-hill", {"method": "generalized-alpha", "dt": 1e-3, "cycles": 2,
                     "until_periodic": 1e-9, "max_cycles": 8}),
    ("oxygen-hill", {"method": "rk4", "cycles": 2, "until_periodic": 1e-7, "max_cycles": 8}),
]


@pytest.mark.parametrize(("name", "kw"), CASES, ids=[f"{n}-{'-'.join(map(str, k.values()))}"
                                                     for n, k in CASES])
def test_a_resumed_run_is_bit_identical_to_the_uninterrupted_one(
        tmp_path: Path, name: str, kw: dict[str, Any]) -> None:
    model = {"oxygen-hill": _oxygen_hill, "reversing-renewal": _reversing_renewal}.get(
        name, lambda: name)()
    whole = oxyline.simulate(model, **kw)
    ck = tmp_path / "run.ckpt"
    # the checkpointing run itself is the same run
    written = oxyline.simulate(model, checkpoint=ck, checkpoint_every="1 cycle", **kw)
    assert _same(whole, written) == []
    # the file holds the state after the last cycle but one (none is written after the last)
    resumed = oxyline.resume(ck)
    assert _same(whole, resumed) == []
    assert resumed.complete
    assert [p.name for p in tmp_path.iterdir()] == ["run.ckpt"]  # no temporary file left
    if "until_periodic" in kw:
        assert 2 < whole.settings["cycles_run"] < kw["max_cycles"]


def test_a_resumed_run_estimates_the_spatial_error_as_the_run_that_wrote_it(
        tmp_path: Path) -> None:
    """estimate_space_error is a stored setting: the resumed run refines the same model once
    more, so its estimate is the uninterrupted run's (the same arithmetic: bit for bit)."""
    kw = {"method": "generalized-alpha", "dt": 1e-3, "cycles": 2, "estimate_space_error": True}
    whole = oxyline.simulate("bifurcation", **kw)
    ck = tmp_path / "run.ckpt"
    oxyline.simulate("bifurcation", checkpoint=ck, checkpoint_every="1 cycle", **kw)
    resumed = oxyline.resume(ck)
    assert _same(whole, resumed) == []
    space = whole.settings["error_estimate_space"]
    assert space > 0 and resumed.settings["error_estimate_space"] == space


def test_a_cancelled_run_resumes_from_its_last_checkpoint(tmp_path: Path) -> None:
    """Deterministic stop: the progress callback cancels the run once the checkpoint of cycle
    2 exists; the partial result comes with SimulationCancelled, and the resumed run ends as
    the uninterrupted one."""
    d = _oxygen_hill()
    kw = {"method": "generalized-alpha", "dt": 1e-3, "cycles": 5, "output_cycles": "all"}
    whole = oxyline.simulate(d, **kw)
    ck = tmp_path / "run.ckpt"
    stop = threading.Event()

    def progress(t: float, t_end: float) -> None:
        if ck.exists():
            stop.set()

    with pytest.raises(oxyline.SimulationCancelled) as exc:
        oxyline.simulate(d, checkpoint=ck, checkpoint_every="2 cycles", cancel=stop,
                         progress=progress, **kw)
    partial = exc.value.result
    assert not partial.complete and 0 < partial.time.size < whole.time.size
    assert np.array_equal(partial.data, whole.data[:partial.time.size])
    assert _same(whole, oxyline.resume(ck)) == []


def test_checkpoint_errors_name_the_file_and_what_differs(tmp_path: Path) -> None:
    ck = tmp_path / "run.ckpt"
    oxyline.simulate("bifurcation", cycles=2, checkpoint=ck, checkpoint_every="1 cycles")
    not_one = tmp_path / "other.ckpt"
    not_one.write_text("hello")
    with pytest.raises(oxyline.CheckpointError, match="other.ckpt: not an oxyline checkpoint"):
        oxyline.resume(not_one)
    with pytest.raises(oxyline.CheckpointError, match="missing.ckpt: checkpoint file not found"):
        oxyline.resume(tmp_path / "missing.ckpt")
    with pytest.raises(oxyline.ModelError, match="resume: cycles cannot change"):
        oxyline.resume(ck, cycles=5)

    def rewrite(change: Any) -> Path:
        out = tmp_path / "changed.ckpt"
        with np.load(ck) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(bytes(arrays.pop("meta")).decode())
        change(meta, arrays)
        with open(out, "wb") as f:
            np.savez(f, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
        return out

    newer = rewrite(lambda m, a: m.update(version=99))
    with pytest.raises(oxyline.CheckpointError, match="file version 99, this oxyline .* reads "
                                                      "version 1"):
        oxyline.resume(newer)
    state = rewrite(lambda m, a: m["state"].update(version=7))
    with pytest.raises(oxyline.CheckpointError, match="run state version 7"):
        oxyline.resume(state)
    # another model (one more vessel) or another step: the core says what differs
    other = rewrite(lambda m, a: m.update(model=oxyline.load_model("aortic-bifurcation")
                                          .to_dict()))
    with pytest.raises(oxyline.CheckpointError, match="changed.ckpt: .*another model"):
        oxyline.resume(other)
    step = rewrite(lambda m, a: m["settings"].update(dt=1e-4))
    with pytest.raises(oxyline.CheckpointError, match="time step .* settings changed"):
        oxyline.resume(step)


def test_checkpoint_settings_are_checked(tmp_path: Path) -> None:
    with pytest.raises(oxyline.ModelError, match="checkpoint_every must be seconds"):
        oxyline.simulate("bifurcation", checkpoint=tmp_path / "c", checkpoint_every="often")
    with pytest.raises(oxyline.ModelError, match="checkpoint_every needs checkpoint"):
        oxyline.simulate("bifurcation", checkpoint_every=10)
    with pytest.raises(oxyline.ModelError, match="cancel must be a threading.Event"):
        oxyline.simulate("bifurcation", cancel=True)
    with pytest.raises(oxyline.ModelError, match="not supported with a streamed store"):
        oxyline.simulate_to_zarr("bifurcation", tmp_path / "r.zarr", checkpoint=tmp_path / "c")


def test_a_cancel_event_stops_a_run_in_a_worker_thread_with_its_partial_result() -> None:
    stop = threading.Event()
    seen: list[float] = []
    outcome: dict[str, Any] = {}

    def progress(t: float, t_end: float) -> None:
        seen.append(t)
        if t > 0.5:  # set from the run's own callback: a deterministic point
            stop.set()

    def work() -> None:
        try:
            oxyline.simulate("bifurcation", cycles=50, method="rk4", output_cycles="all",
                             cancel=stop, progress=progress)
        except oxyline.SimulationCancelled as exc:
            outcome["exc"] = exc

    worker = threading.Thread(target=work)
    worker.start()
    worker.join(timeout=300)
    exc = outcome["exc"]
    assert isinstance(exc, oxyline.SimulationInterrupted)  # caught like Ctrl-C
    assert "run cancelled after" in str(exc)
    part = exc.result
    assert not part.complete and 0 < part.time[-1] <= seen[-1] + 1e-12 < 50.0


@pytest.mark.skipif(os.name != "posix", reason="needs SIGINT")
def test_ctrl_c_in_the_main_thread_cancels_the_runs_in_worker_threads() -> None:
    code = textwrap.dedent("""
        import os, signal, threading, oxyline
        started, result = threading.Event(), {}
        def work():
            try:
                oxyline.simulate("bifurcation", cycles=100000, method="rk4",
                                 progress=lambda t, t_end: started.set())
            except oxyline.SimulationCancelled as exc:
                result["rows"] = exc.result.time.size
        worker = threading.Thread(target=work)
        worker.start()
        started.wait()  # the run is integrating: Ctrl-C now
        try:
            os.kill(os.getpid(), signal.SIGINT)
            worker.join()
        except KeyboardInterrupt:
            print("main: KeyboardInterrupt")
            worker.join()
        print("worker:", "cancelled" if result.get("rows", 0) > 0 else "not cancelled")
    """)
    done = run_child([sys.executable, "-c", code], timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split("\n")[:2] == ["main: KeyboardInterrupt", "worker: cancelled"]


def test_cli_checkpoint_and_resume_give_the_uninterrupted_file(tmp_path: Path) -> None:
    import xarray as xr

    os.chdir(tmp_path)
    # a fixed step (checkpoints need one): the uninterrupted run is the same fixed-step run
    step = ["--dt", "1e-3", "--method", "generalized-alpha"]
    assert cli.main(["run", "bifurcation", "--cycles", "3", "--quiet", *step, "-o",
                     "whole.nc"]) == 0
    assert cli.main(["run", "bifurcation", "--cycles", "3", "--quiet", *step, "--checkpoint",
                     "run.ckpt", "--checkpoint-every", "2 cycles", "-o", "first.nc"]) == 0
    assert cli.main(["run", "--resume", "run.ckpt", "--quiet", "-o", "resumed.nc"]) == 0
    with xr.open_dataset("whole.nc") as a, xr.open_dataset("resumed.nc") as b:
        for name in a.data_vars:
            assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    with pytest.raises(SystemExit) as usage:  # a model and --resume: a usage error
        cli.main(["run", "bifurcation", "--resume", "run.ckpt", "--quiet"])
    assert usage.value.code == 2
    assert cli.main(["run", "--resume", "run.ckpt", "--cycles", "4", "--quiet"]) == 2
    assert cli.main(["run", "bifurcation", "--checkpoint-every", "5", "--quiet"]) == 2


def test_cli_solver_failure_writes_the_partial_result(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A run that fails after some cycles: the rows up to the failure are written, exit 1."""
    real = oxyline.simulate

    def failing(model: Any, **kw: Any) -> oxyline.Result:
        res = real(model, **{**kw, "cycles": 1})
        partial = copy.copy(res)
        partial.complete = False
        exc = oxyline.SolverError("solver failed at t = 1.0 s: Newton did not converge")
        exc.result = partial  # as simulate() attaches it
        raise exc

    monkeypatch.setattr(oxyline, "simulate", failing)
    out = tmp_path / "partial.nc"
    assert cli.main(["run", "bifurcation", "--quiet", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"partial result (up to the failure) written to {out}" in err
    assert "error: solver failed at t = 1.0 s: Newton did not converge" in err
    import xarray as xr

    with xr.open_dataset(out) as ds:
        assert ds.attrs["complete"] == 0 and ds.sizes["time"] > 0


@pytest.mark.skipif(os.name != "posix", reason="needs SIGTERM")
def test_sigterm_in_the_cli_exits_143_and_writes_the_partial_result(tmp_path: Path) -> None:
    out = tmp_path / "partial.nc"
    returncode, text = signal_cli_run(out, signal.SIGTERM)
    assert returncode == 143, text
    assert "Traceback" not in text
    assert f"terminated; partial result written to {out}" in text
    import xarray as xr

    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.attrs["complete"] == 0
        assert ds.sizes["time"] > 0
