from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

# The property tests draw the same examples on every run, so CI is reproducible; set
# HYPOTHESIS_PROFILE=explore to search new random examples locally.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

REPO = Path(__file__).resolve().parents[1]
# Peer reference data shipped with the tests (provenance, licences, citations:
# tests/data/README.md). The suite needs nothing outside the repository except for the few
# tests named there, which read licence-restricted files from ../shared and skip without it.
DATA = REPO / "tests" / "data"
SHARED = REPO.parent / "shared"


def first_harmonic(vessel: Any, variable: str, period: float, steps: int) -> tuple[Any, Any]:
    """The first cycle of ``variable`` of a vessel result sampled ``steps`` times a period
    (the run's last cycle), and its first Fourier coefficient (complex, sin(ωt) → −i)."""
    import math

    import numpy as np

    t = np.asarray(vessel.time)
    keep = t < t[0] + period * (1 - 1e-9)
    t, x = t[keep], np.asarray(getattr(vessel, variable))[keep]
    assert len(t) == steps
    return x, 2.0 / steps * np.sum(x * np.exp(-2j * math.pi * t / period))


def data_path(*parts: str) -> Path:
    """A file or folder of ``tests/data`` (e.g. ``data_path("openbf", "models")``). Large
    files are stored gzipped: ``name`` resolves to ``name.gz`` when only that exists, which
    pandas and numpy readers open transparently."""
    path = DATA.joinpath(*parts)
    packed = path.with_name(path.name + ".gz")
    if not path.exists() and packed.exists():
        return packed
    return path


def bifurcation(**top: Any) -> dict[str, Any]:
    """The package's bifurcation example (YAML) as a dict, with the top-level keys ``top``
    set: the base of the hostile-input tests' models."""
    import yaml

    import oxyline

    example = Path(oxyline.__file__).parent / "examples" / "bifurcation.yaml"
    m = yaml.safe_load(example.read_text())
    m.update(top)
    return m


@contextlib.contextmanager
def raises(cls: type[BaseException], *names: str) -> Iterator[Any]:
    """pytest.raises(cls) whose message must name each of ``names``."""
    with pytest.raises(cls) as info:
        yield info
    msg = str(info.value)
    for n in names:
        assert n in msg, f"{n!r} not in {msg!r}"


def tube(n: int, species: list[dict] | None = None, oxygen: dict | None = None, *,
         radius: float = 3e-3, length: float = 0.1, flow: float | dict = 2e-6,
         compliant: bool = False, r_out: float = 1e8, cycles: int = 40) -> dict:
    """A straight tube of ``n`` segments (rigid unless ``compliant``) between a flow inlet and
    a resistance, with the ``species`` and ``oxygen`` sections given: the transport tests' model."""
    vessel = {"name": "tube", "from": "in", "to": "out", "segments": n, "length": length,
              "radius": radius}
    if compliant:
        vessel.update(wall_thickness=5e-4, youngs_modulus=1e6)
    inflow = {"type": "flow", **(flow if isinstance(flow, dict) else {"value": flow})}
    m: dict = {"period": 1.0, "vessels": [vessel],
               "boundary_conditions": {"in": inflow,
                                       "out": {"type": "resistance", "resistance": r_out}},
               "simulation": {"cycles": cycles}}
    if species:
        m["species"] = species
    if oxygen:
        m["oxygen"] = oxygen
    return m


def main_thread_ticks(work: Any) -> int:
    """Run ``work()`` on another thread and count the main thread's 1 ms ticks until it ends
    (a call that holds the GIL lets few through); an exception of ``work`` is raised here."""
    import time

    done = threading.Event()
    raised: list[BaseException] = []

    def run() -> None:
        try:
            work()
        except BaseException as e:  # noqa: BLE001 (raised again on the main thread)
            raised.append(e)
        finally:
            done.set()

    th = threading.Thread(target=run)
    th.start()
    ticks = 0
    while not done.is_set():
        ticks += 1
        time.sleep(0.001)
    th.join()
    if raised:
        raise raised[0]
    return ticks


