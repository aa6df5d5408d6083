"""A valid file at any moment: SIGINT and SIGTERM sent at randomised moments (deterministic
seeds) to child processes writing NetCDF, CSV and Zarr results and checkpoints, and every file
left behind opened with xarray, pandas or the checkpoint reader.

Each child prints a marker line at each phase (model loaded, run progress, output chunk
appended, checkpoint written, run ended, result being written); the parent picks a phase and
an occurrence from the seed, sends the signal on reading that marker (after a seeded offset
of up to a few milliseconds, so that it lands at varied points inside the phase), and then
checks what is on disk: whole rows, no temporary files, and after any signal from the start
of the run on, the result file itself (partial or whole).
"""

from __future__ import annotations

import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import child_process

pytest.importorskip("xarray")

# the child: phases announced on stdout, then the CLI (or an API call) as a user runs it
CHILD = textwrap.dedent('''
    import sys

    import oxyline
    import oxyline.cli as cli
    import oxyline.run as run
    from oxyline import checkpoint
    from oxyline.io import results

    def mark(name):
        print(name, flush=True)

    def wrap(owner, attr, before=None, after=None):
        f = getattr(owner, attr)
        def wrapped(*a, **k):
            if before:
                mark(before)
            out = f(*a, **k)
            if after:
                mark(after)
            return out
        setattr(owner, attr, wrapped)

    run_core = run._run
    def traced_run(model, s, progress, cancel=None, **core):
        def step(t, t_end):
            mark("step")
        mark("loaded")
        return run_core(model, s, step, cancel, **core)
    run._run = traced_run
    wrap(results.ZarrAppender, "append", before="chunk")
    wrap(checkpoint, "write", after="checkpoint")
    wrap(oxyline, "simulate", after="ran")
    wrap(cli, "_write", before="writing")
    mode = sys.argv[1]
    if mode == "cli":
        sys.exit(cli.main(sys.argv[2:]))
    out = sys.argv[2]
    try:
        if mode == "zarr":
            oxyline.simulate_to_zarr("bifurcation", out, cycles=3, output_cycles="all",
                                     time_chunk=97, method="rk4")
        else:
            oxyline.simulate("bifurcation", cycles=6, checkpoint=out,
                             checkpoint_every="1 cycle", method="rk4")
    except KeyboardInterrupt:
        mark("stopped")
        sys.exit(130)
''')

PHASES_CLI = ("loaded", "step", "ran", "writing")
PHASES_STREAM = ("loaded", "step", "chunk")  # -o out.zarr: written during the run
REPEATED = ("step", "chunk", "checkpoint")  # the phases a run passes through many times
# a script calling the API: Ctrl-C ends it with 130 (the child's handler), SIGTERM with the
# default action (killed by the signal, once the file being written is complete)
API_EXITS = (0, 130, -signal.SIGTERM)
ZARR_TIME_CHUNK = 97  # the child's simulate_to_zarr(time_chunk=...)


def _signal_child(args: list[str], cwd: Path, phases: tuple[str, ...],
                  rng: random.Random) -> tuple[int, str, str, str]:
    """Run the child, signal it at a seeded phase; (exit code, phase, signal name, stderr)."""
    phase = rng.choice(phases)
    nth = rng.randint(1, 3) if phase in REPEATED else 1
    offset = rng.uniform(0.0, 0.004)
    sig = rng.choice((signal.SIGINT, signal.SIGTERM))
    twice = rng.random() < 0.3
    seen = 0
    with child_process([sys.executable, "-c", CHILD, *args], cwd=cwd, stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True) as proc:
        sent = False
        assert proc.stdout is not None and proc.stderr is not None
        for line in proc.stdout:
            if sent or line.strip() != phase:
                continue
            seen += 1
            if seen >= nth:
                time.sleep(offset)  # a seeded offset inside the phase, not a timing guess
                proc.send_signal(sig)
                if twice:
                    proc.send_signal(sig)
                sent = True
        err = proc.stderr.read()
        proc.wait(timeout=600)
    label = f"{phase}#{nth}+{offset * 1e3:.1f}ms {sig.name}{' x2' if twice else ''}"
    return proc.returncode, label if sent else f"{label} (not reached)", sig.name, err