def assert_adjoint_is_forward(fwd: Any, adj: Any, where: object = None) -> None:
    """The adjoint's sensitivities ``adj`` against the forward tangents' ``fwd`` (the same
    model, parameters and outputs): the values to 1e-12, and each derivative to 1e-8 of its
    output's largest response to a 100 % change (the two differ only by their fixed points'
    tolerance, 1e-12, and rounding, so a wrong transpose or weight stands out)."""
    import numpy as np

    np.testing.assert_allclose(adj.values, fwd.values, rtol=1e-12)
    scale = np.abs(fwd.jacobian * fwd.parameter_values).max(axis=1)
    err = np.abs(adj.jacobian - fwd.jacobian) * np.abs(fwd.parameter_values)
    assert (err <= 1e-8 * scale[:, None]).all(), (where, err / scale[:, None])


def assert_sensitivities_are_central_differences(model: dict[str, Any], params: list[str],
                                                 outputs: list[str], h: float = 1e-4) -> Any:
    """The forward tangents of ``outputs`` by ``params`` against central differences of
    whole periodic runs (relative step ``h``): each derivative to 1e-6 of its output's largest
    response to a 100 % change (the differences' truncation and rounding sit near 1e-8 at
    h = 1e-4). Returns the exact sensitivities."""
    import numpy as np

    import oxyline
    from oxyline.calibrate import _base_value, native_model

    exact = oxyline.sensitivities(model, params, outputs)
    assert exact.periodic_change <= 1e-11
    scale = np.abs(exact.jacobian * exact.parameter_values).max(axis=1)
    assert (scale > 0).all()
    for k, path in enumerate(params):
        x0 = _base_value(model, path)  # in the model's units (the Jacobian's are SI)
        up, down = (oxyline.sensitivities(native_model(model, [path], [x0 * f]), [],
                                          outputs).values for f in (1 + h, 1 - h))
        # d(output)/d(log parameter), the same in every unit system
        err = np.abs(exact.jacobian[:, k] * exact.parameter_values[k] - (up - down) / (2 * h))
        assert (err <= 1e-6 * scale).all(), (path, err / scale)
    return exact


def stenosed_inductor(coefficient: float) -> dict[str, Any]:
    """A compliant vessel into a lumped RLC element with a stenosis S |Q| Q of coefficient
    ``coefficient`` in series with its inertance, a steady inflow of 1e-5 m³/s and an outlet
    resistance: the stenosis sets RK4's stability limit."""
    return {
        "name": "stenosis", "period": 1.0,
        "vessels": [
            {"name": "a", "from": "in", "to": "j", "length": 0.0625, "radius": 0.0039,
             "wall_thickness": 3e-4, "youngs_modulus": 1e6},
            {"name": "s", "from": "j", "to": "out",
             "lumped": {"resistance": 1e6, "capacitance": 1e-10, "inductance": 1e4,
                        "stenosis_coefficient": coefficient}}],
        "boundary_conditions": {"in": {"type": "flow", "value": 1e-5},
                                "out": {"type": "resistance", "resistance": 1e7}},
    }


def shared_path(relative: str, why: str) -> Path:
    """A file of ``../shared`` that its licence keeps out of the repository; skips the calling
    test, saying what is missing and why, when ``../shared`` is not beside the repository."""
    path = SHARED / relative
    if not path.exists():
        pytest.skip(f"needs ../shared/{relative} ({why}); not shipped in tests/data because of "
                    f"its licence")
    return path


def model_differences(actual: Any, expected: Any, rel: float, where: str = "model",
                      ) -> list[str]:
    """Where two nested model dicts differ: the same keys, list lengths, strings and integers,
    and every float within ``rel`` (relative; absolute where the expected value is 0). For models
    that a calibration or a linear solve produced: those round differently on another CPU or
    BLAS build, so bit-identity would test the machine, not the code."""
    if isinstance(expected, dict) and isinstance(actual, dict):
        if actual.keys() != expected.keys():
            return [f"{where}: keys {sorted(set(actual) ^ set(expected))} differ"]
        return [d for k in expected for d in model_differences(actual[k], expected[k], rel,
                                                               f"{where}.{k}")]
    if isinstance(expected, list) and isinstance(actual, list):
        if len(actual) != len(expected):
            return [f"{where}: {len(actual)} items, expected {len(expected)}"]
        return [d for i, (a, e) in enumerate(zip(actual, expected))
                for d in model_differences(a, e, rel, f"{where}[{i}]")]
    if isinstance(expected, float) and isinstance(actual, (float, int)):
        tol = rel * abs(expected) if expected else rel
        return [] if abs(actual - expected) <= tol else [(f"{where}: {actual!r}, expected "
                                                         f"{expected!r} (rel {rel:g})")]
    return [] if actual == expected else [f"{where}: {actual!r}, expected {expected!r}"]