def _no_temporaries(d: Path, killed: bool = False) -> None:
    """No temporary file; a process killed by SIGTERM's default action may leave the (empty)
    lock file of the store it wrote, which the next writer takes over."""
    ends = (".partial", ".old") if killed else (".partial", ".old", ".lock")
    left = [p.name for p in d.rglob("*") if p.name.endswith(ends)]
    assert not left, left


def _check_result_file(path: Path) -> int:
    """Open a result file as a user does; the number of whole rows it holds."""
    import xarray as xr

    if path.suffix == ".csv":
        import pandas as pd

        df = pd.read_csv(path)
        assert len(df) > 0 and not df.isna().any().any(), "a CSV with missing cells"
        assert np.all(np.diff(df["time [s]"].unique()) > 0)
        return int(df["time [s]"].nunique())
    if path.suffix == ".zarr":
        with xr.open_zarr(path) as ds:
            n = ds.sizes["time"]
            for name, var in ds.variables.items():
                if "time" in var.dims:
                    assert var.shape[var.dims.index("time")] == n, name
                    assert np.isfinite(var.values).all(), name
        # the arrays as stored agree too (not only the consolidated metadata)
        with xr.open_zarr(path, consolidated=False) as raw:
            assert raw.sizes["time"] >= n
        return int(n)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert np.isfinite(ds["pressure_in"].values).all()
        return int(ds.sizes["time"])


@pytest.mark.parametrize("suffix", [".nc", ".csv", ".zarr"])
def test_cli_signals_at_random_moments_leave_a_valid_result(tmp_path: Path,
                                                            suffix: str) -> None:
    rng = random.Random(f"cli{suffix}")
    for trial in range(5):
        d = tmp_path / f"t{trial}"
        d.mkdir()
        out = d / f"out{suffix}"
        rc, label, signame, err = _signal_child(
            ["cli", "run", "bifurcation", "--cycles", "3", "--method", "rk4", "--quiet",
             "-o", str(out)], d, PHASES_STREAM if suffix == ".zarr" else PHASES_CLI, rng)
        assert rc in (0, 130, 143), (label, rc, err)
        assert "Traceback" not in err, (label, err)
        _no_temporaries(d)
        if rc != 0 and not label.startswith("loaded"):
            # any signal from the start of the run on: the result (partial or whole) is there
            assert out.exists(), (label, err)
        if rc != 0:
            assert rc == (143 if signame == "SIGTERM" else 130), (label, rc, err)
        if out.exists():
            assert _check_result_file(out) >= 1, label


def test_zarr_stream_interrupted_at_random_chunks_opens_with_whole_rows(
        tmp_path: Path) -> None:
    pytest.importorskip("zarr")
    rng = random.Random("zarr-stream")
    for trial in range(5):
        d = tmp_path / f"t{trial}"
        d.mkdir()
        out = d / "run.zarr"
        rc, label, _, err = _signal_child(["zarr", str(out)], d, ("chunk",), rng)
        assert rc in API_EXITS, (label, rc, err)
        _no_temporaries(d, killed=rc == -signal.SIGTERM)
        assert out.exists(), label
        # the marker of chunk k is printed before its append: the k - 1 appends before it are
        # whole in the store whenever the signal lands (the k-th may or may not be, by timing)
        nth = int(label.split("#")[1].split("+")[0])
        assert _check_result_file(out) >= (nth - 1) * ZARR_TIME_CHUNK, label


def test_checkpoints_signalled_while_written_stay_readable(tmp_path: Path) -> None:
    rng = random.Random("checkpoint")
    for trial in range(4):
        d = tmp_path / f"t{trial}"
        d.mkdir()
        ckpt = d / "run.ckpt"
        rc, label, _, err = _signal_child(["checkpoint", str(ckpt)], d,
                                          ("checkpoint", "step"), rng)
        assert rc in API_EXITS, (label, rc, err)
        _no_temporaries(d)
        if ckpt.exists():
            from oxyline import checkpoint

            meta, state = checkpoint.read(ckpt)
            assert state["cycles_run"] >= 1 and meta["model"]["name"] == "bifurcation"