# ---- child processes ------------------------------------------------------------------------
# A child inherits ignored signals: started from a shell or CI runner that ignores SIGINT
# (background job, nohup), a Python child would never see Ctrl-C. Every test that starts a
# process goes through these helpers, which restore the default SIGINT disposition in the child
# (Python then installs its KeyboardInterrupt handler) and kill and reap it whatever happens.

def vessel_time_errors(res: Any, ref: Any) -> dict[str, Any]:
    """Every vessel's error of the run `res` against the reference run `ref` (the same output
    times), each against the vessel's own scale (flow amplitude, pressure peak, pulse
    pressure): the achieved error a time-error estimate is checked against."""
    import numpy as np

    p, pr = res.pressure_in, ref.pressure_in
    return {
        "flow": np.max(np.abs(res.flow_in - ref.flow_in), 0) / np.max(np.abs(ref.flow_in), 0),
        "pressure": np.max(np.abs(p - pr), 0) / np.max(np.abs(pr), 0),
        "pulse_pressure": np.abs(np.ptp(p, 0) - np.ptp(pr, 0)) / np.ptp(pr, 0),
    }


def _default_sigint() -> None:  # runs in the child between fork and exec
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@contextlib.contextmanager
def child_process(args: Sequence[str], **kwargs: Any) -> Iterator[subprocess.Popen[Any]]:
    """``subprocess.Popen(args, **kwargs)`` with SIGINT at its default in the child; the child is
    killed (if still running) and reaped when the block exits, also on failure or timeout."""
    if os.name == "posix":
        kwargs.setdefault("preexec_fn", _default_sigint)
    proc = subprocess.Popen(args, **kwargs)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def _collect_until(stream: Any, seen: threading.Event, marker: bytes, into: list[bytes]) -> None:
    """Read ``stream`` to its end into ``into``; set ``seen`` once ``marker`` has appeared."""
    while chunk := os.read(stream.fileno(), 4096):
        into.append(chunk)
        if marker in b"".join(into):
            seen.set()


def signal_cli_run(out: Any, sig: int) -> tuple[int, str]:
    """Start ``oxyline run bifurcation`` (RK4, 100,000 cycles, ``-o out``) in a child, send it
    ``sig`` once it is integrating, and return its exit code and stderr text.

    Deterministic trigger: the progress bar on stderr (shown once the run has lasted 1 s) says
    the core is integrating, so the signal lands in the run, not in the start-up. The timeouts
    only bound a hang: on a starved machine (nice 19 under load) the child's imports alone can
    take minutes of wall time."""
    err: list[bytes] = []
    running = threading.Event()
    with child_process([sys.executable, "-m", "oxyline.cli", "run", "bifurcation", "--cycles",
                        "100000", "--method", "rk4", "-o", str(out)],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) as proc:
        reader = threading.Thread(target=_collect_until,
                                  args=(proc.stderr, running, b"simulated", err), daemon=True)
        reader.start()
        assert running.wait(timeout=900), b"".join(err).decode()
        proc.send_signal(sig)
        proc.wait(timeout=600)
        reader.join(timeout=60)
    return proc.returncode, b"".join(err).decode()


def run_child(args: Sequence[str], *, timeout: float = 300, **kwargs: Any,
              ) -> subprocess.CompletedProcess[str]:
    """Run a child to completion (text output captured, like ``subprocess.run(...,
    capture_output=True, text=True)``); a child that outlives ``timeout`` is killed and the
    test fails with ``subprocess.TimeoutExpired``."""
    with child_process(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                       **kwargs) as proc:
        out, err = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--runslow", action="store_true", default=False, help="run slow studies")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow study: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


def svzerod_run(cfg: dict[str, Any], refine: int = 1) -> Any:
    """The peer itself, optionally with a `refine` times finer step and outputs at the same
    times."""
    svzerod = pytest.importorskip("svzerod")
    cfg = json.loads(json.dumps(cfg))
    sp = cfg["simulation_parameters"]
    sp["number_of_time_pts_per_cardiac_cycle"] = (
        (sp["number_of_time_pts_per_cardiac_cycle"] - 1) * refine + 1)
    sp["output_interval"] = sp.get("output_interval", 1) * refine
    return svzerod.simulate(cfg)
